//! Covariance shrinkage towards a multiple of the identity, for a covariance estimated
//! from about as many latents as it has dimensions.
//!
//! With n ≈ 80 training latents in p ≈ 68 dimensions the sample covariance S spreads its
//! eigenvalues far beyond the truth (the Marchenko–Pastur law: for p / n = 0.85 and a
//! true identity, from ≈ 0.005 to ≈ 3.7): the leading modes come out too wide and the
//! trailing ones far too narrow, so a Gaussian with covariance S draws latents that lie
//! closer to the training latents than a new patient's does. The shrunk covariance
//! Σ* = (1 − ρ) S + ρ m I, with m = tr S / p, keeps the total variance and moves a share
//! ρ of it evenly onto every direction, including those the training latents do not
//! span when n ≤ p.
//!
//! [`ledoit_wolf`] estimates the ρ that minimises the expected squared Frobenius error of
//! Σ* (Ledoit & Wolf 2004, "A well-conditioned estimator for large-dimensional
//! covariance matrices", Lemmas 3.2–3.4) from the data alone, computed from the n × n
//! Gram matrix of the centred latents so that a large p costs nothing extra.

use super::pca::{centre, dot};
use super::{LatentModelError, check_latents};

/// How far the sampler's covariance is pulled towards a multiple of the identity.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", content = "value", rename_all = "snake_case")]
pub enum Shrinkage {
    /// The intensity ρ estimated from the latents ([`ledoit_wolf`]).
    LedoitWolf,
    /// This intensity ρ, in [0, 1] (0: the sample covariance, 1: m I).
    Intensity(f64),
}

impl Shrinkage {
    /// The intensity ρ for `latents`.
    pub fn intensity(&self, latents: &[Vec<f64>]) -> Result<f64, LatentModelError> {
        match *self {
            Self::LedoitWolf => ledoit_wolf(latents),
            Self::Intensity(rho) if (0.0..=1.0).contains(&rho) => Ok(rho),
            Self::Intensity(rho) => Err(LatentModelError::Domain {
                what: "shrinkage",
                detail: format!("needs an intensity in [0, 1], got {rho}"),
            }),
        }
    }
}

/// The Ledoit–Wolf shrinkage intensity ρ ∈ [0, 1] of ≥ 2 latents, not all identical.
///
/// With the centred latents xₖ, S = Σₖ xₖ xₖᵀ / n, m = tr S / p, d² = ‖S − m I‖²,
/// b̄² = Σₖ ‖xₖ xₖᵀ − S‖² / n² and b² = min(b̄², d²): ρ = b² / d². In terms of the Gram
/// matrix G = (xₖ · xₗ): tr S = Σ Gₖₖ / n, ‖S‖² = Σ Gₖₗ² / n², d² = ‖S‖² − p m², and
/// b̄² = (Σₖ Gₖₖ² − Σ Gₖₗ² / n) / n².
pub fn ledoit_wolf(latents: &[Vec<f64>]) -> Result<f64, LatentModelError> {
    let p = check_latents("Ledoit-Wolf shrinkage", latents, 2)?;
    let n = latents.len() as f64;
    let (_, centred) = centre(latents);
    let (mut diagonal_sq, mut all_sq, mut trace_n) = (0.0, 0.0, 0.0);
    for (k, a) in centred.iter().enumerate() {
        for (l, b) in centred.iter().enumerate() {
            let g = dot(a, b);
            all_sq += g * g;
            if k == l {
                diagonal_sq += g * g;
                trace_n += g;
            }
        }
    }
    let trace = trace_n / n;
    if trace <= 0.0 {
        return Err(LatentModelError::NoVariation);
    }
    let m = trace / p as f64;
    let frobenius_sq = all_sq / (n * n);
    let d2 = frobenius_sq - p as f64 * m * m;
    if d2 <= 1e-12 * frobenius_sq {
        // S is already a multiple of the identity: shrinking changes nothing.
        return Ok(1.0);
    }
    let b2_bar = (diagonal_sq - all_sq / n) / (n * n);
    Ok((b2_bar.max(0.0).min(d2) / d2).clamp(0.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::latent_models::test_latents::anisotropic;

    /// The definition, term by term on p × p matrices.
    fn ledoit_wolf_by_definition(latents: &[Vec<f64>]) -> f64 {
        let (n, p) = (latents.len(), latents[0].len());
        let (_, x) = centre(latents);
        let s: Vec<Vec<f64>> = (0..p)
            .map(|i| {
                (0..p)
                    .map(|j| x.iter().map(|r| r[i] * r[j]).sum::<f64>() / n as f64)
                    .collect()
            })
            .collect();
        let m = (0..p).map(|i| s[i][i]).sum::<f64>() / p as f64;
        let mut d2 = 0.0;
        for (i, row) in s.iter().enumerate() {
            for (j, sij) in row.iter().enumerate() {
                let target = if i == j { m } else { 0.0 };
                d2 += (sij - target).powi(2);
            }
        }
        let mut b2_bar = 0.0;
        for r in &x {
            for (ri, row) in r.iter().zip(&s) {
                for (rj, sij) in r.iter().zip(row) {
                    b2_bar += (ri * rj - sij).powi(2);
                }
            }
        }
        b2_bar /= (n * n) as f64;
        b2_bar.min(d2) / d2
    }

    #[test]
    fn the_gram_form_equals_the_definition() {
        for (n, p, seed) in [(30, 5, 1), (12, 40, 2), (80, 68, 3)] {
            let latents = anisotropic(n, p, seed, |j| 0.2 + 1.0 / (1.0 + j as f64));
            let (fast, slow) = (
                ledoit_wolf(&latents).unwrap(),
                ledoit_wolf_by_definition(&latents),
            );
            assert!(
                (fast - slow).abs() < 1e-10,
                "n {n}, p {p}: {fast} vs {slow}"
            );
        }
    }

    #[test]
    fn isotropic_latents_shrink_fully_and_well_sampled_anisotropic_ones_barely() {
        // True covariance I: the target is the truth, so the optimum is ρ ≈ 1.
        let isotropic = anisotropic(80, 64, 7, |_| 1.0);
        assert!(ledoit_wolf(&isotropic).unwrap() > 0.9);
        // Variances 100 to 0.01 from many latents: S is accurate and far from m I.
        let steep = anisotropic(2000, 5, 8, |j| 10f64.powi(2 - j as i32));
        assert!(ledoit_wolf(&steep).unwrap() < 0.01);
        // Few latents of a steep spectrum in many dimensions: somewhere between.
        let few = anisotropic(20, 40, 9, |j| 3.0 * 0.9f64.powi(j as i32));
        let rho = ledoit_wolf(&few).unwrap();
        assert!(rho > 0.05 && rho < 0.95, "{rho}");
    }

    #[test]
    fn a_fixed_intensity_outside_the_unit_interval_is_refused() {
        let latents = anisotropic(10, 3, 1, |_| 1.0);
        assert_eq!(Shrinkage::Intensity(0.25).intensity(&latents), Ok(0.25));
        for rho in [-0.1, 1.5, f64::NAN] {
            assert!(matches!(
                Shrinkage::Intensity(rho).intensity(&latents),
                Err(LatentModelError::Domain { .. })
            ));
        }
        let same = vec![vec![1.0, 2.0]; 4];
        assert_eq!(ledoit_wolf(&same), Err(LatentModelError::NoVariation));
    }
}
