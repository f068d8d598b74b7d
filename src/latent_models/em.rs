//! Gaussian mixtures fitted by expectation–maximisation (Dempster, Laird & Rubin 1977) to
//! points in a low-dimensional space, started from k-means++ centres (Arthur & Vassilvitskii
//! 2007) drawn from a seed, so a fit is a deterministic function of its inputs.
//!
//! Every covariance gets `regularisation` × I added after each M-step (as scikit-learn's
//! `reg_covar`), which keeps it positive definite when a component holds fewer points than
//! dimensions — the usual case for a few dozen training shapes. A component whose
//! responsibilities vanish keeps its previous mean and covariance with a weight near zero.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::LatentModelError;
use crate::stats::linalg::{Matrix, cholesky, inverse_quadratic_form, log_det};

/// Shape of the component covariances.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CovarianceKind {
    /// Full covariance matrices.
    Full,
    /// Diagonal covariance matrices (fewer parameters for small training sets).
    Diagonal,
}

impl CovarianceKind {
    /// Free parameters of one covariance in `dim` dimensions.
    pub fn parameters(self, dim: usize) -> usize {
        match self {
            Self::Full => dim * (dim + 1) / 2,
            Self::Diagonal => dim,
        }
    }
}

/// One component of a mixture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Component {
    /// Mixing weight.
    pub weight: f64,
    /// Mean.
    pub mean: Vec<f64>,
    /// Covariance.
    pub covariance: Matrix,
    /// Lower Cholesky factor of the covariance (kept for sampling).
    pub cholesky: Matrix,
}

/// Settings of one EM fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmSettings {
    /// Number of components.
    pub components: usize,
    /// Covariance shape.
    pub covariance: CovarianceKind,
    /// Added to every covariance diagonal.
    pub regularisation: f64,
    /// Iteration limit.
    pub max_iterations: usize,
    /// Stop when the mean log-likelihood per point changes by less than this.
    pub tolerance: f64,
    /// Seed of the k-means++ start.
    pub seed: u64,
}

/// A fitted mixture.
#[derive(Debug, Clone, PartialEq)]
pub struct EmFit {
    /// Its components.
    pub components: Vec<Component>,
    /// Total log-likelihood of the points.
    pub log_likelihood: f64,
    /// EM iterations run.
    pub iterations: usize,
}

/// Fits `settings.components` Gaussians to `points` (n × dim, n ≥ components distinct).
pub fn fit_em(points: &[Vec<f64>], settings: &EmSettings) -> Result<EmFit, LatentModelError> {
    let k = settings.components;
    let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
    let centres = kmeans_plus_plus(points, k, &mut rng)?;
    let mut resp: Vec<Vec<f64>> = points
        .iter()
        .map(|x| {
            let nearest = (0..k)
                .min_by(|&a, &b| sq_dist(x, &centres[a]).total_cmp(&sq_dist(x, &centres[b])))
                .unwrap_or(0);
            (0..k).map(|c| (c == nearest) as u8 as f64).collect()
        })
        .collect();
    let mut components: Vec<Component> = centres
        .iter()
        .map(|c| isotropic(c.clone(), 1.0 / k as f64, 1.0))
        .collect();
    let mut previous = f64::NEG_INFINITY;
    let n = points.len() as f64;
    for iteration in 1..=settings.max_iterations.max(1) {
        m_step(points, &resp, &mut components, settings)?;
        let ll = e_step(points, &components, &mut resp);
        if (ll - previous).abs() / n < settings.tolerance || iteration == settings.max_iterations {
            return Ok(EmFit {
                components,
                log_likelihood: ll,
                iterations: iteration,
            });
        }
        previous = ll;
    }
    unreachable!("the loop returns on its last iteration")
}

fn isotropic(mean: Vec<f64>, weight: f64, variance: f64) -> Component {
    let dim = mean.len();
    let covariance: Matrix = (0..dim)
        .map(|i| {
            (0..dim)
                .map(|j| if i == j { variance } else { 0.0 })
                .collect()
        })
        .collect();
    let cholesky = covariance
        .iter()
        .map(|row| row.iter().map(|v| v.sqrt()).collect())
        .collect();
    Component {
        weight,
        mean,
        covariance,
        cholesky,
    }
}

