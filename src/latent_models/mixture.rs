//! A Gaussian mixture in the latents' principal components, for populations with
//! sub-groups that one Gaussian would blur together.
//!
//! The latents are reduced to their kept principal modes and *whitened* (score / σⱼ), so
//! every mode has unit variance and one regularisation constant means the same relative
//! amount on every mode. The mixture models the leading `mixture_modes` of them, where
//! sub-groups show; the remaining kept modes are drawn as independent standard normals
//! (as in [`super::gaussian`]), so the cohort keeps the training spread in every mode
//! while a few dozen latents never have to fill a covariance of dozens of dimensions.
//! Fitting is EM ([`super::em`]); a draw picks a component by weight, draws the leading
//! modes from it and the rest independently, and maps back: z = μ + Σⱼ σⱼ wⱼ uⱼ.
//!
//! The number of components is given, or chosen by the Bayesian information criterion
//! over the m mixture modes ([`super::em::fit_bic_best`]).

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::LatentModelError;
use super::em::{Component, CovarianceKind, EmSettings, fit_bic_best, fit_with_bic};
use super::pca::{ModeSelection, Pca};

/// EM stops when the mean log-likelihood per latent changes by less than this.
pub const EM_TOLERANCE: f64 = 1e-6;

/// Default covariance regularisation, in whitened units (a share of each mode's variance).
pub const DEFAULT_REGULARISATION: f64 = 1e-3;

/// How many components to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", content = "value", rename_all = "snake_case")]
pub enum ComponentCount {
    /// Exactly this many (≥ 1).
    Fixed(usize),
    /// The BIC-best count from 1 up to this many.
    Bic(usize),
}

/// How to fit the mixture.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PcaMixtureConfig {
    /// Which principal modes the sampler keeps.
    pub modes: ModeSelection,
    /// How many of the leading kept modes the mixture models (≥ 1; at most the kept ones).
    pub mixture_modes: usize,
    /// Number of components.
    pub components: ComponentCount,
    /// Shape of the component covariances.
    pub covariance: CovarianceKind,
    /// Added to every whitened covariance diagonal (> 0).
    pub regularisation: f64,
    /// EM iteration limit.
    pub max_iterations: usize,
    /// Seed of the k-means++ start.
    pub seed: u64,
}

impl Default for PcaMixtureConfig {
    fn default() -> Self {
        Self {
            modes: ModeSelection::AllNonZero,
            mixture_modes: 4,
            components: ComponentCount::Bic(4),
            covariance: CovarianceKind::Full,
            regularisation: DEFAULT_REGULARISATION,
            max_iterations: 500,
            seed: 0,
        }
    }
}

/// A fitted mixture in the whitened principal components.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PcaMixture {
    /// The principal components it draws in.
    pub pca: Pca,
    /// Components over the leading modes, in whitened coordinates.
    pub components: Vec<Component>,
    /// Covariance shape.
    pub covariance: CovarianceKind,
    /// Log-likelihood of the whitened training scores of the mixture modes.
    pub log_likelihood: f64,
    /// Its BIC.
    pub bic: f64,
}

impl PcaMixture {
    /// Fits the components of `latents` (≥ 2, not all identical) and a mixture in them.
    pub fn fit(latents: &[Vec<f64>], config: &PcaMixtureConfig) -> Result<Self, LatentModelError> {
        if !(config.regularisation > 0.0 && config.regularisation.is_finite()) {
            return Err(LatentModelError::Domain {
                what: "mixture regularisation",
                detail: format!("needs a finite value > 0, got {}", config.regularisation),
            });
        }
        if config.mixture_modes == 0 {
            return Err(LatentModelError::Domain {
                what: "mixture modes",
                detail: "needs at least one mode".into(),
            });
        }
        let pca = Pca::fit(latents, config.modes)?;
        let m = config.mixture_modes.min(pca.modes());
        let whitened: Vec<Vec<f64>> = latents
            .iter()
            .map(|z| {
                pca.scores(z)
                    .iter()
                    .zip(&pca.sd)
                    .take(m)
                    .map(|(s, sd)| s / sd)
                    .collect()
            })
            .collect();
        let settings = EmSettings {
            components: 1,
            covariance: config.covariance,
            regularisation: config.regularisation,
            max_iterations: config.max_iterations,
            tolerance: EM_TOLERANCE,
            seed: config.seed,
        };
        let (fit, bic) = match config.components {
            ComponentCount::Fixed(k) => fit_with_bic(
                &whitened,
                &EmSettings {
                    components: k,
                    ..settings
                },
            )?,
            ComponentCount::Bic(max) => fit_bic_best(&whitened, max, &settings)?,
        };
        Ok(Self {
            pca,
            components: fit.components,
            covariance: config.covariance,
            log_likelihood: fit.log_likelihood,
            bic,
        })
    }

    /// Number of leading modes the mixture models.
    pub fn mixture_modes(&self) -> usize {
        self.components[0].mean.len()
    }

