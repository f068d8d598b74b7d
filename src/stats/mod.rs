//! Population statistics for validating a virtual cohort against a real one: special
//! functions, descriptive summaries, two-sample tests (Kolmogorov–Smirnov, TOST), distances
//! between distributions (Wasserstein-1, ECDF area), Gaussian kernel densities with SIMCor's
//! bootstrap density-band test, and multivariate comparisons (Mahalanobis forms against χ²,
//! Spearman correlation matrices).
//!
//! Everything here is pure `f64` arithmetic without I/O, deterministic (the bootstrap draws
//! from a seeded ChaCha8), and checked against exact references: analytic identities, brute
//! force, or scipy values committed as constants with the script that printed them
//! (`tests/reference/`). A statistic that cannot be computed — too few values, zero
//! variance, a singular covariance — returns a [`StatsError`] that says why; no function
//! here returns NaN.

pub mod bootstrap;
pub mod descriptive;
pub mod distributions;
pub mod kde;
pub mod ks;
pub mod linalg;
pub mod multivariate;
pub mod pair_sample;
pub mod rank;
pub mod special;
pub mod tost;
pub mod wasserstein;

/// Why a statistic cannot be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StatsError {
    /// Fewer values than the statistic needs.
    #[error("{what} needs at least {needed} values, got {got}")]
    TooFew {
        /// The statistic or input.
        what: &'static str,
        /// The minimum.
        needed: usize,
        /// What was given.
        got: usize,
    },
    /// The values do not vary, so a scale-dependent statistic is undefined.
    #[error("{what}: the values have zero variance")]
    ZeroVariance {
        /// The statistic or input.
        what: &'static str,
    },
    /// An input is NaN or infinite.
    #[error("{what}: value {index} is not finite")]
    NotFinite {
        /// The statistic or input.
        what: &'static str,
        /// Position of the first offending value.
        index: usize,
    },
    /// A covariance (or other symmetric) matrix is not positive definite.
    #[error("{what}: the matrix is singular or not positive definite")]
    Singular {
        /// The statistic or input.
        what: &'static str,
    },
    /// Inputs whose shapes do not fit together.
    #[error("{what}: {detail}")]
    Dimension {
        /// The statistic or input.
        what: &'static str,
        /// Which sizes disagree.
        detail: String,
    },
    /// A parameter outside its domain (a probability outside (0, 1), a negative margin …).
    #[error("{what}: {detail}")]
    Domain {
        /// The parameter.
        what: &'static str,
        /// Its allowed range and value.
        detail: String,
    },
}

/// `Err(NotFinite)` naming the first value of `values` that is NaN or infinite.
pub(crate) fn check_finite(what: &'static str, values: &[f64]) -> Result<(), StatsError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(StatsError::NotFinite { what, index }),
        None => Ok(()),
    }
}

/// `Err(TooFew)` unless `values` has at least `needed` entries, all finite.
pub(crate) fn check_sample(
    what: &'static str,
    values: &[f64],
    needed: usize,
) -> Result<(), StatsError> {
    if values.len() < needed {
        return Err(StatsError::TooFew {
            what,
            needed,
            got: values.len(),
        });
    }
    check_finite(what, values)
}

/// A copy of `values` sorted ascending (callers have checked they are finite).
pub(crate) fn sorted(values: &[f64]) -> Vec<f64> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v
}

#[cfg(test)]
pub(crate) mod test_support {
    //! The deterministic samples the scipy references of `tests/reference/` are computed on.

    /// `offset + amp·sin(freq·(i + 1))` for i in 0..n: the `wave` of the reference scripts.
    pub(crate) fn wave(n: usize, freq: f64, amp: f64, offset: f64) -> Vec<f64> {
        (0..n)
            .map(|i| offset + amp * (freq * (i + 1) as f64).sin())
            .collect()
    }
}