fn sq_dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// k-means++ seeding: the first centre uniformly, each next one with probability
/// proportional to the squared distance to the nearest centre chosen so far.
pub fn kmeans_plus_plus(
    points: &[Vec<f64>],
    k: usize,
    rng: &mut ChaCha8Rng,
) -> Result<Vec<Vec<f64>>, LatentModelError> {
    if k == 0 || points.len() < k {
        return Err(LatentModelError::TooFew {
            what: "mixture components (points per component)",
            needed: k.max(1),
            got: points.len(),
        });
    }
    let mut centres = vec![points[rng.random_range(0..points.len())].clone()];
    let mut nearest: Vec<f64> = points.iter().map(|p| sq_dist(p, &centres[0])).collect();
    while centres.len() < k {
        let total: f64 = nearest.iter().sum();
        if total <= 0.0 {
            return Err(LatentModelError::TooFew {
                what: "mixture components (distinct latents)",
                needed: k,
                got: centres.len(),
            });
        }
        let mut target = rng.random::<f64>() * total;
        let mut pick = nearest.iter().rposition(|d| *d > 0.0).unwrap_or(0);
        for (i, d) in nearest.iter().enumerate() {
            if target < *d {
                pick = i;
                break;
            }
            target -= d;
        }
        centres.push(points[pick].clone());
        for (best, p) in nearest.iter_mut().zip(points) {
            *best = best.min(sq_dist(p, &points[pick]));
        }
    }
    Ok(centres)
}

fn m_step(
    points: &[Vec<f64>],
    resp: &[Vec<f64>],
    components: &mut [Component],
    settings: &EmSettings,
) -> Result<(), LatentModelError> {
    let dim = points[0].len();
    let n = points.len() as f64;
    for (c, component) in components.iter_mut().enumerate() {
        let nk: f64 = resp.iter().map(|r| r[c]).sum();
        component.weight = nk / n;
        if nk < 1e-10 {
            continue;
        }
        let mean: Vec<f64> = (0..dim)
            .map(|j| {
                points
                    .iter()
                    .zip(resp)
                    .map(|(x, r)| r[c] * x[j])
                    .sum::<f64>()
                    / nk
            })
            .collect();
        let cov = weighted_covariance(points, resp, c, &mean, nk, settings);
        component.cholesky = cholesky(&cov, "mixture component covariance").map_err(|_| {
            LatentModelError::Domain {
                what: "mixture regularisation",
                detail: format!("{} leaves a covariance singular", settings.regularisation),
            }
        })?;
        component.mean = mean;
        component.covariance = cov;
    }
    Ok(())
}

/// Σ_c = Σᵢ rᵢ_c (xᵢ − μ)(xᵢ − μ)ᵀ / N_c (off-diagonals zero for a diagonal model), plus
/// the regularisation on the diagonal.
fn weighted_covariance(
    points: &[Vec<f64>],
    resp: &[Vec<f64>],
    c: usize,
    mean: &[f64],
    nk: f64,
    settings: &EmSettings,
) -> Matrix {
    let dim = mean.len();
    let entry = |i: usize, j: usize| {
        if i != j && settings.covariance == CovarianceKind::Diagonal {
            return 0.0;
        }
        let spread: f64 = points
            .iter()
            .zip(resp)
            .map(|(x, r)| r[c] * (x[i] - mean[i]) * (x[j] - mean[j]))
            .sum();
        spread / nk + if i == j { settings.regularisation } else { 0.0 }
    };
    (0..dim)
        .map(|i| (0..dim).map(|j| entry(i, j)).collect())
        .collect()
}

/// A fit and its Bayesian information criterion BIC = −2 ln L + p ln n, with
/// p = (K − 1) + K·dim + K·(covariance parameters).
pub fn fit_with_bic(
    points: &[Vec<f64>],
    settings: &EmSettings,
) -> Result<(EmFit, f64), LatentModelError> {
    let fit = fit_em(points, settings)?;
    let (k, dim) = (settings.components, points[0].len());
    let parameters = (k - 1) + k * dim + k * settings.covariance.parameters(dim);
    let bic = -2.0 * fit.log_likelihood + parameters as f64 * (points.len() as f64).ln();
    Ok((fit, bic))
}

