//! Two-sample Kolmogorov–Smirnov test (two-sided), as `scipy.stats.ks_2samp` with its
//! default `method="auto"` computes it.
//!
//! D = sup_x |F_a(x) − F_b(x)| over the two empirical distribution functions. The p-value
//! is exact when both samples have at most [`EXACT_MAX_N`] values (scipy's switch):
//! P(D ≥ d) counted over the lattice paths of the merged order, with d rounded to a
//! multiple of 1/lcm(n_a, n_b) first as scipy does. Equal sizes use the closed alternating
//! sum of Gnedenko & Korolyuk (the form scipy evaluates); unequal sizes use one minus the
//! share of paths that stay strictly inside the band |x/n_a − y/n_b| < d (Hodges 1958),
//! evaluated as probabilities so nothing overflows. Like scipy, ties are not corrected
//! for: the path count assumes continuous data.
//!
//! Beyond [`EXACT_MAX_N`] the p-value is asymptotic. There scipy evaluates the one-sample
//! distribution `kstwo.sf(d, round(n_e))` with n_e = n_a n_b / (n_a + n_b); this module
//! uses its limit, Kolmogorov's distribution Q(√n_e · d) ([`kolmogorov_sf`]), which agrees
//! with it to O(1/√n_e) (well under 1 % relative for n_e > 5 000 and p > 1e-3).

use serde::{Deserialize, Serialize};

use super::{StatsError, check_sample, sorted};

/// Largest sample size for which the p-value is exact (as in scipy).
pub const EXACT_MAX_N: usize = 10_000;

/// How the p-value was computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum KsMethod {
    /// Exact lattice-path probability.
    Exact,
    /// Kolmogorov's limiting distribution.
    Asymptotic,
}

/// Result of the two-sided two-sample test.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct KsResult {
    /// sup |F_a − F_b|.
    pub statistic: f64,
    /// P(D ≥ statistic) under the hypothesis that both samples come from one continuous
    /// distribution.
    pub p_value: f64,
    /// How `p_value` was computed.
    pub method: KsMethod,
}

/// Two-sided two-sample Kolmogorov–Smirnov test of `a` against `b` (each ≥ 1 value).
pub fn ks_two_sample(a: &[f64], b: &[f64]) -> Result<KsResult, StatsError> {
    check_sample("KS test (first sample)", a, 1)?;
    check_sample("KS test (second sample)", b, 1)?;
    let (a, b) = (sorted(a), sorted(b));
    let (n1, n2) = (a.len(), b.len());
    let d = ks_statistic_sorted(&a, &b);
    if n1.max(n2) > EXACT_MAX_N {
        let en = (n1 as f64 * n2 as f64) / (n1 + n2) as f64;
        return Ok(KsResult {
            statistic: d,
            p_value: kolmogorov_sf(en.sqrt() * d),
            method: KsMethod::Asymptotic,
        });
    }
    let g = gcd(n1, n2);
    let lcm = (n1 / g) * n2;
    let h = (d * lcm as f64).round() as usize;
    let p = if h == 0 {
        1.0
    } else if n1 == n2 {
        prob_outside_square(n1, h)
    } else {
        1.0 - prob_inside_band(n1, n2, h * g)
    };
    Ok(KsResult {
        statistic: h as f64 / lcm as f64,
        p_value: p.clamp(0.0, 1.0),
        method: KsMethod::Exact,
    })
}

/// sup |F_a − F_b| of two ascending samples, evaluated just after every distinct value.
fn ks_statistic_sorted(a: &[f64], b: &[f64]) -> f64 {
    let (n1, n2) = (a.len() as f64, b.len() as f64);
    let (mut i, mut j, mut d) = (0, 0, 0.0f64);
    while i < a.len() && j < b.len() {
        let v = a[i].min(b[j]);
        while i < a.len() && a[i] <= v {
            i += 1;
        }
        while j < b.len() && b[j] <= v {
            j += 1;
        }
        d = d.max((i as f64 / n1 - j as f64 / n2).abs());
    }
    // Once one sample is exhausted its ECDF is 1; the other's only rises towards 1.
    d.max((i as f64 / n1 - j as f64 / n2).abs())
}

