//! Equivalence of two means within a margin: the two one-sided tests (TOST; Schuirmann
//! 1987) with Welch's unequal-variance t statistic, as `statsmodels`'
//! `ttost_ind(a, b, low, high, usevar="unequal")` computes it.
//!
//! With Δ = mean(a) − mean(b), s = √(s_a²/n_a + s_b²/n_b) and Welch–Satterthwaite degrees
//! of freedom ν = s⁴ / ((s_a²/n_a)²/(n_a − 1) + (s_b²/n_b)²/(n_b − 1)):
//! * lower test, H₀: Δ ≤ low — t_low = (Δ − low)/s, p_low = 1 − T_ν(t_low);
//! * upper test, H₀: Δ ≥ high — t_high = (Δ − high)/s, p_high = T_ν(t_high);
//! * p = max(p_low, p_high): equivalence is shown at level α when p < α, which is the same
//!   as the (1 − 2α) confidence interval Δ ± t_{1−α,ν} s lying inside (low, high). The
//!   result carries that interval at α = 0.05 (the 90 % interval).

use serde::{Deserialize, Serialize};

use super::StatsError;
use super::descriptive::{mean, variance};
use super::distributions::{student_t_cdf, student_t_quantile};

/// Result of a Welch TOST of `a` against `b`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Tost {
    /// mean(a) − mean(b).
    pub difference: f64,
    /// Welch standard error of the difference.
    pub standard_error: f64,
    /// Welch–Satterthwaite degrees of freedom.
    pub df: f64,
    /// Lower equivalence bound.
    pub low: f64,
    /// Upper equivalence bound.
    pub high: f64,
    /// t statistic of the lower test.
    pub t_low: f64,
    /// p-value of the lower test (H₀: difference ≤ low).
    pub p_low: f64,
    /// t statistic of the upper test.
    pub t_high: f64,
    /// p-value of the upper test (H₀: difference ≥ high).
    pub p_high: f64,
    /// max(p_low, p_high).
    pub p_value: f64,
    /// 90 % confidence interval of the difference, (lower, upper).
    pub ci90: (f64, f64),
}

/// TOST with the symmetric margin (−margin, +margin), margin > 0 in the values' unit.
pub fn tost_welch(a: &[f64], b: &[f64], margin: f64) -> Result<Tost, StatsError> {
    if !(margin > 0.0 && margin.is_finite()) {
        return Err(StatsError::Domain {
            what: "TOST margin",
            detail: format!("needs a finite margin > 0, got {margin}"),
        });
    }
    tost_welch_bounds(a, b, -margin, margin)
}