/// The fit with the lowest BIC over 1..=max components. A candidate whose smallest
/// component holds fewer than dim + 1 points (full covariances) or 2 (diagonal) is passed
/// over: its covariance is fitted to too few points, and the likelihood that buys exceeds
/// BIC's penalty.
pub fn fit_bic_best(
    points: &[Vec<f64>],
    max: usize,
    settings: &EmSettings,
) -> Result<(EmFit, f64), LatentModelError> {
    let dim = points.first().map_or(0, Vec::len);
    let smallest_allowed = match settings.covariance {
        CovarianceKind::Full => (dim + 1) as f64,
        CovarianceKind::Diagonal => 2.0,
    };
    let n = points.len() as f64;
    let mut best = fit_with_bic(
        points,
        &EmSettings {
            components: 1,
            ..*settings
        },
    )?;
    for k in 2..=max.min(points.len()) {
        let (fit, bic) = match fit_with_bic(
            points,
            &EmSettings {
                components: k,
                ..*settings
            },
        ) {
            Ok(candidate) => candidate,
            // fewer distinct points than components: no larger count can work either
            Err(LatentModelError::TooFew { .. }) => break,
            Err(e) => return Err(e),
        };
        let smallest = fit
            .components
            .iter()
            .map(|c| c.weight * n)
            .fold(f64::INFINITY, f64::min);
        if smallest >= smallest_allowed && bic < best.1 {
            best = (fit, bic);
        }
    }
    Ok(best)
}

/// ln N(x | μ, Σ) from the Cholesky factor.
pub fn log_normal_density(x: &[f64], component: &Component) -> f64 {
    let centred: Vec<f64> = x.iter().zip(&component.mean).map(|(a, m)| a - m).collect();
    let q = inverse_quadratic_form(&component.cholesky, &centred);
    let dim = x.len() as f64;
    -0.5 * (dim * (2.0 * std::f64::consts::PI).ln() + log_det(&component.cholesky) + q)
}

/// Fills the responsibilities and returns the total log-likelihood (log-sum-exp per point).
fn e_step(points: &[Vec<f64>], components: &[Component], resp: &mut [Vec<f64>]) -> f64 {
    let mut total = 0.0;
    for (x, r) in points.iter().zip(resp.iter_mut()) {
        let logs: Vec<f64> = components
            .iter()
            .map(|c| c.weight.max(1e-300).ln() + log_normal_density(x, c))
            .collect();
        let top = logs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let sum: f64 = logs.iter().map(|l| (l - top).exp()).sum();
        let ll = top + sum.ln();
        for (ri, l) in r.iter_mut().zip(&logs) {
            *ri = (l - ll).exp();
        }
        total += ll;
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kmeans_plus_plus_never_picks_a_centre_twice_and_refuses_too_few_distinct_points() {
        let points: Vec<Vec<f64>> = (0..6).map(|i| vec![i as f64, 0.0]).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let centres = kmeans_plus_plus(&points, 6, &mut rng).unwrap();
        for (i, a) in centres.iter().enumerate() {
            assert!(centres[..i].iter().all(|b| b != a));
        }
        let same = vec![vec![1.0, 1.0]; 5];
        assert!(matches!(
            kmeans_plus_plus(&same, 2, &mut rng),
            Err(LatentModelError::TooFew {
                needed: 2,
                got: 1,
                ..
            })
        ));
    }

    #[test]
    fn the_log_density_of_a_standard_normal_is_analytic() {
        let c = isotropic(vec![0.0, 0.0], 1.0, 1.0);
        let x = [0.6, -1.2];
        let want = -(2.0 * std::f64::consts::PI).ln() - 0.5 * (0.36 + 1.44);
        assert!((log_normal_density(&x, &c) - want).abs() < 1e-14);
    }
}
