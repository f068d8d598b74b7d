//! What a mixture means to the model: the convex combination `z = Σ αᵢ z_{iᵢ}` of learned
//! latents (plus fitted anchors' latents and optional Gaussian noise scaled by the training
//! latents' spread), and the same combination of the shapes' unit-ball transforms, so a
//! generated mesh can be returned in the training meshes' units (DESIGN §1.3, §3).

use rand::RngExt;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use crate::geometry::normalize::{BlendError, UnitBallTransform};

/// Which training shapes a generated shape combines, and how much of each.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mixture {
    /// Distinct training indices.
    pub indices: Vec<usize>,
    /// Convex weights, one per index.
    pub weights: Vec<f64>,
}

impl Mixture {
    /// `Σ αᵢ z_{iᵢ}` over rows of `latents` (each of the latent dimension), accumulated in f64.
    pub fn mix_latents(&self, latents: &[Vec<f32>]) -> Vec<f32> {
        self.mix_f64(latents)
            .into_iter()
            .map(|v| v as f32)
            .collect()
    }

    fn mix_f64(&self, latents: &[Vec<f32>]) -> Vec<f64> {
        let dim = latents.first().map_or(0, Vec::len);
        let mut z = vec![0.0f64; dim];
        for (&i, &w) in self.indices.iter().zip(&self.weights) {
            for (acc, &v) in z.iter_mut().zip(&latents[i]) {
                *acc += w * f64::from(v);
            }
        }
        z
    }

    /// The same convex combination of the shapes' unit-ball transforms.
    pub fn mix_transforms(
        &self,
        transforms: &[UnitBallTransform],
    ) -> Result<UnitBallTransform, BlendError> {
        UnitBallTransform::blend(&self.transform_parts(transforms))
    }

    /// Each chosen shape's transform with its weight, the parts of the blend.
    fn transform_parts<'t>(
        &self,
        transforms: &'t [UnitBallTransform],
    ) -> Vec<(f64, &'t UnitBallTransform)> {
        self.indices
            .iter()
            .zip(&self.weights)
            .map(|(&i, &w)| (w, &transforms[i]))
            .collect()
    }
}

/// Per-dimension sample standard deviation of the training latents (0 for one latent).
pub fn latent_std(latents: &[Vec<f32>]) -> Vec<f64> {
    let n = latents.len();
    let dim = latents.first().map_or(0, Vec::len);
    if n < 2 {
        return vec![0.0; dim];
    }
    (0..dim)
        .map(|d| {
            let mean = latents.iter().map(|z| f64::from(z[d])).sum::<f64>() / n as f64;
            let var = latents
                .iter()
                .map(|z| (f64::from(z[d]) - mean).powi(2))
                .sum::<f64>()
                / (n - 1) as f64;
            var.sqrt()
        })
        .collect()
}

/// Stream tag of the latent-noise draws.
const NOISE_STREAM: u64 = 0x4e4f_4953;

/// The mixed latent of `mixture` plus Gaussian noise of `noise` training standard
/// deviations per dimension, drawn from `seed`. With `noise` = 0 it is exactly
/// [`Mixture::mix_latents`], so cohorts without noise are unchanged.
pub fn noisy_latent(mixture: &Mixture, latents: &[Vec<f32>], noise: f64, seed: u64) -> Vec<f32> {
    if noise == 0.0 {
        return mixture.mix_latents(latents);
    }
    let std = latent_std(latents);
    let mut rng = crate::sdf::data::batch::stream_rng(seed, 0, 0, NOISE_STREAM);
    let mut z = mixture.mix_f64(latents);
    for (acc, s) in z.iter_mut().zip(std) {
        let g: f64 = rng.sample(StandardNormal);
        *acc += noise * s * g;
    }
    z.into_iter().map(|v| v as f32).collect()
}

/// A fitted latent (an anchor) with its weight in a mixture.
#[derive(Debug, Clone, Copy)]
pub struct AnchorPart<'a> {
    /// Its share of the mixture.
    pub weight: f64,
    /// Its latent code (the model's latent dimension).
    pub latent: &'a [f32],
    /// Its mesh's unit-ball transform, blended like the training shapes'.
    pub transform: &'a UnitBallTransform,
}

/// Why a mixture cannot be turned into a latent.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MixingError {
    /// The stored transforms cannot be blended (a damaged manifest).
    #[error("cannot blend the shapes' transforms: {0}")]
    Blend(#[from] BlendError),
    /// An anchor's latent does not fit the model.
    #[error("anchor {index} has {found} latent values, the model {expected}")]
    AnchorDimension {
        /// Position of the anchor in the mixture's anchor list.
        index: usize,
        /// Its latent length.
        found: usize,
        /// The model's latent dimension.
        expected: usize,
    },
}

