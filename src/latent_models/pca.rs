//! Principal components of n latents of dimension d, from the eigen-decomposition (the
//! symmetric Jacobi solver of [`crate::stats::linalg`]) of whichever is smaller: the n × n
//! Gram matrix of the centred latents — the usual case, n ≈ 16–100 shapes in d ≈ 64–256
//! dimensions, with at most n − 1 non-zero modes — or the d × d scatter matrix.
//!
//! With X the centred n × d latents and X Xᵀ = V Λ Vᵀ, the unit principal directions are
//! uⱼ = Xᵀ vⱼ / √λⱼ and the variance along uⱼ is σⱼ² = λⱼ / (n − 1): the eigenpairs of the
//! sample covariance Xᵀ X / (n − 1) without forming that d × d matrix. Modes with
//! λ ≤ 1e-12 λ_max carry no variance and are dropped.

use serde::{Deserialize, Serialize};

use super::{LatentModelError, check_latents};
use crate::stats::linalg::symmetric_eigen;

/// Eigenvalues below this share of the largest count as zero.
const ZERO_MODE: f64 = 1e-12;

/// Which modes to keep.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", content = "value", rename_all = "snake_case")]
pub enum ModeSelection {
    /// The fewest leading modes whose variance reaches this share (0 < share ≤ 1) of the
    /// total.
    VarianceShare(f64),
    /// The leading modes, at most this many (≥ 1).
    Count(usize),
    /// Every mode with non-zero variance.
    AllNonZero,
}

/// Mean and leading principal modes of a set of latents.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pca {
    /// Mean latent μ.
    pub mean: Vec<f64>,
    /// Unit principal directions uⱼ (each of length d), by decreasing variance.
    pub components: Vec<Vec<f64>>,
    /// Standard deviation σⱼ along each kept direction.
    pub sd: Vec<f64>,
    /// Total variance of the latents (the sum over all modes, kept or not).
    pub total_variance: f64,
}

impl Pca {
    /// Fits μ and the modes of `latents` (≥ 2, not all identical) and keeps those chosen.
    pub fn fit(latents: &[Vec<f64>], modes: ModeSelection) -> Result<Self, LatentModelError> {
        check_selection(modes)?;
        let d = check_latents("principal components", latents, 2)?;
        let n = latents.len();
        let (mean, centred) = centre(latents);
        let (values, directions) = if n <= d {
            gram_modes(&centred)
        } else {
            scatter_modes(&centred)
        };
        let largest = values.first().copied().unwrap_or(0.0);
        if largest <= 0.0 {
            return Err(LatentModelError::NoVariation);
        }
        let nonzero = values
            .iter()
            .take_while(|l| **l > ZERO_MODE * largest)
            .count();
        let total: f64 = values[..nonzero].iter().sum();
        let keep = kept_modes(&values[..nonzero], total, modes);
        let components = directions.into_iter().take(keep).collect();
        let variance = |lambda: &f64| lambda / (n - 1) as f64;
        Ok(Self {
            mean,
            components,
            sd: values[..keep].iter().map(|l| variance(l).sqrt()).collect(),
            total_variance: total / (n - 1) as f64,
        })
    }

    /// Latent dimension d.
    pub fn dimension(&self) -> usize {
        self.mean.len()
    }

    /// Number of kept modes.
    pub fn modes(&self) -> usize {
        self.sd.len()
    }

    /// Share of the total variance that the kept modes explain.
    pub fn explained_share(&self) -> f64 {
        self.sd.iter().map(|s| s * s).sum::<f64>() / self.total_variance
    }

    /// Coordinates uⱼ · (z − μ) of `latent` along the kept modes.
    pub fn scores(&self, latent: &[f64]) -> Vec<f64> {
        let centred: Vec<f64> = latent.iter().zip(&self.mean).map(|(a, m)| a - m).collect();
        self.components.iter().map(|u| dot(u, &centred)).collect()
    }

    /// μ + Σⱼ scoresⱼ uⱼ.
    pub fn latent(&self, scores: &[f64]) -> Vec<f64> {
        let mut z = self.mean.clone();
        for (s, u) in scores.iter().zip(&self.components) {
            for (zj, uj) in z.iter_mut().zip(u) {
                *zj += s * uj;
            }
        }
        z
    }
}

/// Eigenvalues λ of X Xᵀ (descending) and unit directions Xᵀ v / √λ, for n ≤ d.
fn gram_modes(centred: &[Vec<f64>]) -> (Vec<f64>, Vec<Vec<f64>>) {
    let gram: Vec<Vec<f64>> = centred
        .iter()
        .map(|a| centred.iter().map(|b| dot(a, b)).collect())
        .collect();
    let (values, vectors) = symmetric_eigen(&gram);
    let d = centred[0].len();
    let directions = vectors
        .iter()
        .zip(&values)
        .filter(|(_, lambda)| **lambda > 0.0)
        .map(|(v, lambda)| {
            let scale = 1.0 / lambda.sqrt();
            (0..d)
                .map(|j| scale * v.iter().zip(centred).map(|(vi, x)| vi * x[j]).sum::<f64>())
                .collect()
        })
        .collect();
    (values, directions)
}

/// Eigenvalues and unit eigenvectors of the d × d scatter matrix Xᵀ X, for d < n.
fn scatter_modes(centred: &[Vec<f64>]) -> (Vec<f64>, Vec<Vec<f64>>) {
    let d = centred[0].len();
    let scatter: Vec<Vec<f64>> = (0..d)
        .map(|i| {
            (0..d)
                .map(|j| centred.iter().map(|x| x[i] * x[j]).sum())
                .collect()
        })
        .collect();
    symmetric_eigen(&scatter)
}