fn gcd(mut a: usize, mut b: usize) -> usize {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// P(D_{n,n} ≥ h/n) = 2 Σ_{k≥1} (−1)^(k−1) C(2n, n − kh) / C(2n, n), evaluated from the
/// innermost term outwards as nested products of ratios (no cancellation, no overflow).
fn prob_outside_square(n: usize, h: usize) -> f64 {
    let mut p = 0.0;
    for k in (0..=n / h).rev() {
        let mut ratio = 1.0;
        for j in 0..h {
            let num = n as f64 - (k * h + j) as f64;
            ratio *= num / (n + k * h + j + 1) as f64;
        }
        p = ratio * (1.0 - p);
    }
    2.0 * p
}

/// Share of the monotone lattice paths from (0, 0) to (m, n) along which every point
/// satisfies |x n − y m| < `bound`. r(x, y) is the share of the C(x + y, x) paths to (x, y)
/// that stayed inside, so r(x, y) = r(x − 1, y)·x/(x + y) + r(x, y − 1)·y/(x + y).
fn prob_inside_band(m: usize, n: usize, bound: usize) -> f64 {
    let inside = |x: usize, y: usize| {
        (x as i64 * n as i64 - y as i64 * m as i64).unsigned_abs() < bound as u64
    };
    let mut row = vec![0.0f64; n + 1];
    for x in 0..=m {
        for y in 0..=n {
            row[y] = if !inside(x, y) {
                0.0
            } else if x == 0 && y == 0 {
                1.0
            } else {
                let total = (x + y) as f64;
                let from_left = if x > 0 {
                    row[y] * x as f64 / total
                } else {
                    0.0
                };
                let from_below = if y > 0 {
                    row[y - 1] * y as f64 / total
                } else {
                    0.0
                };
                from_left + from_below
            };
        }
    }
    row[n]
}

/// Survival function of Kolmogorov's limiting distribution,
/// Q(λ) = 2 Σ_{k≥1} (−1)^(k−1) exp(−2k²λ²), with the dual theta-function series
/// 1 − (√(2π)/λ) Σ_{k≥1} exp(−(2k − 1)²π²/(8λ²)) for small λ, where the first converges
/// slowly.
pub fn kolmogorov_sf(lambda: f64) -> f64 {
    if lambda <= 0.0 {
        return 1.0;
    }
    if lambda < 1.0 {
        let pi2 = std::f64::consts::PI * std::f64::consts::PI;
        let s: f64 = (1..=20)
            .map(|k| (-((2 * k - 1) as f64).powi(2) * pi2 / (8.0 * lambda * lambda)).exp())
            .sum();
        return (1.0 - (2.0 * std::f64::consts::PI).sqrt() / lambda * s).clamp(0.0, 1.0);
    }
    let s: f64 = (1..=100)
        .map(|k| {
            let sign = if k % 2 == 1 { 1.0 } else { -1.0 };
            sign * (-2.0 * (k * k) as f64 * lambda * lambda).exp()
        })
        .sum();
    (2.0 * s).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::test_support::wave;

    // `scipy.stats.ks_2samp(a, b)` (scipy 1.17.1), printed by `python tests/reference/ks.py`:
    // (n_a, freq_a, amp_a, offset_a, n_b, freq_b, amp_b, offset_b, D, p).
    #[allow(clippy::type_complexity)]
    const CASES: [(usize, f64, f64, f64, usize, f64, f64, f64, f64, f64); 8] = [
        (
            20,
            1.3,
            10.0,
            50.0,
            20,
            0.7,
            12.0,
            52.0,
            0.3,
            0.33559098126008213,
        ),
        (
            20,
            1.3,
            10.0,
            50.0,
            20,
            0.9,
            10.0,
            58.0,
            0.45,
            0.0335416594061465,
        ),
        (3, 1.0, 1.0, 0.0, 4, 2.0, 1.0, 0.5, 0.5, 0.6571428571428571),
        (
            20,
            1.3,
            10.0,
            50.0,
            35,
            0.7,
            12.0,
            52.0,
            0.2857142857142857,
            0.2088272438586636,
        ),
        (
            40,
            0.31,
            3.0,
            25.0,
            100,
            1.7,
            3.5,
            25.4,
            0.24,
            0.06485250627892215,
        ),
        (
            100,
            2.1,
            4.0,
            30.0,
            80,
            0.45,
            4.0,
            33.0,
            0.45,
            1.2854747646181631e-08,
        ),
        (
            7,
            0.5,
            2.0,
            1.0,
            300,
            0.05,
            2.0,
            1.0,
            0.3233333333333333,
            0.3901034960224643,
        ),
        (
            250,
            1.1,
            5.0,
            0.0,
            250,
            0.37,
            5.0,
            0.2,
            0.1,
            0.16422053981533355,
        ),
    ];
    // `scipy.special.kolmogorov(λ)`: (λ, Q(λ)).
    const KOLMOGOROV: [(f64, f64); 7] = [
        (0.3, 0.9999906941986655),
        (0.6, 0.8642827790506042),
        (0.9, 0.3927307079406543),
        (1.0, 0.26999967167735456),
        (1.2, 0.11224966667072497),
        (1.8, 0.003067621347579706),
        (3.0, 3.045995948942526e-08),
    ];

    #[test]
    fn statistic_and_p_value_match_scipy() {
        for (na, fa, aa, oa, nb, fb, ab, ob, d, p) in CASES {
            let r = ks_two_sample(&wave(na, fa, aa, oa), &wave(nb, fb, ab, ob)).unwrap();
            assert!((r.statistic - d).abs() < 1e-12, "D {} vs {d}", r.statistic);
            assert!(
                (r.p_value - p).abs() <= 1e-9 * p.max(1e-6),
                "p {} vs {p}",
                r.p_value
            );
            assert_eq!(r.method, KsMethod::Exact);
        }
    }

    #[test]
    fn kolmogorov_distribution_matches_scipy_on_both_series() {
        for (lambda, want) in KOLMOGOROV {
            let got = kolmogorov_sf(lambda);
            assert!(
                (got - want).abs() <= 1e-12 * want.max(1e-3),
                "Q({lambda}) = {got}"
            );
        }
    }

    /// P(D ≥ d) by enumerating every assignment of the n_a + n_b ranks to the two samples.
    fn brute_force_p(na: usize, nb: usize, d: f64) -> f64 {
        let (mut hits, mut total) = (0usize, 0usize);
        for mask in 0u32..(1 << (na + nb)) {
            if mask.count_ones() as usize != na {
                continue;
            }
            let (mut a, mut b) = (Vec::new(), Vec::new());
            for rank in 0..na + nb {
                let side = if mask >> rank & 1 == 1 {
                    &mut a
                } else {
                    &mut b
                };
                side.push(rank as f64);
            }
            total += 1;
            if ks_statistic_sorted(&a, &b) >= d - 1e-12 {
                hits += 1;
            }
        }
        hits as f64 / total as f64
    }

    #[test]
    fn exact_p_values_equal_the_enumeration_of_all_orderings() {
        for (na, nb) in [(3, 4), (2, 7), (5, 5), (4, 6), (6, 8)] {
            let a = wave(na, 1.9, 1.0, 0.0);
            let b = wave(nb, 0.8, 1.0, 0.3);
            let r = ks_two_sample(&a, &b).unwrap();
            let want = brute_force_p(na, nb, r.statistic);
            assert!(
                (r.p_value - want).abs() < 1e-12,
                "{na}×{nb}: {} vs {want}",
                r.p_value
            );
        }
    }

    #[test]
    fn the_square_formula_and_the_path_recursion_agree() {
        for (n, h) in [(5, 2), (20, 6), (60, 9), (200, 30)] {
            let square = prob_outside_square(n, h);
            let band = 1.0 - prob_inside_band(n, n, h * n);
            assert!(
                (square - band).abs() < 1e-12,
                "n {n} h {h}: {square} vs {band}"
            );
        }
    }

    #[test]
    fn identical_samples_have_d_zero_and_p_one_and_empty_ones_are_refused() {
        let a = wave(30, 0.6, 2.0, 1.0);
        let r = ks_two_sample(&a, &a).unwrap();
        assert_eq!((r.statistic, r.p_value), (0.0, 1.0));
        assert!(matches!(
            ks_two_sample(&[], &a),
            Err(StatsError::TooFew { needed: 1, .. })
        ));
    }

    #[test]
    fn large_samples_switch_to_the_asymptotic_distribution() {
        let a = wave(EXACT_MAX_N + 1, 0.013, 1.0, 0.0);
        let b = wave(EXACT_MAX_N + 1, 0.017, 1.0, 0.02);
        let r = ks_two_sample(&a, &b).unwrap();
        assert_eq!(r.method, KsMethod::Asymptotic);
        let en = (EXACT_MAX_N + 1) as f64 / 2.0;
        assert_eq!(r.p_value, kolmogorov_sf(en.sqrt() * r.statistic));
    }
}
