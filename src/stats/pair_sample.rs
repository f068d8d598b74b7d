//! Which pairs of a cohort's shapes its pairwise statistics are computed over, and how
//! far a sample of pairs can be trusted.
//!
//! A cohort of n shapes has n(n−1)/2 distinct pairs: every one of them up to
//! [`EXACT_MAX_SHAPES`] shapes (4 950 pairs), beyond that a uniform random sample of
//! [`SAMPLED_PAIRS`] pairs drawn without replacement from the cohort's seed, so the cost of
//! the step stays that of a 100-shape cohort whatever the cohort's size. Statistics of a
//! sample carry 95 % confidence intervals ([`mean_interval`], [`median_interval`]).
//!
//! The pairs are cut into tasks of at most [`PAIRS_PER_TASK`] pairs that any worker can
//! compute on its own; the order groups pairs whose shapes are close in index (tiles of the
//! matrix), so a task reads few meshes.

use std::collections::HashSet;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Largest cohort whose pairs are all computed.
pub const EXACT_MAX_SHAPES: usize = 100;

/// Pairs in the sample of a larger cohort: as many as a cohort of [`EXACT_MAX_SHAPES`] has.
pub const SAMPLED_PAIRS: usize = EXACT_MAX_SHAPES * (EXACT_MAX_SHAPES - 1) / 2;

/// Pairs per task: a few seconds of a release build at the service's Chamfer points.
pub const PAIRS_PER_TASK: usize = 400;

/// The standard normal's 97.5 % quantile.
const Z_95: f64 = 1.959_963_984_540_054;

/// The pairs of a cohort its statistics are over, in task order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PairPlan {
    shapes: usize,
    sampled: bool,
    pairs: Vec<(u32, u32)>,
}

impl PairPlan {
    /// The plan of a cohort of `shapes` shapes drawn from `seed` (used only when sampling).
    pub fn new(shapes: usize, seed: u64) -> Self {
        let population = pair_count(shapes);
        let sampled = shapes > EXACT_MAX_SHAPES;
        let mut pairs: Vec<(u32, u32)> = if sampled {
            sample_ranks(population, SAMPLED_PAIRS as u64, seed)
                .into_iter()
                .map(pair_of_rank)
                .collect()
        } else {
            (0..shapes as u32)
                .flat_map(|j| (0..j).map(move |i| (i, j)))
                .collect()
        };
        let tile = tile_size(pairs.len() as f64 / population.max(1) as f64);
        pairs.sort_unstable_by_key(|&(i, j)| (i / tile, j / tile, i, j));
        Self {
            shapes,
            sampled,
            pairs,
        }
    }

    /// Shapes of the cohort.
    pub fn shapes(&self) -> usize {
        self.shapes
    }

    /// Whether the pairs are a random sample rather than all of them.
    pub fn is_sampled(&self) -> bool {
        self.sampled
    }

    /// Every distinct pair of the cohort, n(n−1)/2.
    pub fn population(&self) -> u64 {
        pair_count(self.shapes)
    }

    /// The planned pairs `(i, j)`, `i < j`, in task order.
    pub fn pairs(&self) -> &[(u32, u32)] {
        &self.pairs
    }

    /// Tasks the pairs are cut into; at least one, which finishes the statistics of a
    /// cohort without pairs.
    pub fn task_count(&self) -> usize {
        self.pairs.len().div_ceil(PAIRS_PER_TASK).max(1)
    }

    /// The pairs of task `task` (empty past the last one).
    pub fn task_pairs(&self, task: usize) -> &[(u32, u32)] {
        let start = (task * PAIRS_PER_TASK).min(self.pairs.len());
        let end = (start + PAIRS_PER_TASK).min(self.pairs.len());
        &self.pairs[start..end]
    }
}

/// n(n−1)/2.
pub fn pair_count(shapes: usize) -> u64 {
    let n = shapes as u64;
    n * n.saturating_sub(1) / 2
}

/// The pair of rank `r` when pairs are listed (0,1), (0,2), (1,2), (0,3), …: column `j` is
/// the largest with j(j−1)/2 ≤ r.
fn pair_of_rank(r: u64) -> (u32, u32) {
    let mut j = ((1.0 + (1.0 + 8.0 * r as f64).sqrt()) / 2.0) as u64;
    while j * (j - 1) / 2 > r {
        j -= 1;
    }
    while (j + 1) * j / 2 <= r {
        j += 1;
    }
    ((r - j * (j - 1) / 2) as u32, j as u32)
}

