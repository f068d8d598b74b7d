//! Summary statistics of a cohort's pairwise Chamfer distances (the diversity figure) and
//! of per-shape values (novelty, anatomical measurements).

use serde::{Deserialize, Serialize};

/// Number of histogram bins in a summary.
pub const HISTOGRAM_BINS: usize = 20;

/// Statistics over the distinct pairs (i < j) of a symmetric distance matrix.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct PairwiseSummary {
    /// Number of pairs, n(n−1)/2.
    pub pairs: usize,
    /// Mean distance.
    pub mean: f64,
    /// Sample standard deviation (n−1 denominator; 0 for a single pair).
    pub std: f64,
    /// Smallest distance.
    pub min: f64,
    /// Largest distance.
    pub max: f64,
    /// Quantiles by linear interpolation between order statistics.
    pub quantiles: Quantiles,
    /// Equal-width histogram over [min, max].
    pub histogram: Histogram,
}

/// Selected quantiles.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Quantiles {
    /// 5 %.
    pub p05: f64,
    /// 25 %.
    pub p25: f64,
    /// Median.
    pub p50: f64,
    /// 75 %.
    pub p75: f64,
    /// 95 %.
    pub p95: f64,
}

/// Equal-width bins; `edges` has one more entry than `counts`, the last bin is closed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Histogram {
    /// Bin edges, ascending.
    pub edges: Vec<f64>,
    /// Pairs per bin.
    pub counts: Vec<usize>,
}

/// Statistics over one value per shape.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ValueSummary {
    /// Number of values (shapes with the value).
    pub count: usize,
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (n−1 denominator; 0 for a single value).
    pub std: f64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Quantiles by linear interpolation between order statistics.
    pub quantiles: Quantiles,
    /// Equal-width histogram over [min, max].
    pub histogram: Histogram,
}

/// Summarises the upper triangle of `matrix`; None when there is no pair.
pub fn summarize(matrix: &[Vec<f64>]) -> Option<PairwiseSummary> {
    let values: Vec<f64> = (0..matrix.len())
        .flat_map(|i| (i + 1..matrix.len()).map(move |j| (i, j)))
        .map(|(i, j)| matrix[i][j])
        .collect();
    let s = summarize_values(values)?;
    Some(PairwiseSummary {
        pairs: s.count,
        mean: s.mean,
        std: s.std,
        min: s.min,
        max: s.max,
        quantiles: s.quantiles,
        histogram: s.histogram,
    })
}

/// Summarises a list of values (non-finite ones are dropped); None when none is left.
pub fn summarize_values(mut values: Vec<f64>) -> Option<ValueSummary> {
    values.retain(|v| v.is_finite());
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    let mean = values.iter().sum::<f64>() / n as f64;
    let var = if n > 1 {
        values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64
    } else {
        0.0
    };
    let q = |p: f64| quantile_sorted(&values, p);
    Some(ValueSummary {
        count: n,
        mean,
        std: var.sqrt(),
        min: values[0],
        max: values[n - 1],
        quantiles: Quantiles {
            p05: q(0.05),
            p25: q(0.25),
            p50: q(0.5),
            p75: q(0.75),
            p95: q(0.95),
        },
        histogram: histogram(&values, HISTOGRAM_BINS),
    })
}

fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    let pos = p * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

/// Equal-width histogram of non-empty sorted values over [min, max].
pub fn histogram(sorted: &[f64], bins: usize) -> Histogram {
    let (min, max) = (sorted[0], sorted[sorted.len() - 1]);
    let width = (max - min) / bins as f64;
    let edges = (0..=bins).map(|b| min + width * b as f64).collect();
    let mut counts = vec![0; bins];
    for v in sorted {
        let b = if width > 0.0 {
            ((v - min) / width) as usize
        } else {
            0
        };
        counts[b.min(bins - 1)] += 1;
    }
    Histogram { edges, counts }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn matrix_from_points(x: &[f64]) -> Vec<Vec<f64>> {
        x.iter()
            .map(|a| x.iter().map(|b| (a - b).abs()).collect())
            .collect()
    }

    #[test]
    fn summary_matches_hand_computed_values() {
        // Points 0, 1, 3 → pair distances 1, 3, 2.
        let s = summarize(&matrix_from_points(&[0.0, 1.0, 3.0])).unwrap();
        assert_eq!(s.pairs, 3);
        assert_eq!((s.min, s.max, s.mean), (1.0, 3.0, 2.0));
        assert!((s.std - 1.0).abs() < 1e-12);
        assert_eq!(s.quantiles.p50, 2.0);
        assert!((s.quantiles.p25 - 1.5).abs() < 1e-12);
        assert!((s.quantiles.p95 - 2.9).abs() < 1e-12);
        assert_eq!(s.histogram.counts.iter().sum::<usize>(), 3);
        assert_eq!(s.histogram.counts[0], 1);
        assert_eq!(s.histogram.counts[HISTOGRAM_BINS - 1], 1);
        assert_eq!(s.histogram.edges.len(), HISTOGRAM_BINS + 1);
    }

    #[test]
    fn value_summaries_drop_non_finite_values() {
        let s = summarize_values(vec![3.0, f64::NAN, 1.0, 2.0]).unwrap();
        assert_eq!((s.count, s.min, s.max, s.mean), (3, 1.0, 3.0, 2.0));
        assert_eq!(s.quantiles.p50, 2.0);
        assert_eq!(summarize_values(vec![f64::INFINITY]), None);
    }

    #[test]
    fn degenerate_inputs_are_handled() {
        assert_eq!(summarize(&[vec![0.0]]), None);
        let s = summarize(&matrix_from_points(&[0.0, 2.0])).unwrap();
        assert_eq!((s.pairs, s.std, s.histogram.counts[0]), (1, 0.0, 1));
    }
}
