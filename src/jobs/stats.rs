//! Summary statistics of a cohort's pairwise Chamfer distances (the diversity figure) and
//! of per-shape values (novelty, anatomical measurements).

use serde::{Deserialize, Serialize};

use crate::stats::pair_sample;

/// Number of histogram bins in a summary.
pub const HISTOGRAM_BINS: usize = 20;

/// Statistics over the distinct pairs (i < j) of a cohort's shapes: all of them, or beyond
/// [`EXACT_MAX_SHAPES`](crate::stats::pair_sample::EXACT_MAX_SHAPES) shapes a uniform
/// random sample of them with 95 % confidence intervals for the mean and median of all
/// pairs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct PairwiseSummary {
    /// Number of pairs the statistics are over.
    pub pairs: usize,
    /// Every distinct pair of the cohort's shapes, n(n−1)/2 (equal to `pairs` unless
    /// `sampled`).
    #[serde(default)]
    pub population_pairs: u64,
    /// Whether `pairs` is a uniform random sample (without replacement, drawn from the
    /// cohort's seed) of the `population_pairs`.
    #[serde(default)]
    pub sampled: bool,
    /// 95 % confidence interval of the mean over all pairs (normal approximation with the
    /// finite-population correction); null when every pair was computed.
    #[serde(default)]
    pub mean_ci95: Option<[f64; 2]>,
    /// 95 % distribution-free confidence interval of the median over all pairs (order
    /// statistics of the sample); null when every pair was computed.
    #[serde(default)]
    pub median_ci95: Option<[f64; 2]>,
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

/// The stored pair distances of a cohort.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PairDistances {
    /// Every pair: the symmetric matrix in shape-index order (zero diagonal).
    Matrix(Vec<Vec<f64>>),
    /// A sample of the pairs of a cohort of `shapes` shapes: `(i, j, d)` with `i < j`.
    Sample {
        /// Shapes of the cohort.
        shapes: usize,
        /// The sampled pairs and their distances.
        pairs: Vec<(u32, u32, f64)>,
    },
}

impl PairDistances {
    /// Distances of `pairs` among `shapes` shapes: the matrix when they are every pair.
    pub fn new(shapes: usize, sampled: bool, pairs: Vec<(u32, u32, f64)>) -> Self {
        if sampled {
            return Self::Sample { shapes, pairs };
        }
        let mut matrix = vec![vec![0.0; shapes]; shapes];
        for (i, j, d) in pairs {
            matrix[i as usize][j as usize] = d;
            matrix[j as usize][i as usize] = d;
        }
        Self::Matrix(matrix)
    }

    /// Each computed pair once, `(i, j, d)` with `i < j`, in `(i, j)` order.
    pub fn pairs(&self) -> Vec<(u32, u32, f64)> {
        match self {
            Self::Matrix(m) => (0..m.len())
                .flat_map(|i| (i + 1..m.len()).map(move |j| (i as u32, j as u32, m[i][j])))
                .collect(),
            Self::Sample { pairs, .. } => {
                let mut out = pairs.clone();
                out.sort_by_key(|&(i, j, _)| (i, j));
                out
            }
        }
    }

    /// The computed distances, each pair once.
    pub fn values(&self) -> Vec<f64> {
        self.pairs().into_iter().map(|(_, _, d)| d).collect()
    }

    /// The symmetric matrix with `None` for pairs outside the sample.
    pub fn matrix(&self) -> Vec<Vec<Option<f64>>> {
        match self {
            Self::Matrix(m) => m
                .iter()
                .map(|row| row.iter().copied().map(Some).collect())
                .collect(),
            Self::Sample { shapes, pairs } => {
                let n = *shapes;
                let mut m: Vec<Vec<Option<f64>>> = (0..n)
                    .map(|i| (0..n).map(|j| (i == j).then_some(0.0)).collect())
                    .collect();
                for &(i, j, d) in pairs {
                    m[i as usize][j as usize] = Some(d);
                    m[j as usize][i as usize] = Some(d);
                }
                m
            }
        }
    }

    /// Every distinct pair of the cohort's shapes, n(n−1)/2.
    pub fn population(&self) -> u64 {
        match self {
            Self::Matrix(m) => pair_sample::pair_count(m.len()),
            Self::Sample { shapes, .. } => pair_sample::pair_count(*shapes),
        }
    }