/// `m` distinct values of `0..population`, uniformly (Floyd's algorithm), sorted.
fn sample_ranks(population: u64, m: u64, seed: u64) -> Vec<u64> {
    let m = m.min(population);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x9A1F_5EED_0000_0001);
    let mut chosen = HashSet::with_capacity(m as usize);
    for top in population - m..population {
        let t = rng.random_range(0..=top);
        if !chosen.insert(t) {
            chosen.insert(top);
        }
    }
    let mut out: Vec<u64> = chosen.into_iter().collect();
    out.sort_unstable();
    out
}

/// Side of the matrix tiles tasks are cut along, for a share `density` of planned pairs:
/// about [`PAIRS_PER_TASK`] planned pairs a tile.
fn tile_size(density: f64) -> u32 {
    let side = (PAIRS_PER_TASK as f64 / density.max(1e-9)).sqrt();
    side.clamp(1.0, u32::MAX as f64) as u32
}

/// 95 % confidence interval of the mean of all `population` pairs from a simple random
/// sample's mean and standard deviation over `sampled` pairs (normal approximation with
/// the finite-population correction); None when the sample is the population or has fewer
/// than two pairs.
pub fn mean_interval(mean: f64, std: f64, sampled: u64, population: u64) -> Option<[f64; 2]> {
    if sampled < 2 || sampled >= population {
        return None;
    }
    let fpc = ((population - sampled) as f64 / (population - 1) as f64).sqrt();
    let half = Z_95 * std / (sampled as f64).sqrt() * fpc;
    Some([mean - half, mean + half])
}

