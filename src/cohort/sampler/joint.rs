//! A density sampler of latents *and* unit-ball transforms: each training shape is the row
//! [z ‖ t], z its latent and t = (ln r, cₓ, c_y, c_z) its transform (radius r, centre c in
//! mm), and the configured [`LatentSampler`] is fitted to those rows. A draw is split back
//! into a latent and the transform that serves it in mm, so sizes come out correlated with
//! shape as in the training population — a convex combination blends its parents'
//! transforms instead, which a sampled latent does not have.
//!
//! Each transform coordinate is standardised and then scaled to the latents' typical
//! per-dimension spread, so in the principal components it weighs like one latent
//! dimension: it neither dominates the modes (millimetres against latent units) nor
//! vanishes from them. A coordinate that does not vary is drawn at its constant value.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::engine::SampledLatent;
use crate::geometry::normalize::UnitBallTransform;
use crate::latent_models::{LatentModelError, LatentSampler, SamplerConfig};

/// Stream tag of a draw's generator, apart from the weights' stream of the same seed.
const SAMPLER_STREAM: u64 = 0x5341_4d50_4c45_5231;
/// Transform coordinates per shape: ln r and the centre.
const TRANSFORM_COORDS: usize = 4;

/// A fitted joint sampler.
#[derive(Debug, Clone, PartialEq)]
pub struct JointSampler {
    sampler: LatentSampler,
    latent_dim: usize,
    mean: [f64; TRANSFORM_COORDS],
    sd: [f64; TRANSFORM_COORDS],
    latent_spread: f64,
}

/// What a fitted sampler is, for provenance and reports.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct SamplerSummary {
    /// Principal modes drawn.
    pub modes: usize,
    /// Share of the joint variance they explain.
    pub explained_share: f64,
    /// Mixture components (1 for the Gaussian).
    pub components: usize,
    /// Covariance shrinkage intensity ρ (0: the sample covariance).
    pub shrinkage: f64,
}

impl JointSampler {
    /// Fits `config` to the training `latents` and their `transforms` (same order).
    pub fn fit(
        config: &SamplerConfig,
        latents: &[Vec<f32>],
        transforms: &[UnitBallTransform],
    ) -> Result<Self, LatentModelError> {
        if latents.len() != transforms.len() {
            return Err(LatentModelError::Domain {
                what: "joint sampler",
                detail: format!(
                    "{} latents but {} transforms",
                    latents.len(),
                    transforms.len()
                ),
            });
        }
        let latent_dim = latents.first().map_or(0, Vec::len);
        let coords: Vec<[f64; TRANSFORM_COORDS]> = transforms.iter().map(coordinates).collect();
        let (mean, sd) = mean_sd(&coords);
        let latent_spread = latent_spread(latents);
        let rows: Vec<Vec<f64>> = latents
            .iter()
            .zip(&coords)
            .map(|(z, t)| {
                let mut row: Vec<f64> = z.iter().map(|&v| f64::from(v)).collect();
                row.extend((0..TRANSFORM_COORDS).map(|k| latent_spread * (t[k] - mean[k]) / sd[k]));
                row
            })
            .collect();
        Ok(Self {
            sampler: config.fit(&rows)?,
            latent_dim,
            mean,
            sd,
            latent_spread,
        })
    }

    /// The latent and transform of the draw seeded `seed` (a pure function of both).
    pub fn draw(&self, seed: u64) -> SampledLatent {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ SAMPLER_STREAM);
        let row = self.sampler.sample(&mut rng);
        let (z, t) = row.split_at(self.latent_dim);
        let coord = |k: usize| self.mean[k] + self.sd[k] * t[k] / self.latent_spread;
        SampledLatent {
            latent: z.iter().map(|&v| v as f32).collect(),
            transform: UnitBallTransform {
                centre: [coord(1), coord(2), coord(3)],
                radius: coord(0).exp(),
            },
        }
    }

    /// Modes, explained variance and components of the fitted model.
    pub fn summary(&self) -> SamplerSummary {
        let (pca, components, shrinkage) = match &self.sampler {
            LatentSampler::PcaGaussian(g) => (&g.pca, 1, g.shrinkage),
            LatentSampler::PcaMixture(m) => (&m.pca, m.components.len(), 0.0),
        };
        SamplerSummary {
            modes: pca.modes(),
            explained_share: pca.explained_share(),
            components,
            shrinkage,
        }
    }
}