    /// Whether the distances are a sample of the pairs.
    pub fn is_sampled(&self) -> bool {
        matches!(self, Self::Sample { .. })
    }
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

/// Summarises the upper triangle of `matrix` (every pair computed); None when there is no
/// pair.
pub fn summarize(matrix: &[Vec<f64>]) -> Option<PairwiseSummary> {
    let values: Vec<f64> = (0..matrix.len())
        .flat_map(|i| (i + 1..matrix.len()).map(move |j| (i, j)))
        .map(|(i, j)| matrix[i][j])
        .collect();
    let population = values.len() as u64;
    summarize_pairs(values, population)
}

/// Summarises pair distances computed over `values.len()` of the cohort's `population`
/// pairs, with confidence intervals when that is a sample; None when there is no pair.
pub fn summarize_pairs(values: Vec<f64>, population: u64) -> Option<PairwiseSummary> {
    let mut sorted = values;
    sorted.retain(|v| v.is_finite());
    sorted.sort_by(f64::total_cmp);
    let s = summarize_values(sorted.clone())?;
    let sampled = (s.count as u64) < population;
    Some(PairwiseSummary {
        pairs: s.count,
        population_pairs: population.max(s.count as u64),
        sampled,
        mean_ci95: pair_sample::mean_interval(s.mean, s.std, s.count as u64, population),
        median_ci95: if sampled {
            pair_sample::median_interval(&sorted)
        } else {
            None
        },
        mean: s.mean,
        std: s.std,
        min: s.min,
        max: s.max,
        quantiles: s.quantiles,
        histogram: s.histogram,
    })
}

impl PairwiseSummary {
    /// A summary as stored; one stored before sampling existed covers every pair.
    pub fn from_stored(json: &str) -> serde_json::Result<Option<Self>> {
        let mut summary: Option<Self> = serde_json::from_str(json)?;
        if let Some(s) = summary.as_mut().filter(|s| s.population_pairs == 0) {
            s.population_pairs = s.pairs as u64;
        }
        Ok(summary)
    }
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
    fn a_sample_of_pairs_carries_intervals_and_a_census_does_not() {
        let all = summarize(&matrix_from_points(&[0.0, 1.0, 3.0, 7.0])).unwrap();
        assert_eq!(
            (all.pairs, all.population_pairs, all.sampled),
            (6, 6, false)
        );
        assert_eq!((all.mean_ci95, all.median_ci95), (None, None));
        let values: Vec<f64> = (0..50).map(|k| f64::from(k) * 0.1).collect();
        let s = summarize_pairs(values, 1_000).unwrap();
        assert_eq!((s.pairs, s.population_pairs, s.sampled), (50, 1_000, true));
        let [lo, hi] = s.mean_ci95.unwrap();
        assert!(lo < s.mean && s.mean < hi);
        // Half-width 1.96 · sd / √m · √((N−m)/(N−1)).
        let half = 1.959_963_984_540_054 * s.std / 50f64.sqrt() * (950.0f64 / 999.0).sqrt();
        assert!(((hi - lo) / 2.0 - half).abs() < 1e-12);
        let [lo, hi] = s.median_ci95.unwrap();
        assert!(lo < s.quantiles.p50 && s.quantiles.p50 < hi);
    }

    #[test]
    fn a_summary_stored_before_sampling_reads_as_a_census() {
        let mut old =
            serde_json::to_value(summarize(&matrix_from_points(&[0.0, 2.0, 5.0]))).unwrap();
        for key in ["population_pairs", "sampled", "mean_ci95", "median_ci95"] {
            old.as_object_mut().unwrap().remove(key);
        }
        let read = PairwiseSummary::from_stored(&old.to_string())
            .unwrap()
            .unwrap();
        assert_eq!(
            (read.pairs, read.population_pairs, read.sampled),
            (3, 3, false)
        );
        assert_eq!(PairwiseSummary::from_stored("null").unwrap(), None);
    }

    #[test]
    fn pair_distances_store_a_census_as_the_matrix_and_a_sample_as_pairs() {
        let all = PairDistances::new(3, false, vec![(0, 1, 1.0), (1, 2, 2.0), (0, 2, 3.0)]);
        let json = serde_json::to_string(&all).unwrap();
        assert_eq!(json, "[[0.0,1.0,3.0],[1.0,0.0,2.0],[3.0,2.0,0.0]]");
        let read: PairDistances = serde_json::from_str(&json).unwrap();
        assert_eq!(read.values(), vec![1.0, 3.0, 2.0]);
        assert!(!read.is_sampled());
        let sample = PairDistances::new(4, true, vec![(2, 3, 5.0), (0, 2, 4.0)]);
        let read: PairDistances =
            serde_json::from_str(&serde_json::to_string(&sample).unwrap()).unwrap();
        assert!(read.is_sampled());
        assert_eq!(read.pairs(), vec![(0, 2, 4.0), (2, 3, 5.0)]);
        let m = read.matrix();
        assert_eq!(m[2][0], Some(4.0));
        assert_eq!(m[3][2], Some(5.0));
        assert_eq!(m[1][1], Some(0.0));
        assert_eq!(m[0][1], None);
    }

    #[test]
    fn degenerate_inputs_are_handled() {
        assert_eq!(summarize(&[vec![0.0]]), None);
        let s = summarize(&matrix_from_points(&[0.0, 2.0])).unwrap();
        assert_eq!((s.pairs, s.std, s.histogram.counts[0]), (1, 0.0, 1));
    }
}
