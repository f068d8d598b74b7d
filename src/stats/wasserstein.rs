//! Distances between two one-dimensional samples, in the measurement's own unit (mm):
//! the Wasserstein-1 distance and the ECDF area metric.
//!
//! * [`wasserstein_1`] integrates the gap between the two quantile functions,
//!   W₁ = ∫₀¹ |F_a⁻¹(t) − F_b⁻¹(t)| dt — the cost of moving one sample's mass onto the
//!   other's, as `scipy.stats.wasserstein_distance` reports it.
//! * [`ecdf_area`] integrates the gap between the two empirical distribution functions,
//!   A = ∫ |F_a(x) − F_b(x)| dx — the area validation metric of Ferson, Oberkampf &
//!   Ginzburg (2008) with both sides empirical.
//!
//! For unweighted samples the two are the same number: both integrals measure the area
//! of the region between the two staircase graphs, once sliced horizontally and once
//! vertically (in one dimension W₁ = ∫|F_a − F_b| dx; Vallender 1973). They are computed
//! here by the two different routes, and the tests check that they agree to rounding.
//! They part only where this module does not go: weighted samples (scipy's `u_weights`,
//! which the quantile route must then split at cumulative weights), W_p for p ≠ 1, or an
//! area metric taken against a model's continuous CDF instead of a second sample.

use super::{StatsError, check_sample, sorted};

/// W₁ between the empirical distributions of `a` and `b` (each ≥ 1 value), integrating
/// |F_a⁻¹ − F_b⁻¹| over the merged breakpoints i/n_a and j/n_b of the quantile functions.
pub fn wasserstein_1(a: &[f64], b: &[f64]) -> Result<f64, StatsError> {
    check_sample("Wasserstein distance (first sample)", a, 1)?;
    check_sample("Wasserstein distance (second sample)", b, 1)?;
    let (a, b) = (sorted(a), sorted(b));
    let (na, nb) = (a.len(), b.len());
    // Work in units of 1/(na·nb) so the breakpoints i·nb and j·na are exact integers.
    let (mut i, mut j, mut t, mut total) = (0usize, 0usize, 0usize, 0.0);
    while i < na && j < nb {
        let next = ((i + 1) * nb).min((j + 1) * na);
        total += (next - t) as f64 * (a[i] - b[j]).abs();
        t = next;
        if t == (i + 1) * nb {
            i += 1;
        }
        if t == (j + 1) * na {
            j += 1;
        }
    }
    Ok(total / (na * nb) as f64)
}

/// Area between the empirical distribution functions of `a` and `b` (each ≥ 1 value),
/// summing |F_a − F_b| × width over the gaps between consecutive merged values.
pub fn ecdf_area(a: &[f64], b: &[f64]) -> Result<f64, StatsError> {
    check_sample("ECDF area (first sample)", a, 1)?;
    check_sample("ECDF area (second sample)", b, 1)?;
    let (a, b) = (sorted(a), sorted(b));
    let (na, nb) = (a.len() as f64, b.len() as f64);
    let mut merged: Vec<f64> = a.iter().chain(&b).copied().collect();
    merged.sort_by(f64::total_cmp);
    let (mut i, mut j, mut area) = (0usize, 0usize, 0.0);
    for pair in merged.windows(2) {
        while i < a.len() && a[i] <= pair[0] {
            i += 1;
        }
        while j < b.len() && b[j] <= pair[0] {
            j += 1;
        }
        area += (i as f64 / na - j as f64 / nb).abs() * (pair[1] - pair[0]);
    }
    Ok(area)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::test_support::wave;

    // `scipy.stats.wasserstein_distance(a, b)` on the samples of `tests/reference/ks.py`,
    // printed by `python tests/reference/wasserstein.py`:
    // (n_a, freq_a, amp_a, offset_a, n_b, freq_b, amp_b, offset_b, W₁).
    #[allow(clippy::type_complexity)]
    const CASES: [(usize, f64, f64, f64, usize, f64, f64, f64, f64); 5] = [
        (20, 1.3, 10.0, 50.0, 20, 0.7, 12.0, 52.0, 2.7638582488974914),
        (3, 1.0, 1.0, 0.0, 4, 2.0, 1.0, 0.5, 0.4909033594405758),
        (20, 1.3, 10.0, 50.0, 35, 0.7, 12.0, 52.0, 1.9971664150370962),
        (40, 0.31, 3.0, 25.0, 100, 1.7, 3.5, 25.4, 0.4408953943555676),
        (7, 0.5, 2.0, 1.0, 300, 0.05, 2.0, 1.0, 0.7983624292315031),
    ];

    #[test]
    fn wasserstein_matches_scipy_and_equals_the_ecdf_area() {
        for (na, fa, aa, oa, nb, fb, ab, ob, want) in CASES {
            let (a, b) = (wave(na, fa, aa, oa), wave(nb, fb, ab, ob));
            let w = wasserstein_1(&a, &b).unwrap();
            let area = ecdf_area(&a, &b).unwrap();
            assert!((w - want).abs() < 1e-11 * want.max(1.0), "W₁ {w} vs {want}");
            assert!(
                (w - area).abs() < 1e-11 * want.max(1.0),
                "W₁ {w} vs area {area}"
            );
        }
    }

    #[test]
    fn a_shift_moves_every_unit_of_mass_by_the_shift() {
        let a = wave(37, 0.9, 3.0, 20.0);
        let b: Vec<f64> = a.iter().map(|v| v + 2.5).collect();
        assert!((wasserstein_1(&a, &b).unwrap() - 2.5).abs() < 1e-12);
        assert!((ecdf_area(&b, &a).unwrap() - 2.5).abs() < 1e-12);
        assert_eq!(wasserstein_1(&a, &a).unwrap(), 0.0);
    }

    #[test]
    fn point_masses_and_ties_by_hand() {
        // {0, 0, 3} vs {1}: mass 2/3 moves by 1, mass 1/3 by 2 → 4/3.
        let (a, b) = ([0.0, 3.0, 0.0], [1.0]);
        assert!((wasserstein_1(&a, &b).unwrap() - 4.0 / 3.0).abs() < 1e-15);
        assert!((ecdf_area(&a, &b).unwrap() - 4.0 / 3.0).abs() < 1e-15);
        assert!(matches!(ecdf_area(&[], &b), Err(StatsError::TooFew { .. })));
    }
}