fn coordinates(t: &UnitBallTransform) -> [f64; TRANSFORM_COORDS] {
    [t.radius.ln(), t.centre[0], t.centre[1], t.centre[2]]
}

/// Per-coordinate mean and sample standard deviation (1 where a coordinate is constant,
/// so it stays at its mean).
fn mean_sd(
    coords: &[[f64; TRANSFORM_COORDS]],
) -> ([f64; TRANSFORM_COORDS], [f64; TRANSFORM_COORDS]) {
    let n = coords.len().max(1) as f64;
    let mean: [f64; TRANSFORM_COORDS] =
        std::array::from_fn(|k| coords.iter().map(|c| c[k]).sum::<f64>() / n);
    let sd = std::array::from_fn(|k| {
        let ss: f64 = coords.iter().map(|c| (c[k] - mean[k]).powi(2)).sum();
        let sd = (ss / (n - 1.0).max(1.0)).sqrt();
        if sd > 0.0 && sd.is_finite() { sd } else { 1.0 }
    });
    (mean, sd)
}

/// Root-mean per-dimension variance of the latents (1 when they do not vary).
fn latent_spread(latents: &[Vec<f32>]) -> f64 {
    let std = crate::sdf::inference::mixing::latent_std(latents);
    let ms = std.iter().map(|s| s * s).sum::<f64>() / std.len().max(1) as f64;
    if ms > 0.0 { ms.sqrt() } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::latent_models::gaussian::PcaGaussianConfig;
    use rand::RngExt;

    /// 60 shapes whose log-radius is 3 + the first latent coordinate (plus tiny noise), so
    /// size and shape are correlated; centres constant in z.
    fn population() -> (Vec<Vec<f32>>, Vec<UnitBallTransform>) {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let mut latents = Vec::new();
        let mut transforms = Vec::new();
        for _ in 0..60 {
            let z: Vec<f32> = (0..6).map(|_| rng.random_range(-0.5f32..0.5)).collect();
            let ln_r = 3.0 + f64::from(z[0]) + 0.01 * rng.random::<f64>();
            transforms.push(UnitBallTransform {
                centre: [10.0 * f64::from(z[1]), rng.random_range(-5.0..5.0), 7.0],
                radius: ln_r.exp(),
            });
            latents.push(z);
        }
        (latents, transforms)
    }

    #[test]
    fn draws_keep_the_correlation_of_size_and_shape_and_constant_coordinates() {
        let (latents, transforms) = population();
        let config = SamplerConfig::PcaGaussian(PcaGaussianConfig::default());
        let s = JointSampler::fit(&config, &latents, &transforms).unwrap();
        for seed in 0..200 {
            let d = s.draw(seed);
            assert_eq!(d.latent.len(), 6);
            // Exactly linear in the training rows, so exactly linear in every draw (the
            // draws stay in the span of the centred rows), up to the noise's small share.
            let predicted = 3.0 + f64::from(d.latent[0]);
            assert!(
                (d.transform.radius.ln() - predicted).abs() < 0.05,
                "seed {seed}"
            );
            assert!((d.transform.centre[2] - 7.0).abs() < 1e-9);
        }
        let bits = |d: &SampledLatent| d.latent.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&s.draw(5)), bits(&s.draw(5)));
        assert_ne!(bits(&s.draw(5)), bits(&s.draw(6)));
    }

    #[test]
    fn the_transform_spread_matches_the_training_spread() {
        let (latents, transforms) = population();
        let config = SamplerConfig::PcaGaussian(PcaGaussianConfig::default());
        let s = JointSampler::fit(&config, &latents, &transforms).unwrap();
        let ln_r: Vec<f64> = (0..4000).map(|i| s.draw(i).transform.radius.ln()).collect();
        let train: Vec<f64> = transforms.iter().map(|t| t.radius.ln()).collect();
        let sd = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        };
        // A Gaussian with the training covariance: the drawn sd matches the sample sd
        // within a few standard errors of 4000 draws (≈ 1.1 %).
        assert!(
            (sd(&ln_r) / sd(&train) - 1.0).abs() < 0.05,
            "{} vs {}",
            sd(&ln_r),
            sd(&train)
        );
        assert_eq!(s.summary().components, 1);
        assert!((s.summary().explained_share - 1.0).abs() < 1e-9);
    }

    #[test]
    fn mismatched_inputs_are_refused() {
        let (latents, transforms) = population();
        let config = SamplerConfig::PcaGaussian(PcaGaussianConfig::default());
        assert!(JointSampler::fit(&config, &latents, &transforms[1..]).is_err());
    }
}