    /// One new latent.
    pub fn sample(&self, rng: &mut ChaCha8Rng) -> Vec<f64> {
        let u: f64 = rng.random();
        let mut acc = 0.0;
        let mut chosen = &self.components[self.components.len() - 1];
        for c in &self.components {
            acc += c.weight;
            if u < acc {
                chosen = c;
                break;
            }
        }
        let m = self.mixture_modes();
        let e: Vec<f64> = (0..self.pca.modes())
            .map(|_| StandardNormal.sample(rng))
            .collect();
        let scores: Vec<f64> = (0..e.len())
            .map(|i| {
                let w = if i < m {
                    chosen.mean[i] + (0..=i).map(|k| chosen.cholesky[i][k] * e[k]).sum::<f64>()
                } else {
                    e[i]
                };
                w * self.pca.sd[i]
            })
            .collect();
        self.pca.latent(&scores)
    }

    /// Component `c`'s mean in latent space.
    pub fn latent_mean(&self, c: usize) -> Vec<f64> {
        let scores: Vec<f64> = self.components[c]
            .mean
            .iter()
            .zip(&self.pca.sd)
            .map(|(w, s)| w * s)
            .collect();
        self.pca.latent(&scores)
    }

    /// Component `c`'s covariance in latent space, U S Σ' S Uᵀ with S = diag(σ) and Σ' the
    /// component's whitened covariance on the mixture modes and the identity on the rest.
    pub fn latent_covariance(&self, c: usize) -> Vec<Vec<f64>> {
        let (u, sd, cov) = (
            &self.pca.components,
            &self.pca.sd,
            &self.components[c].covariance,
        );
        let m = self.mixture_modes();
        let whitened = |a: usize, b: usize| match (a < m && b < m, a == b) {
            (true, _) => cov[a][b],
            (false, true) => 1.0,
            (false, false) => 0.0,
        };
        let (d, k) = (self.pca.dimension(), sd.len());
        (0..d)
            .map(|i| {
                (0..d)
                    .map(|j| {
                        (0..k)
                            .flat_map(|a| (0..k).map(move |b| (a, b)))
                            .map(|(a, b)| u[a][i] * sd[a] * whitened(a, b) * sd[b] * u[b][j])
                            .sum()
                    })
                    .collect()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::latent_models::LatentSampler;
    use crate::stats::multivariate::mean_vector;
    use rand::SeedableRng;

    /// 600 latents in 2-D from 0.3·N((−3, 0), A) + 0.7·N((3, 1), B), A = [[1, 0.3], [0.3, 0.73]]
    /// and B = [[0.5, −0.2], [−0.2, 1]] (given by their Cholesky factors).
    fn two_groups() -> Vec<Vec<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (la, lb) = (
            [[1.0, 0.0], [0.3, 0.64f64.sqrt()]],
            [
                [0.5f64.sqrt(), 0.0],
                [-0.2 / 0.5f64.sqrt(), (1.0f64 - 0.08).sqrt()],
            ],
        );
        (0..600)
            .map(|i| {
                let (mean, l) = if i % 10 < 3 {
                    ([-3.0, 0.0], la)
                } else {
                    ([3.0, 1.0], lb)
                };
                let e: [f64; 2] = [
                    StandardNormal.sample(&mut rng),
                    StandardNormal.sample(&mut rng),
                ];
                vec![
                    mean[0] + l[0][0] * e[0],
                    mean[1] + l[1][0] * e[0] + l[1][1] * e[1],
                ]
            })
            .collect()
    }

    fn config(components: ComponentCount) -> PcaMixtureConfig {
        PcaMixtureConfig {
            modes: ModeSelection::AllNonZero,
            components,
            ..PcaMixtureConfig::default()
        }
    }

    #[test]
    fn em_recovers_the_weights_means_and_covariances_of_a_known_mixture() {
        let m = PcaMixture::fit(&two_groups(), &config(ComponentCount::Fixed(2))).unwrap();
        let small = (0..2)
            .min_by(|&a, &b| m.components[a].weight.total_cmp(&m.components[b].weight))
            .unwrap();
        let (big, want) = (
            1 - small,
            [
                ([-3.0, 0.0], [[1.0, 0.3], [0.3, 0.73]]),
                ([3.0, 1.0], [[0.5, -0.2], [-0.2, 1.0]]),
            ],
        );
        assert!(
            (m.components[small].weight - 0.3).abs() < 0.05,
            "{:?}",
            m.components[small].weight
        );
        for (c, (mean, cov)) in [small, big].into_iter().zip(want) {
            let (got_mean, got_cov) = (m.latent_mean(c), m.latent_covariance(c));
            for i in 0..2 {
                // standard errors ≈ 1/√180 for the means, ≈ 0.1 for the covariances
                assert!((got_mean[i] - mean[i]).abs() < 0.25, "mean {got_mean:?}");
                for j in 0..2 {
                    assert!((got_cov[i][j] - cov[i][j]).abs() < 0.3, "cov {got_cov:?}");
                }
            }
        }
    }

    #[test]
    fn bic_prefers_two_components_for_two_groups_and_one_for_one() {
        let m = PcaMixture::fit(&two_groups(), &config(ComponentCount::Bic(4))).unwrap();
        assert_eq!(m.components.len(), 2);
        let one_group: Vec<Vec<f64>> = two_groups()
            .into_iter()
            .enumerate()
            .filter(|(i, _)| i % 10 >= 3)
            .map(|(_, z)| z)
            .collect();
        let m = PcaMixture::fit(&one_group, &config(ComponentCount::Bic(4))).unwrap();
        assert_eq!(m.components.len(), 1);
    }

    #[test]
    fn draws_replay_bit_for_bit_and_average_to_the_mixture_mean() {
        let latents = two_groups();
        let fit = |seed| {
            PcaMixture::fit(
                &latents,
                &PcaMixtureConfig {
                    seed,
                    ..config(ComponentCount::Fixed(2))
                },
            )
            .unwrap()
        };
        let (m, again) = (fit(3), fit(3));
        assert_eq!(m, again);
        let sampler = LatentSampler::PcaMixture(m.clone());
        let restored: LatentSampler =
            serde_json::from_str(&serde_json::to_string(&sampler).unwrap()).unwrap();
        let draws = sampler.sample_many(20_000, 8);
        assert_eq!(draws, restored.sample_many(20_000, 8));
        let mean = mean_vector(&draws).unwrap();
        let want: Vec<f64> = (0..2)
            .map(|i| {
                (0..2)
                    .map(|c| m.components[c].weight * m.latent_mean(c)[i])
                    .sum()
            })
            .collect();
        // the mixture's sd is about 3 per coordinate: 5 standard errors ≈ 0.11
        for i in 0..2 {
            assert!((mean[i] - want[i]).abs() < 0.11, "{mean:?} vs {want:?}");
        }
    }

    #[test]
    fn a_diagonal_model_has_diagonal_whitened_covariances_and_fits_from_a_request() {
        let request: crate::latent_models::SamplerConfig = serde_json::from_str(
            r#"{"kind": "pca_mixture", "modes": {"kind": "all_non_zero"}, "mixture_modes": 2,
                "components": {"kind": "fixed", "value": 2}, "covariance": "diagonal",
                "regularisation": 0.001, "max_iterations": 200, "seed": 1}"#,
        )
        .unwrap();
        let LatentSampler::PcaMixture(m) = request.fit(&two_groups()).unwrap() else {
            panic!("the request names a mixture");
        };
        assert_eq!(
            (m.covariance, m.components.len()),
            (CovarianceKind::Diagonal, 2)
        );
        for c in &m.components {
            assert_eq!((c.covariance[0][1], c.covariance[1][0]), (0.0, 0.0));
            assert!(c.covariance[0][0] > 0.0 && c.covariance[1][1] > 0.0);
        }
    }

    #[test]
    fn with_few_latents_in_many_dimensions_bic_keeps_one_component_and_every_mode_spreads() {
        // 16 latents of one Gaussian in 64-D: 15 modes; three components of about five
        // latents in 4 mixture modes would buy likelihood with near-singular covariances
        let latents = crate::latent_models::test_latents::anisotropic(16, 64, 2, |j| {
            1.0 / (1.0 + j as f64).sqrt()
        });
        let m = PcaMixture::fit(&latents, &PcaMixtureConfig::default()).unwrap();
        assert_eq!(
            (m.components.len(), m.mixture_modes(), m.pca.modes()),
            (1, 4, 15)
        );
        let draws = LatentSampler::PcaMixture(m.clone()).sample_many(20_000, 1);
        for j in 4..15 {
            // modes outside the mixture are standard normal in whitened units
            let var = draws
                .iter()
                .map(|z| (m.pca.scores(z)[j] / m.pca.sd[j]).powi(2))
                .sum::<f64>()
                / draws.len() as f64;
            assert!(
                (var - 1.0).abs() < 5.0 * (2.0f64 / 20_000.0).sqrt(),
                "mode {j}: {var}"
            );
        }
    }

    #[test]
    fn degenerate_inputs_say_why() {
        let same = vec![vec![0.5; 8]; 4];
        assert_eq!(
            PcaMixture::fit(&same, &PcaMixtureConfig::default()),
            Err(LatentModelError::NoVariation)
        );
        let few = two_groups()[..3].to_vec();
        assert!(matches!(
            PcaMixture::fit(&few, &config(ComponentCount::Fixed(5))),
            Err(LatentModelError::TooFew { .. })
        ));
        assert!(
            PcaMixture::fit(
                &few,
                &PcaMixtureConfig {
                    regularisation: 0.0,
                    ..PcaMixtureConfig::default()
                }
            )
            .is_err()
        );
    }
}