/// Distribution-free 95 % confidence interval of the population median from the sorted
/// sample: the order statistics at ranks m/2 ∓ 1.96·√m/2 (the binomial's normal
/// approximation); None for fewer than two values.
pub fn median_interval(sorted: &[f64]) -> Option<[f64; 2]> {
    let m = sorted.len();
    if m < 2 {
        return None;
    }
    let half = Z_95 * (m as f64).sqrt() / 2.0;
    let centre = m as f64 / 2.0;
    let lo = ((centre - half).floor().max(1.0) as usize).min(m) - 1;
    let hi = ((centre + half).ceil() as usize).clamp(1, m) - 1;
    Some([sorted[lo], sorted[hi]])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_map_to_every_pair_once_in_order() {
        let mut expected = Vec::new();
        for j in 1..60u32 {
            for i in 0..j {
                expected.push((i, j));
            }
        }
        let got: Vec<_> = (0..expected.len() as u64).map(pair_of_rank).collect();
        assert_eq!(got, expected);
        // Far out, where the square root's rounding matters.
        let j: u64 = 3_000_000;
        assert_eq!(pair_of_rank(j * (j - 1) / 2), (0, j as u32));
        assert_eq!(
            pair_of_rank(j * (j - 1) / 2 - 1),
            (j as u32 - 2, j as u32 - 1)
        );
    }

    #[test]
    fn a_small_cohort_plans_every_pair_once() {
        for n in [0, 1, 2, 3, 30, EXACT_MAX_SHAPES] {
            let plan = PairPlan::new(n, 7);
            assert!(!plan.is_sampled());
            assert_eq!(plan.pairs().len() as u64, pair_count(n));
            let set: HashSet<_> = plan.pairs().iter().copied().collect();
            assert_eq!(set.len(), plan.pairs().len(), "n = {n}: a pair twice");
            assert!(plan.pairs().iter().all(|&(i, j)| i < j && (j as usize) < n));
            // Tasks partition the plan.
            let joined: Vec<_> = (0..plan.task_count())
                .flat_map(|t| plan.task_pairs(t).to_vec())
                .collect();
            assert_eq!(joined, plan.pairs());
            assert!(plan.task_pairs(plan.task_count()).is_empty());
        }
        assert_eq!(PairPlan::new(0, 1).task_count(), 1);
        assert_eq!(
            PairPlan::new(30, 1).task_count(),
            435usize.div_ceil(PAIRS_PER_TASK)
        );
    }

    #[test]
    fn a_large_cohort_samples_distinct_pairs_reproducibly() {
        let plan = PairPlan::new(200, 42);
        assert!(plan.is_sampled());
        assert_eq!(plan.population(), 19_900);
        assert_eq!(plan.pairs().len(), SAMPLED_PAIRS);
        let set: HashSet<_> = plan.pairs().iter().copied().collect();
        assert_eq!(set.len(), SAMPLED_PAIRS);
        assert!(plan.pairs().iter().all(|&(i, j)| i < j && j < 200));
        assert_eq!(plan, PairPlan::new(200, 42));
        assert_ne!(plan.pairs(), PairPlan::new(200, 43).pairs());
        // A task of a sampled plan reads far fewer shapes than the cohort has.
        let shapes: HashSet<u32> = plan
            .task_pairs(0)
            .iter()
            .flat_map(|&(i, j)| [i, j])
            .collect();
        assert!(shapes.len() < 120, "{} shapes in one task", shapes.len());
        // A huge cohort costs the same number of pairs.
        let huge = PairPlan::new(10_000, 1);
        assert_eq!(huge.pairs().len(), SAMPLED_PAIRS);
        assert_eq!(huge.population(), 49_995_000);
    }

    #[test]
    fn the_sample_is_uniform_over_pairs() {
        // Each pair of a 120-shape cohort (7 140 pairs) is drawn with probability 4950/7140;
        // over 200 seeds the count of draws of each shape's pairs matches that share.
        let n = 120usize;
        let p = SAMPLED_PAIRS as f64 / pair_count(n) as f64;
        let mut per_shape = vec![0u64; n];
        let seeds = 200;
        for seed in 0..seeds {
            for &(i, j) in PairPlan::new(n, seed).pairs() {
                per_shape[i as usize] += 1;
                per_shape[j as usize] += 1;
            }
        }
        let expected = seeds as f64 * (n - 1) as f64 * p;
        for (shape, &count) in per_shape.iter().enumerate() {
            let rel = (count as f64 - expected).abs() / expected;
            assert!(
                rel < 0.03,
                "shape {shape}: {count} draws, expected {expected:.0}"
            );
        }
    }

    #[test]
    fn intervals_cover_the_population_values_about_95_percent_of_the_time() {
        // A known population of pair values; 400 independent samples of 300 of its 4 000
        // values: the 95 % intervals must hold the true mean and median in ~95 % of them.
        let population: Vec<f64> = (0..4_000)
            .map(|k| {
                let x = (k as f64 * 0.618_033_988_75).fract();
                x * x * 3.0 + 0.1
            })
            .collect();
        let true_mean = population.iter().sum::<f64>() / population.len() as f64;
        let mut sorted_pop = population.clone();
        sorted_pop.sort_by(f64::total_cmp);
        let true_median = (sorted_pop[1999] + sorted_pop[2000]) / 2.0;
        let (mut mean_hits, mut median_hits) = (0, 0);
        let trials = 400;
        for seed in 0..trials {
            let ranks = sample_ranks(population.len() as u64, 300, seed);
            let mut s: Vec<f64> = ranks.iter().map(|&r| population[r as usize]).collect();
            s.sort_by(f64::total_cmp);
            let mean = s.iter().sum::<f64>() / s.len() as f64;
            let var = s.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (s.len() - 1) as f64;
            let [lo, hi] = mean_interval(mean, var.sqrt(), 300, 4_000).unwrap();
            mean_hits += usize::from(lo <= true_mean && true_mean <= hi);
            let [lo, hi] = median_interval(&s).unwrap();
            median_hits += usize::from(lo <= true_median && true_median <= hi);
        }
        for (what, hits) in [("mean", mean_hits), ("median", median_hits)] {
            let coverage = hits as f64 / trials as f64;
            assert!(
                (0.91..=0.99).contains(&coverage),
                "{what} interval coverage {coverage}"
            );
        }
    }

    #[test]
    fn no_interval_for_a_census_or_a_single_pair() {
        assert_eq!(mean_interval(1.0, 0.5, 10, 10), None);
        assert_eq!(mean_interval(1.0, 0.5, 1, 10), None);
        assert_eq!(median_interval(&[1.0]), None);
        let [lo, hi] = median_interval(&[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
        assert!(lo <= 3.0 && hi >= 3.0 && lo >= 1.0 && hi <= 5.0);
    }
}