/// The mean of `latents` (≥ 1, all of one length) and every latent minus it.
pub(crate) fn centre(latents: &[Vec<f64>]) -> (Vec<f64>, Vec<Vec<f64>>) {
    let n = latents.len();
    let d = latents.first().map_or(0, Vec::len);
    let mean: Vec<f64> = (0..d)
        .map(|j| latents.iter().map(|z| z[j]).sum::<f64>() / n as f64)
        .collect();
    let centred = latents
        .iter()
        .map(|z| z.iter().zip(&mean).map(|(a, m)| a - m).collect())
        .collect();
    (mean, centred)
}

pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn check_selection(modes: ModeSelection) -> Result<(), LatentModelError> {
    let bad = match modes {
        ModeSelection::VarianceShare(s) => !(s > 0.0 && s <= 1.0),
        ModeSelection::Count(k) => k == 0,
        ModeSelection::AllNonZero => false,
    };
    if bad {
        return Err(LatentModelError::Domain {
            what: "mode selection",
            detail: format!("{modes:?}: a share must be in (0, 1] and a count ≥ 1"),
        });
    }
    Ok(())
}

/// How many of the non-zero `values` (descending, summing to `total`) to keep.
fn kept_modes(values: &[f64], total: f64, modes: ModeSelection) -> usize {
    match modes {
        ModeSelection::AllNonZero => values.len(),
        ModeSelection::Count(k) => k.min(values.len()),
        ModeSelection::VarianceShare(share) => {
            let mut sum = 0.0;
            for (k, v) in values.iter().enumerate() {
                sum += v;
                // a relative slack so that share = 1 keeps exactly the non-zero modes
                if sum >= share * total * (1.0 - 1e-12) {
                    return k + 1;
                }
            }
            values.len()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::latent_models::test_latents::anisotropic;
    use crate::stats::multivariate::covariance;

    #[test]
    fn gram_modes_are_the_eigenpairs_of_the_sample_covariance() {
        let latents = anisotropic(12, 6, 1, |j| 1.0 + j as f64);
        let pca = Pca::fit(&latents, ModeSelection::AllNonZero).unwrap();
        assert_eq!(pca.modes(), 6);
        let (values, _) = symmetric_eigen(&covariance(&latents).unwrap());
        let cov = covariance(&latents).unwrap();
        for ((sd, lambda), u) in pca.sd.iter().zip(&values).zip(&pca.components) {
            assert!(
                (sd * sd - lambda).abs() < 1e-10 * lambda,
                "{sd}² vs {lambda}"
            );
            // Σ u = σ² u and |u| = 1
            for i in 0..6 {
                let su: f64 = (0..6).map(|k| cov[i][k] * u[k]).sum();
                assert!((su - sd * sd * u[i]).abs() < 1e-9);
            }
            assert!((dot(u, u) - 1.0).abs() < 1e-12);
        }
        assert!((pca.explained_share() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn the_gram_and_scatter_routes_give_the_same_modes() {
        let latents = anisotropic(12, 6, 5, |j| 1.0 + j as f64);
        let (_, centred) = centre(&latents);
        let (gv, gu) = gram_modes(&centred);
        let (sv, su) = scatter_modes(&centred);
        for k in 0..6 {
            assert!((gv[k] - sv[k]).abs() < 1e-10 * sv[0], "λ{k}");
            assert!((dot(&gu[k], &su[k]).abs() - 1.0).abs() < 1e-10, "u{k}");
        }
    }

    #[test]
    fn with_fewer_latents_than_dimensions_there_are_n_minus_one_modes_that_reconstruct() {
        let latents = anisotropic(16, 64, 2, |_| 1.0);
        let pca = Pca::fit(&latents, ModeSelection::AllNonZero).unwrap();
        assert_eq!(pca.modes(), 15);
        for z in &latents {
            let back = pca.latent(&pca.scores(z));
            let err = back
                .iter()
                .zip(z)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-10, "reconstruction error {err}");
        }
    }

    #[test]
    fn a_variance_share_keeps_the_fewest_modes_that_reach_it() {
        let latents = anisotropic(30, 5, 3, |j| [10.0, 5.0, 1.0, 0.5, 0.1][j]);
        let pca = Pca::fit(&latents, ModeSelection::VarianceShare(0.9)).unwrap();
        let all = Pca::fit(&latents, ModeSelection::AllNonZero).unwrap();
        let share = |k: usize| all.sd[..k].iter().map(|s| s * s).sum::<f64>() / all.total_variance;
        let k = pca.modes();
        assert!(share(k) >= 0.9 && share(k - 1) < 0.9, "kept {k}");
        assert_eq!(
            Pca::fit(&latents, ModeSelection::Count(2)).unwrap().modes(),
            2
        );
    }

    #[test]
    fn degenerate_latents_are_refused_with_the_reason() {
        let one = vec![vec![1.0, 2.0]];
        assert!(matches!(
            Pca::fit(&one, ModeSelection::AllNonZero),
            Err(LatentModelError::TooFew {
                needed: 2,
                got: 1,
                ..
            })
        ));
        let same = vec![vec![1.0, 2.0]; 5];
        assert_eq!(
            Pca::fit(&same, ModeSelection::AllNonZero),
            Err(LatentModelError::NoVariation)
        );
        let ragged = vec![vec![1.0, 2.0], vec![1.0]];
        assert!(matches!(
            Pca::fit(&ragged, ModeSelection::AllNonZero),
            Err(LatentModelError::Dimension { index: 1, .. })
        ));
        let latents = anisotropic(5, 3, 1, |_| 1.0);
        assert!(Pca::fit(&latents, ModeSelection::VarianceShare(0.0)).is_err());
    }
}