/// TOST with the equivalence interval (low, high), low < high.
pub fn tost_welch_bounds(a: &[f64], b: &[f64], low: f64, high: f64) -> Result<Tost, StatsError> {
    if !(low < high && low.is_finite() && high.is_finite()) {
        return Err(StatsError::Domain {
            what: "TOST bounds",
            detail: format!("needs finite low < high, got ({low}, {high})"),
        });
    }
    let (va, vb) = (variance(a)?, variance(b)?);
    let (na, nb) = (a.len() as f64, b.len() as f64);
    let (ua, ub) = (va / na, vb / nb);
    let se2 = ua + ub;
    if se2 <= 0.0 {
        return Err(StatsError::ZeroVariance { what: "TOST" });
    }
    let se = se2.sqrt();
    let df = se2 * se2 / (ua * ua / (na - 1.0) + ub * ub / (nb - 1.0));
    let difference = mean(a)? - mean(b)?;
    let t_low = (difference - low) / se;
    let t_high = (difference - high) / se;
    // T(−t) rather than 1 − T(t): the upper tail keeps its relative precision.
    let p_low = student_t_cdf(-t_low, df)?;
    let p_high = student_t_cdf(t_high, df)?;
    let half = student_t_quantile(0.95, df)? * se;
    Ok(Tost {
        difference,
        standard_error: se,
        df,
        low,
        high,
        t_low,
        p_low,
        t_high,
        p_high,
        p_value: p_low.max(p_high),
        ci90: (difference - half, difference + half),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::test_support::wave;

    // statsmodels 0.15.0 `ttost_ind(a, b, -m, m, usevar="unequal")` and
    // `CompareMeans(...).tconfint_diff(alpha=0.1, usevar="unequal")`, printed by
    // `python tests/reference/tost.py`: (n_a, freq_a, amp_a, offset_a, n_b, freq_b, amp_b,
    // offset_b, margin, p, t_low, p_low, t_high, p_high, df, ci_low, ci_high).
    #[allow(clippy::type_complexity)]
    const CASES: [(
        usize,
        f64,
        f64,
        f64,
        usize,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
        f64,
    ); 5] = [
        (
            20,
            1.3,
            10.0,
            50.0,
            20,
            0.7,
            12.0,
            52.0,
            3.0,
            0.45374115014691063,
            0.11701857497600489,
            0.45374115014691063,
            -2.2226083682136646,
            0.01623825078155037,
            36.7628251098147,
            -7.027192164200235,
            1.627383106521,
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
            1.0,
            0.08337208986753972,
            1.3950994886622674,
            0.08337208986753972,
            -3.3333779086923516,
            0.0006441116132356382,
            82.19491063837869,
            -1.1135691658492934,
            0.2937372169371688,
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
            2.0,
            0.00015884770916885953,
            3.7593381873395773,
            0.00015884770916885953,
            -5.697616607369661,
            9.182715747358387e-08,
            82.19491063837869,
            -1.1135691658492934,
            0.2937372169371688,
        ),
        (
            12,
            0.9,
            1.0,
            22.0,
            60,
            0.4,
            4.0,
            21.5,
            0.5,
            0.49783945226519655,
            2.303321469840512,
            0.012231640886199022,
            -0.0054365482053341935,
            0.49783945226519655,
            65.11800553677641,
            -0.22507763566259165,
            1.2203681354353346,
        ),
        (
            80,
            2.2,
            2.5,
            24.0,
            20,
            1.1,
            2.5,
            27.0,
            2.0,
            0.9939344728246161,
            -2.6758726293101596,
            0.9939344728246161,
            -11.579143617598168,
            1.079898640659018e-12,
            28.986249309746693,
            -3.9655815256288767,
            -2.438813562720285,
        ),
    ];

    #[test]
    fn tost_matches_statsmodels() {
        for c in CASES {
            let a = wave(c.0, c.1, c.2, c.3);
            let b = wave(c.4, c.5, c.6, c.7);
            let r = tost_welch(&a, &b, c.8).unwrap();
            let close = |got: f64, want: f64, what: &str| {
                assert!(
                    (got - want).abs() <= 1e-10 * want.abs().max(1e-3),
                    "{what}: {got} vs {want}"
                )
            };
            close(r.p_value, c.9, "p");
            close(r.t_low, c.10, "t_low");
            close(r.p_low, c.11, "p_low");
            close(r.t_high, c.12, "t_high");
            close(r.p_high, c.13, "p_high");
            close(r.df, c.14, "df");
            close(r.ci90.0, c.15, "ci low");
            close(r.ci90.1, c.16, "ci high");
        }
    }

    #[test]
    fn equivalence_at_5_percent_is_the_90_percent_interval_inside_the_margin() {
        let a = wave(40, 0.7, 2.0, 25.0);
        for shift in [0.0, 0.3, 0.8, 1.2, 2.5] {
            let b: Vec<f64> = wave(33, 1.9, 2.4, 25.0 + shift);
            let r = tost_welch(&a, &b, 1.0).unwrap();
            let inside = r.ci90.0 > -1.0 && r.ci90.1 < 1.0;
            assert_eq!(r.p_value < 0.05, inside, "shift {shift}: {r:?}");
        }
    }

    #[test]
    fn annuli_3_mm_larger_fail_equivalence_at_2_mm_and_ks_while_one_law_passes_both() {
        use crate::stats::ks::ks_two_sample;
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let draw = |mean: f64, seed: u64| -> Vec<f64> {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let law = Normal::new(mean, 2.0).unwrap();
            (0..60).map(|_| law.sample(&mut rng)).collect()
        };
        let real = draw(23.0, 1);
        let same = draw(23.0, 2);
        let larger = draw(26.0, 3);
        // 60 per side, sd 2: the difference's standard error is about 0.37 mm
        assert!(tost_welch(&same, &real, 2.0).unwrap().p_value < 0.05);
        assert!(ks_two_sample(&same, &real).unwrap().p_value > 0.05);
        assert!(tost_welch(&larger, &real, 2.0).unwrap().p_value > 0.05);
        assert!(ks_two_sample(&larger, &real).unwrap().p_value < 0.05);
    }

    #[test]
    fn degenerate_inputs_say_why() {
        let a = [1.0, 1.0, 1.0];
        assert!(matches!(
            tost_welch(&a, &a, 1.0),
            Err(StatsError::ZeroVariance { .. })
        ));
        assert!(matches!(
            tost_welch(&[1.0], &[1.0, 2.0], 1.0),
            Err(StatsError::TooFew { needed: 2, .. })
        ));
        assert!(matches!(
            tost_welch(&[1.0, 2.0], &[1.0, 2.0], 0.0),
            Err(StatsError::Domain { .. })
        ));
    }
}
