//! A Gaussian in the latents' principal components: new latent z = μ + Σⱼ s σⱼ εⱼ uⱼ with
//! independent standard normal εⱼ, σⱼ the training latents' spread along mode j and s an
//! optional scale. With a truncation c each εⱼ is redrawn until |εⱼ| ≤ c (rejection per
//! mode), the practice of statistical shape models for virtual cohorts (e.g. ±3 σ per
//! mode for TAVI anatomies), which keeps every shape within the plausible range of each
//! mode; the per-mode variance then shrinks to 1 − 2cφ(c)/(2Φ(c) − 1) of σⱼ².
//!
//! With a shrinkage ρ ([`super::shrinkage`]) the covariance is (1 − ρ) S + ρ m I instead
//! of the training latents' S = Σⱼ σⱼ² uⱼ uⱼᵀ, m = Σⱼ σⱼ² / d: mode j draws with variance
//! (1 − ρ) σⱼ² + ρ m, and the directions no kept mode spans with variance ρ m (an
//! independent normal projected onto their complement, never truncated).

use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::LatentModelError;
use super::pca::{ModeSelection, Pca};
use super::shrinkage::Shrinkage;

/// How to fit and draw from the Gaussian.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PcaGaussianConfig {
    /// Which principal modes to keep.
    pub modes: ModeSelection,
    /// Redraw each mode's normal variate until it lies within ±c (c > 0); none: no limit.
    pub truncation: Option<f64>,
    /// Multiplies every σⱼ (> 0; 1 reproduces the training spread).
    pub sigma_scale: f64,
    /// Pulls the covariance towards m I; none: the sample covariance.
    pub shrinkage: Option<Shrinkage>,
}

impl Default for PcaGaussianConfig {
    fn default() -> Self {
        Self {
            modes: ModeSelection::AllNonZero,
            truncation: None,
            sigma_scale: 1.0,
            shrinkage: None,
        }
    }
}

/// A fitted Gaussian in the principal components.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PcaGaussian {
    /// The principal components it draws in.
    pub pca: Pca,
    /// Truncation c of each mode's normal variate, if any.
    pub truncation: Option<f64>,
    /// Scale on every σⱼ.
    pub sigma_scale: f64,
    /// Shrinkage intensity ρ in [0, 1] (0: the sample covariance).
    #[serde(default)]
    pub shrinkage: f64,
}

impl PcaGaussian {
    /// Fits the components of `latents` (≥ 2, not all identical).
    pub fn fit(latents: &[Vec<f64>], config: &PcaGaussianConfig) -> Result<Self, LatentModelError> {
        if let Some(c) = config.truncation
            && !(c > 0.0 && c.is_finite())
        {
            return Err(LatentModelError::Domain {
                what: "truncation",
                detail: format!("needs a finite c > 0, got {c}"),
            });
        }
        if !(config.sigma_scale > 0.0 && config.sigma_scale.is_finite()) {
            return Err(LatentModelError::Domain {
                what: "sigma scale",
                detail: format!("needs a finite scale > 0, got {}", config.sigma_scale),
            });
        }
        let shrinkage = match config.shrinkage {
            Some(s) => s.intensity(latents)?,
            None => 0.0,
        };
        Ok(Self {
            pca: Pca::fit(latents, config.modes)?,
            truncation: config.truncation,
            sigma_scale: config.sigma_scale,
            shrinkage,
        })
    }

    /// ρ m: the variance shrinkage adds to every direction (m = Σⱼ σⱼ² / d).
    pub fn isotropic_variance(&self) -> f64 {
        let kept: f64 = self.pca.sd.iter().map(|s| s * s).sum();
        self.shrinkage * kept / self.pca.dimension() as f64
    }

    /// The standard deviation drawn along each kept mode, before the scale:
    /// √((1 − ρ) σⱼ² + ρ m).
    pub fn mode_sd(&self) -> Vec<f64> {
        let iso = self.isotropic_variance();
        self.pca
            .sd
            .iter()
            .map(|s| ((1.0 - self.shrinkage) * s * s + iso).sqrt())
            .collect()
    }

    /// The normal variates εⱼ of one draw, truncated if configured.
    pub fn draw_variates(&self, rng: &mut ChaCha8Rng) -> Vec<f64> {
        (0..self.pca.modes())
            .map(|_| {
                loop {
                    let e: f64 = StandardNormal.sample(rng);
                    match self.truncation {
                        Some(c) if e.abs() > c => continue,
                        _ => break e,
                    }
                }
            })
            .collect()
    }

