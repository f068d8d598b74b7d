//! Descriptive statistics of one measurement: mean, sample standard deviation, quantiles
//! with numpy's default (linear) interpolation, a summary of the usual figures, and
//! histograms of two samples on common bins so they can be overlaid in a plot.

use serde::{Deserialize, Serialize};

use super::{StatsError, check_sample, sorted};

/// Arithmetic mean of at least one finite value.
pub fn mean(values: &[f64]) -> Result<f64, StatsError> {
    check_sample("mean", values, 1)?;
    Ok(values.iter().sum::<f64>() / values.len() as f64)
}

/// Sample variance (n − 1 denominator) of at least two finite values.
pub fn variance(values: &[f64]) -> Result<f64, StatsError> {
    check_sample("variance", values, 2)?;
    let m = values.iter().sum::<f64>() / values.len() as f64;
    let ss: f64 = values.iter().map(|v| (v - m) * (v - m)).sum();
    Ok(ss / (values.len() - 1) as f64)
}

/// Sample standard deviation (n − 1 denominator) of at least two finite values.
pub fn sample_sd(values: &[f64]) -> Result<f64, StatsError> {
    variance(values).map(f64::sqrt)
}

/// The `p`-quantile (0 ≤ p ≤ 1) of ascending `sorted` values by linear interpolation
/// between order statistics: position h = (n − 1) p, as `numpy.quantile`'s default method
/// (Hyndman & Fan type 7, also R's default).
pub fn quantile_sorted(sorted: &[f64], p: f64) -> Result<f64, StatsError> {
    check_sample("quantile", sorted, 1)?;
    if !(0.0..=1.0).contains(&p) {
        return Err(StatsError::Domain {
            what: "quantile",
            detail: format!("needs 0 ≤ p ≤ 1, got {p}"),
        });
    }
    let h = (sorted.len() - 1) as f64 * p;
    let below = h.floor() as usize;
    let above = (below + 1).min(sorted.len() - 1);
    Ok(sorted[below] + (h - below as f64) * (sorted[above] - sorted[below]))
}

/// The `p`-quantile of unsorted `values` (see [`quantile_sorted`]).
pub fn quantile(values: &[f64], p: f64) -> Result<f64, StatsError> {
    check_sample("quantile", values, 1)?;
    quantile_sorted(&sorted(values), p)
}

/// The usual figures of one sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Summary {
    /// Number of values.
    pub count: usize,
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (n − 1 denominator).
    pub sd: f64,
    /// Smallest value.
    pub min: f64,
    /// 5 % quantile.
    pub p05: f64,
    /// 25 % quantile.
    pub p25: f64,
    /// Median.
    pub median: f64,
    /// 75 % quantile.
    pub p75: f64,
    /// 95 % quantile.
    pub p95: f64,
    /// Largest value.
    pub max: f64,
}

impl Summary {
    /// Summarises at least two finite values.
    pub fn of(values: &[f64]) -> Result<Self, StatsError> {
        check_sample("summary", values, 2)?;
        let s = sorted(values);
        let q = |p| quantile_sorted(&s, p);
        Ok(Self {
            count: s.len(),
            mean: mean(&s)?,
            sd: sample_sd(&s)?,
            min: s[0],
            p05: q(0.05)?,
            p25: q(0.25)?,
            median: q(0.5)?,
            p75: q(0.75)?,
            p95: q(0.95)?,
            max: s[s.len() - 1],
        })
    }
}

/// Two samples counted on the same equal-width bins.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct CommonHistograms {
    /// Bin edges, ascending; one more than the bins. Bins are half-open `[lo, hi)` except
    /// the last, which is closed, so every value is counted.
    pub edges: Vec<f64>,
    /// Values of the first sample per bin.
    pub counts_a: Vec<usize>,
    /// Values of the second sample per bin.
    pub counts_b: Vec<usize>,
}

