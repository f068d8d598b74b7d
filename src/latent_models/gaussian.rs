//! A Gaussian in the latents' principal components: new latent z = μ + Σⱼ s σⱼ εⱼ uⱼ with
//! independent standard normal εⱼ, σⱼ the training latents' spread along mode j and s an
//! optional scale. With a truncation c each εⱼ is redrawn until |εⱼ| ≤ c (rejection per
//! mode), the practice of statistical shape models for virtual cohorts (e.g. ±3 σ per
//! mode for TAVI anatomies), which keeps every shape within the plausible range of each
//! mode; the per-mode variance then shrinks to 1 − 2cφ(c)/(2Φ(c) − 1) of σⱼ².

use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::LatentModelError;
use super::pca::{ModeSelection, Pca};

/// How to fit and draw from the Gaussian.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PcaGaussianConfig {
    /// Which principal modes to keep.
    pub modes: ModeSelection,
    /// Redraw each mode's normal variate until it lies within ±c (c > 0); none: no limit.
    pub truncation: Option<f64>,
    /// Multiplies every σⱼ (> 0; 1 reproduces the training spread).
    pub sigma_scale: f64,
}

impl Default for PcaGaussianConfig {
    fn default() -> Self {
        Self {
            modes: ModeSelection::AllNonZero,
            truncation: None,
            sigma_scale: 1.0,
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
        Ok(Self {
            pca: Pca::fit(latents, config.modes)?,
            truncation: config.truncation,
            sigma_scale: config.sigma_scale,
        })
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
        let scores: Vec<f64> = self
            .draw_variates(rng)
            .iter()
            .zip(&self.pca.sd)
            .map(|(e, sd)| self.sigma_scale * sd * e)
            .collect();
        self.pca.latent(&scores)
    }

    /// The covariance of the untruncated model, U diag(s² σ²) Uᵀ (d × d).
    pub fn covariance(&self) -> Vec<Vec<f64>> {
        let d = self.pca.dimension();
        let var: Vec<f64> = self
            .pca
            .sd
            .iter()
            .map(|s| (self.sigma_scale * s).powi(2))
            .collect();
        (0..d)
            .map(|i| {
                (0..d)
                    .map(|j| {
                        self.pca
                            .components
                            .iter()
                            .zip(&var)
                            .map(|(u, v)| v * u[i] * u[j])
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
