//! Density models of a model's training latents that draw new latents — samplers that aim
//! at the population rather than at convex combinations of the training patients.
//!
//! Training sets are small (n ≈ 16–100 shapes) in a large latent space (d ≈ 64–256), so
//! every model here first reduces to the latents' principal components ([`pca`], via the
//! n × n Gram matrix), where at most n − 1 directions carry variance:
//! * [`gaussian::PcaGaussian`]: independent normal scores per mode, optionally truncated
//!   at ±c σ per mode (the statistical-shape-model practice for virtual TAVI cohorts),
//!   scaled, and with its covariance shrunk towards a multiple of the identity
//!   ([`shrinkage`]: a sample covariance of n ≈ d latents is too narrow in its trailing
//!   modes);
//! * [`mixture::PcaMixture`]: a Gaussian mixture on the leading whitened modes (EM from a
//!   k-means++ start, regularised covariances, number of components given or chosen by
//!   BIC) with the remaining modes independent normal, for populations with sub-groups.
//!
//! Fitted samplers serialise with serde so they can be stored with the model. Draws are a
//! pure function of the sampler and the seed (ChaCha8 and `rand_distr`'s ziggurat normal),
//! so a cohort replays bit for bit on the same build.

pub mod em;
pub mod gaussian;
pub mod mixture;
pub mod pca;
pub mod shrinkage;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Why a latent model cannot be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LatentModelError {
    /// Fewer latents than the model needs.
    #[error("{what} needs at least {needed} latents, got {got}")]
    TooFew {
        /// The model or step.
        what: &'static str,
        /// The minimum.
        needed: usize,
        /// What was given.
        got: usize,
    },
    /// Latents of different lengths, or no dimensions.
    #[error("latent {index} has {got} values, expected {expected}")]
    Dimension {
        /// The offending latent.
        index: usize,
        /// Its length.
        got: usize,
        /// The first latent's length.
        expected: usize,
    },
    /// A latent value is NaN or infinite.
    #[error("latent {index} has a value that is not finite")]
    NotFinite {
        /// The offending latent.
        index: usize,
    },
    /// The latents do not vary (all identical), so there is no distribution to fit.
    #[error("the latents are identical: no variation to model")]
    NoVariation,
    /// A parameter out of range.
    #[error("{what}: {detail}")]
    Domain {
        /// The parameter.
        what: &'static str,
        /// Its allowed range and value.
        detail: String,
    },
}

/// A sampler and its parameters as a cohort request names them, before fitting.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SamplerConfig {
    /// Gaussian in the principal components.
    PcaGaussian(gaussian::PcaGaussianConfig),
    /// Gaussian mixture in the whitened principal components.
    PcaMixture(mixture::PcaMixtureConfig),
}

impl SamplerConfig {
    /// Fits the configured sampler to the training `latents`.
    pub fn fit(&self, latents: &[Vec<f64>]) -> Result<LatentSampler, LatentModelError> {
        Ok(match self {
            Self::PcaGaussian(c) => {
                LatentSampler::PcaGaussian(gaussian::PcaGaussian::fit(latents, c)?)
            }
            Self::PcaMixture(c) => LatentSampler::PcaMixture(mixture::PcaMixture::fit(latents, c)?),
        })
    }
}

/// A fitted sampler of new latents, as stored with a model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum LatentSampler {
    /// Gaussian in the principal components.
    PcaGaussian(gaussian::PcaGaussian),
    /// Gaussian mixture in the whitened principal components.
    PcaMixture(mixture::PcaMixture),
}

impl LatentSampler {
    /// One new latent drawn with `rng`.
    pub fn sample(&self, rng: &mut ChaCha8Rng) -> Vec<f64> {
        match self {
            Self::PcaGaussian(g) => g.sample(rng),
            Self::PcaMixture(m) => m.sample(rng),
        }
    }

    /// `count` latents from a generator seeded with `seed`.
    pub fn sample_many(&self, count: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..count).map(|_| self.sample(&mut rng)).collect()
    }

    /// Latent dimension d.
    pub fn dimension(&self) -> usize {
        match self {
            Self::PcaGaussian(g) => g.pca.dimension(),
            Self::PcaMixture(m) => m.pca.dimension(),
        }
    }
}

/// Checks that there are at least `needed` latents of one length d ≥ 1, all finite;
/// returns d.
pub(crate) fn check_latents(
    what: &'static str,
    latents: &[Vec<f64>],
    needed: usize,
) -> Result<usize, LatentModelError> {
    if latents.len() < needed {
        return Err(LatentModelError::TooFew {
            what,
            needed,
            got: latents.len(),
        });
    }
    let d = latents[0].len();
    for (index, z) in latents.iter().enumerate() {
        if z.len() != d || d == 0 {
            return Err(LatentModelError::Dimension {
                index,
                got: z.len(),
                expected: d,
            });
        }
        if z.iter().any(|v| !v.is_finite()) {
            return Err(LatentModelError::NotFinite { index });
        }
    }
    Ok(d)
}

#[cfg(test)]
pub(crate) mod test_latents {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// `n` latents of dimension `d` with independent normal coordinates, coordinate j
    /// having standard deviation `sd(j)` and mean `0.1 j`.
    pub fn anisotropic(n: usize, d: usize, seed: u64, sd: impl Fn(usize) -> f64) -> Vec<Vec<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                (0..d)
                    .map(|j| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        0.1 * j as f64 + sd(j) * z
                    })
                    .collect()
            })
            .collect()
    }
}