impl CommonHistograms {
    /// `bins` equal-width bins spanning the smallest to the largest value of both samples.
    pub fn new(a: &[f64], b: &[f64], bins: usize) -> Result<Self, StatsError> {
        check_sample("histogram (first sample)", a, 1)?;
        check_sample("histogram (second sample)", b, 1)?;
        if bins == 0 {
            return Err(StatsError::Domain {
                what: "histogram",
                detail: "needs at least one bin".into(),
            });
        }
        let all = a.iter().chain(b);
        let lo = all.clone().copied().fold(f64::INFINITY, f64::min);
        let hi = all.copied().fold(f64::NEG_INFINITY, f64::max);
        if hi <= lo {
            return Err(StatsError::ZeroVariance { what: "histogram" });
        }
        let width = (hi - lo) / bins as f64;
        let edges = (0..=bins).map(|i| lo + width * i as f64).collect();
        let count = |values: &[f64]| {
            let mut counts = vec![0; bins];
            for v in values {
                let bin = (((v - lo) / width).floor() as usize).min(bins - 1);
                counts[bin] += 1;
            }
            counts
        };
        Ok(Self {
            edges,
            counts_a: count(a),
            counts_b: count(b),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // numpy 2.4.6 `np.quantile(x, p)` and `np.std(x, ddof=1)`, printed by
    // `python tests/reference/descriptive.py`.
    const SAMPLE: [f64; 7] = [3.1, -0.4, 7.7, 2.2, 2.2, 10.5, 0.9];
    const QUANTILES: [(f64, f64); 5] = [
        (0.0, -0.4),
        (0.05, -0.009999999999999953),
        (0.3, 1.94),
        (0.5, 2.2),
        (0.95, 9.659999999999998),
    ];
    const SD: f64 = 3.910182068590133;

    #[test]
    fn quantiles_and_sd_match_numpy() {
        for (p, want) in QUANTILES {
            let got = quantile(&SAMPLE, p).unwrap();
            assert!((got - want).abs() < 1e-12, "q({p}) = {got}, want {want}");
        }
        assert!((sample_sd(&SAMPLE).unwrap() - SD).abs() < 1e-12);
        let summary = Summary::of(&SAMPLE).unwrap();
        assert_eq!((summary.count, summary.min, summary.max), (7, -0.4, 10.5));
        assert!((summary.mean - 26.2 / 7.0).abs() < 1e-12);
        assert!((summary.p95 - 9.66).abs() < 1e-12);
    }

    #[test]
    fn quantiles_interpolate_between_order_statistics() {
        let values = [10.0, 0.0, 20.0, 30.0];
        // h = 3p: p = 0.5 → between 10 and 20; p = 1/6 → halfway 0..10
        assert_eq!(quantile(&values, 0.5).unwrap(), 15.0);
        assert!((quantile(&values, 1.0 / 6.0).unwrap() - 5.0).abs() < 1e-12);
        assert_eq!(quantile(&values, 1.0).unwrap(), 30.0);
    }

    #[test]
    fn statistics_without_enough_values_say_why() {
        assert!(matches!(
            mean(&[]),
            Err(StatsError::TooFew { needed: 1, .. })
        ));
        assert!(matches!(
            sample_sd(&[1.0]),
            Err(StatsError::TooFew { needed: 2, .. })
        ));
        assert!(matches!(
            mean(&[1.0, f64::NAN]),
            Err(StatsError::NotFinite { index: 1, .. })
        ));
        assert!(quantile(&[1.0], 1.5).is_err());
        assert!(matches!(
            CommonHistograms::new(&[2.0], &[2.0, 2.0], 4),
            Err(StatsError::ZeroVariance { .. })
        ));
    }

    #[test]
    fn common_histograms_share_edges_and_count_every_value() {
        let a = [0.0, 0.5, 1.0, 3.9, 4.0];
        let b = [2.0, 2.5, 8.0];
        let h = CommonHistograms::new(&a, &b, 4).unwrap();
        assert_eq!(h.edges, vec![0.0, 2.0, 4.0, 6.0, 8.0]);
        assert_eq!(h.counts_a, vec![3, 1, 1, 0]);
        assert_eq!(h.counts_b, vec![0, 2, 0, 1]);
    }
}