    /// One new latent.
    pub fn sample(&self, rng: &mut ChaCha8Rng) -> Vec<f64> {
        // Without shrinkage the training σⱼ themselves, so earlier cohorts replay bit for bit.
        let mode_sd = if self.shrinkage > 0.0 {
            self.mode_sd()
        } else {
            self.pca.sd.clone()
        };
        let scores: Vec<f64> = self
            .draw_variates(rng)
            .iter()
            .zip(&mode_sd)
            .map(|(e, sd)| self.sigma_scale * sd * e)
            .collect();
        let mut z = self.pca.latent(&scores);
        let d = self.pca.dimension();
        if self.shrinkage > 0.0 && self.pca.modes() < d {
            let sd = self.sigma_scale * self.isotropic_variance().sqrt();
            let mut noise: Vec<f64> = (0..d).map(|_| StandardNormal.sample(rng)).collect();
            for u in &self.pca.components {
                let along: f64 = u.iter().zip(&noise).map(|(a, b)| a * b).sum();
                for (n, uj) in noise.iter_mut().zip(u) {
                    *n -= along * uj;
                }
            }
            for (zj, n) in z.iter_mut().zip(&noise) {
                *zj += sd * n;
            }
        }
        z
    }

    /// The covariance of the untruncated model (d × d):
    /// s² [U diag((1 − ρ) σ² + ρ m) Uᵀ + ρ m (I − U Uᵀ)].
    pub fn covariance(&self) -> Vec<Vec<f64>> {
        let d = self.pca.dimension();
        let scale2 = self.sigma_scale.powi(2);
        let iso = scale2 * self.isotropic_variance();
        // U diag(v − ρ m) Uᵀ + ρ m I, with v the drawn mode variances.
        let excess: Vec<f64> = self
            .mode_sd()
            .iter()
            .map(|s| scale2 * s * s - iso)
            .collect();
        (0..d)
            .map(|i| {
                (0..d)
                    .map(|j| {
                        let along: f64 = self
                            .pca
                            .components
                            .iter()
                            .zip(&excess)
                            .map(|(u, v)| v * u[i] * u[j])
                            .sum();
                        along + if i == j { iso } else { 0.0 }
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
    use crate::latent_models::test_latents::anisotropic;
    use crate::stats::distributions::{normal_cdf, normal_pdf};
    use crate::stats::multivariate::{covariance, mean_vector};
    use rand::SeedableRng;

    fn fitted(config: PcaGaussianConfig) -> PcaGaussian {
        let latents = anisotropic(20, 8, 1, |j| 0.5 + 0.3 * j as f64);
        PcaGaussian::fit(&latents, &config).unwrap()
    }

    #[test]
    fn many_draws_have_the_fitted_mean_and_covariance() {
        let config = PcaGaussianConfig {
            sigma_scale: 1.3,
            ..PcaGaussianConfig::default()
        };
        let g = fitted(config);
        let n = 20_000;
        let draws = LatentSampler::PcaGaussian(g.clone()).sample_many(n, 5);
        let (mean, cov, want) = (
            mean_vector(&draws).unwrap(),
            covariance(&draws).unwrap(),
            g.covariance(),
        );
        for i in 0..8 {
            // standard errors of a sample mean and of a sample covariance of a Gaussian
            let se_mean = (want[i][i] / n as f64).sqrt();
            assert!((mean[i] - g.pca.mean[i]).abs() < 4.5 * se_mean, "mean {i}");
            for j in 0..8 {
                let se = ((want[i][i] * want[j][j] + want[i][j].powi(2)) / n as f64).sqrt();
                assert!((cov[i][j] - want[i][j]).abs() < 4.5 * se, "cov ({i}, {j})");
            }
        }
    }

    #[test]
    fn shrunk_draws_have_the_shrunk_covariance_inside_and_outside_the_span() {
        // 12 latents in 20 dimensions: 11 modes, so 9 directions are outside their span.
        let latents = anisotropic(12, 20, 3, |j| 0.3 + 0.2 * j as f64);
        let rho = 0.4;
        let g = PcaGaussian::fit(
            &latents,
            &PcaGaussianConfig {
                shrinkage: Some(Shrinkage::Intensity(rho)),
                sigma_scale: 1.2,
                ..PcaGaussianConfig::default()
            },
        )
        .unwrap();
        assert_eq!(g.pca.modes(), 11);
        // The covariance is s²[(1 − ρ) S + ρ m I] with S the training latents' (n − 1).
        let s = covariance(&latents).unwrap();
        let m = (0..20).map(|i| s[i][i]).sum::<f64>() / 20.0;
        let want = g.covariance();
        for i in 0..20 {
            for j in 0..20 {
                let exact = 1.44 * ((1.0 - rho) * s[i][j] + if i == j { rho * m } else { 0.0 });
                assert!((want[i][j] - exact).abs() < 1e-10, "({i}, {j})");
            }
        }
        let n = 20_000;
        let draws = LatentSampler::PcaGaussian(g.clone()).sample_many(n, 9);
        let cov = covariance(&draws).unwrap();
        for i in 0..20 {
            for j in 0..20 {
                let se = ((want[i][i] * want[j][j] + want[i][j].powi(2)) / n as f64).sqrt();
                assert!((cov[i][j] - want[i][j]).abs() < 4.5 * se, "cov ({i}, {j})");
            }
        }
    }

    #[test]
    fn no_shrinkage_draws_what_an_unshrunk_sampler_draws_bit_for_bit() {
        let plain = fitted(PcaGaussianConfig::default());
        let zero = fitted(PcaGaussianConfig {
            shrinkage: Some(Shrinkage::Intensity(0.0)),
            ..PcaGaussianConfig::default()
        });
        let bits = |g: &PcaGaussian| {
            let draws = LatentSampler::PcaGaussian(g.clone()).sample_many(4, 11);
            draws
                .iter()
                .flatten()
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&plain), bits(&zero));
        // A sampler stored before shrinkage existed reads back as unshrunk.
        let mut json = serde_json::to_value(&plain).unwrap();
        json.as_object_mut().unwrap().remove("shrinkage");
        let old: PcaGaussian = serde_json::from_value(json).unwrap();
        assert_eq!(old, plain);
    }

    #[test]
    fn truncation_bounds_every_mode_and_shrinks_its_variance_as_predicted() {
        let c = 1.5;
        let g = fitted(PcaGaussianConfig {
            truncation: Some(c),
            ..PcaGaussianConfig::default()
        });
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = 20_000;
        let mut sum_sq = vec![0.0; g.pca.modes()];
        for _ in 0..n {
            let z = g.sample(&mut rng);
            for (k, (s, sd)) in g.pca.scores(&z).iter().zip(&g.pca.sd).enumerate() {
                let e = s / sd;
                assert!(e.abs() <= c + 1e-9, "mode {k}: {e}");
                sum_sq[k] += e * e / n as f64;
            }
        }
        let var = 1.0 - 2.0 * c * normal_pdf(c) / (2.0 * normal_cdf(c) - 1.0);
        // the variance of e² for a normal truncated at 1.5 is below 0.5; 5 standard errors
        let tol = 5.0 * (0.5 / n as f64).sqrt();
        for v in sum_sq {
            assert!((v - var).abs() < tol, "variance {v} vs {var}");
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_draws_bit_for_bit_even_after_serde() {
        let sampler = LatentSampler::PcaGaussian(fitted(PcaGaussianConfig {
            truncation: Some(2.0),
            ..PcaGaussianConfig::default()
        }));
        let json = serde_json::to_string(&sampler).unwrap();
        let restored: LatentSampler = serde_json::from_str(&json).unwrap();
        let (a, b) = (sampler.sample_many(5, 42), restored.sample_many(5, 42));
        let bits = |v: &Vec<Vec<f64>>| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&b));
        assert_ne!(bits(&a), bits(&sampler.sample_many(5, 43)));
    }

    #[test]
    fn draws_stay_in_the_span_of_the_training_latents_when_n_is_below_d() {
        let latents = anisotropic(16, 64, 4, |_| 1.0);
        let g = PcaGaussian::fit(&latents, &PcaGaussianConfig::default()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let z = g.sample(&mut rng);
        let back = g.pca.latent(&g.pca.scores(&z));
        assert!(z.iter().zip(&back).all(|(a, b)| (a - b).abs() < 1e-10));
    }

    #[test]
    fn bad_parameters_are_refused() {
        let latents = anisotropic(5, 3, 1, |_| 1.0);
        for config in [
            PcaGaussianConfig {
                truncation: Some(0.0),
                ..PcaGaussianConfig::default()
            },
            PcaGaussianConfig {
                sigma_scale: -1.0,
                ..PcaGaussianConfig::default()
            },
        ] {
            assert!(matches!(
                PcaGaussian::fit(&latents, &config),
                Err(LatentModelError::Domain { .. })
            ));
        }
    }
}