/// The latent and the blended transform of `mixture` over the training shapes plus `anchors`:
/// the training part with `latent_noise` (scaled by the training latents' spread, drawn from
/// `noise_seed`), then each anchor's weighted latent.
pub fn anchored_latent(
    mixture: &Mixture,
    latents: &[Vec<f32>],
    transforms: &[UnitBallTransform],
    anchors: &[AnchorPart<'_>],
    latent_noise: f64,
    noise_seed: u64,
) -> Result<(UnitBallTransform, Vec<f32>), MixingError> {
    let mut latent = noisy_latent(mixture, latents, latent_noise, noise_seed);
    let mut parts = mixture.transform_parts(transforms);
    for (index, anchor) in anchors.iter().enumerate() {
        if anchor.latent.len() != latent.len() {
            return Err(MixingError::AnchorDimension {
                index,
                found: anchor.latent.len(),
                expected: latent.len(),
            });
        }
        for (acc, &v) in latent.iter_mut().zip(anchor.latent) {
            *acc = (f64::from(*acc) + anchor.weight * f64::from(v)) as f32;
        }
        parts.push((anchor.weight, anchor.transform));
    }
    Ok((UnitBallTransform::blend(&parts)?, latent))
}

/// Latent sets for the tests of mixing and of latent selection.
#[cfg(test)]
pub(crate) mod test_support {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// 20 latents in 4 dimensions: a tight cluster of 16 around the origin and 4 outliers.
    pub(crate) fn clustered_latents() -> Vec<Vec<f32>> {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut latents: Vec<Vec<f32>> = (0..16)
            .map(|_| (0..4).map(|_| rng.random::<f32>() * 0.1).collect())
            .collect();
        for d in 0..4 {
            let mut z = vec![0.0; 4];
            z[d] = 3.0;
            latents.push(z);
        }
        latents
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::clustered_latents;
    use super::*;

    fn mixture() -> Mixture {
        Mixture {
            indices: vec![1, 17, 4],
            weights: vec![0.2, 0.5, 0.3],
        }
    }

    #[test]
    fn zero_noise_reproduces_the_plain_mixed_latent_bit_for_bit() {
        let latents = clustered_latents();
        let m = mixture();
        for seed in 0..20 {
            assert_eq!(
                noisy_latent(&m, &latents, 0.0, seed),
                m.mix_latents(&latents)
            );
        }
    }

    #[test]
    fn noise_has_the_requested_scale_per_dimension() {
        let latents = clustered_latents();
        let std = latent_std(&latents);
        let m = mixture();
        let base = m.mix_latents(&latents);
        let (scale, draws) = (0.5, 4000);
        let mut sum = [0.0f64; 4];
        let mut sum_sq = [0.0f64; 4];
        for seed in 0..draws {
            let z = noisy_latent(&m, &latents, scale, seed);
            assert_eq!(z, noisy_latent(&m, &latents, scale, seed), "deterministic");
            for d in 0..4 {
                let e = f64::from(z[d] - base[d]) / (scale * std[d]);
                sum[d] += e;
                sum_sq[d] += e * e;
            }
        }
        for d in 0..4 {
            let mean = sum[d] / draws as f64;
            let var = sum_sq[d] / draws as f64 - mean * mean;
            // Standard normal: the mean's standard error is 1/√4000 ≈ 0.016, the variance's
            // ≈ √(2/4000) ≈ 0.022.
            assert!(mean.abs() < 0.06, "dimension {d}: mean {mean}");
            assert!((var - 1.0).abs() < 0.09, "dimension {d}: variance {var}");
        }
    }

    #[test]
    fn anchors_add_their_weighted_latent_and_transform() {
        let latents = vec![vec![1.0f32, 0.0], vec![0.0, 1.0]];
        let transforms = [UnitBallTransform::IDENTITY; 2];
        let anchor_transform = UnitBallTransform {
            centre: [10.0, 0.0, 0.0],
            radius: 3.0,
        };
        let mixture = Mixture {
            indices: vec![1],
            weights: vec![0.5],
        };
        let anchor = AnchorPart {
            weight: 0.5,
            latent: &[4.0, 2.0],
            transform: &anchor_transform,
        };
        let (t, z) = anchored_latent(&mixture, &latents, &transforms, &[anchor], 0.0, 1).unwrap();
        assert_eq!(z, vec![2.0, 1.5]);
        assert_eq!(t.centre, [5.0, 0.0, 0.0]);
        assert!((t.radius - 2.0).abs() < 1e-12, "{t:?}");
        let short = AnchorPart {
            latent: &[1.0],
            ..anchor
        };
        assert!(matches!(
            anchored_latent(&mixture, &latents, &transforms, &[short], 0.0, 1),
            Err(MixingError::AnchorDimension { index: 0, .. })
        ));
    }
}
