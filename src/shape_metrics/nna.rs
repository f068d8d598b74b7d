//! 1-NNA: the leave-one-out accuracy of a 1-nearest-neighbour classifier that tells
//! generated shapes S from reference shapes R on S ∪ R (PointFlow's `knn` with k = 1).
//! Each shape is labelled by its nearest other shape; the accuracy is the share labelled
//! correctly. 0.5 means the sets cannot be told apart, 1 that they are separated, and
//! values near 0 that every shape sits next to one of the other set (S copies R).
//!
//! The accuracy is only comparable to 0.5 when |S| = |R|. With unequal sizes the larger
//! set is subsampled without replacement to the smaller size, repeatedly (ChaCha8 from
//! the seed), and the estimate reports the mean and the 2.5–97.5 % range over subsets.
//! Exact distance ties among a shape's nearest neighbours count fractionally: the shape
//! scores the share of its tied nearest neighbours that carry its own label (the expected
//! score under a random choice; PointFlow's `topk` picks one arbitrarily).

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{DistanceMatrix, ShapeMetricsError, expect_shape};
use crate::stats::descriptive::quantile_sorted;

/// Default number of equal-size subsets when |S| ≠ |R|.
pub const DEFAULT_SUBSETS: usize = 200;

/// How unequal sets are subsampled.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NnaConfig {
    /// Number of subsets (used only when the sizes differ).
    pub subsets: usize,
    /// Seed of the subsampling.
    pub seed: u64,
}

impl Default for NnaConfig {
    fn default() -> Self {
        Self {
            subsets: DEFAULT_SUBSETS,
            seed: 0,
        }
    }
}

/// 1-NNA over equal-size subsets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct NnaEstimate {
    /// Mean accuracy over subsets (the accuracy itself when |S| = |R|).
    pub mean: f64,
    /// 2.5 % quantile of the subset accuracies.
    pub low: f64,
    /// 97.5 % quantile of the subset accuracies.
    pub high: f64,
    /// Shapes per set in each subset, min(|S|, |R|).
    pub subset_size: usize,
    /// Number of subsets evaluated (1 when the sizes are equal).
    pub subsets: usize,
}

/// The three matrices of one comparison, checked against each other.
struct Distances<'a> {
    sr: &'a DistanceMatrix,
    ss: &'a DistanceMatrix,
    rr: &'a DistanceMatrix,
}

impl<'a> Distances<'a> {
    fn new(
        sr: &'a DistanceMatrix,
        ss: &'a DistanceMatrix,
        rr: &'a DistanceMatrix,
    ) -> Result<Self, ShapeMetricsError> {
        let (ns, nr) = (sr.rows(), sr.cols());
        expect_shape("1-NNA generated × generated", ss, ns, ns)?;
        expect_shape("1-NNA reference × reference", rr, nr, nr)?;
        if ns == 0 || nr == 0 {
            return Err(ShapeMetricsError::TooFew {
                what: "1-NNA (generated and reference sets)",
                needed: 1,
                got: ns.min(nr),
            });
        }
        Ok(Self { sr, ss, rr })
    }

    /// Leave-one-out accuracy on the generated shapes `s` and reference shapes `r`.
    fn accuracy(&self, s: &[usize], r: &[usize]) -> f64 {
        let score_s: f64 = s
            .iter()
            .map(|&i| {
                let same = s.iter().filter(|&&k| k != i).map(|&k| self.ss.get(i, k));
                let other = r.iter().map(|&j| self.sr.get(i, j));
                nearest_same_share(same, other)
            })
            .sum();
        let score_r: f64 = r
            .iter()
            .map(|&j| {
                let same = r.iter().filter(|&&k| k != j).map(|&k| self.rr.get(j, k));
                let other = s.iter().map(|&i| self.sr.get(i, j));
                nearest_same_share(same, other)
            })
            .sum();
        (score_s + score_r) / (s.len() + r.len()) as f64
    }
}

/// Share of the nearest neighbours (all at the minimum distance) that have the same label.
fn nearest_same_share(same: impl Iterator<Item = f64>, other: impl Iterator<Item = f64>) -> f64 {
    let (mut best, mut n_same, mut n_other) = (f64::INFINITY, 0usize, 0usize);
    let labelled = same.map(|d| (d, true)).chain(other.map(|d| (d, false)));
    for (d, is_same) in labelled {
        if d < best {
            (best, n_same, n_other) = (d, 0, 0);
        }
        if d == best {
            if is_same {
                n_same += 1;
            } else {
                n_other += 1;
            }
        }
    }
    if n_same + n_other == 0 {
        0.0
    } else {
        n_same as f64 / (n_same + n_other) as f64
    }
}

/// 1-NNA of equal-size sets from the generated × reference, generated × generated and
/// reference × reference distances (diagonals are ignored).
pub fn one_nna(
    generated_to_reference: &DistanceMatrix,
    generated_to_generated: &DistanceMatrix,
    reference_to_reference: &DistanceMatrix,
) -> Result<f64, ShapeMetricsError> {
    let d = Distances::new(
        generated_to_reference,
        generated_to_generated,
        reference_to_reference,
    )?;
    let (ns, nr) = (d.sr.rows(), d.sr.cols());
    if ns != nr {
        return Err(ShapeMetricsError::Dimension {
            what: "1-NNA",
            detail: format!("{ns} generated and {nr} reference shapes; use one_nna_subsampled"),
        });
    }
    Ok(d.accuracy(&(0..ns).collect::<Vec<_>>(), &(0..nr).collect::<Vec<_>>()))
}

/// 1-NNA on equal-size subsets: the larger set is subsampled `config.subsets` times to
/// the smaller set's size; equal sets are evaluated once, exactly.
pub fn one_nna_subsampled(
    generated_to_reference: &DistanceMatrix,
    generated_to_generated: &DistanceMatrix,
    reference_to_reference: &DistanceMatrix,
    config: &NnaConfig,
) -> Result<NnaEstimate, ShapeMetricsError> {
    let d = Distances::new(
        generated_to_reference,
        generated_to_generated,
        reference_to_reference,
    )?;
    let (ns, nr) = (d.sr.rows(), d.sr.cols());
    let k = ns.min(nr);
    let all = |n: usize| (0..n).collect::<Vec<_>>();
    if ns == nr {
        let a = d.accuracy(&all(ns), &all(nr));
        return Ok(estimate(vec![a], k));
    }
    if config.subsets == 0 {
        return Err(ShapeMetricsError::Domain {
            what: "1-NNA subsets",
            detail: "needs at least one subset".into(),
        });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let accuracies = (0..config.subsets)
        .map(|_| {
            if ns > nr {
                d.accuracy(&choose(&mut rng, ns, k), &all(nr))
            } else {
                d.accuracy(&all(ns), &choose(&mut rng, nr, k))
            }
        })
        .collect();
    Ok(estimate(accuracies, k))
}

fn estimate(mut accuracies: Vec<f64>, subset_size: usize) -> NnaEstimate {
    accuracies.sort_by(f64::total_cmp);
    // never empty and p in range, so the quantile always exists
    let q = |p| quantile_sorted(&accuracies, p).unwrap_or(0.0);
    NnaEstimate {
        mean: accuracies.iter().sum::<f64>() / accuracies.len() as f64,
        low: q(0.025),
        high: q(0.975),
        subset_size,
        subsets: accuracies.len(),
    }
}

/// `k` distinct indices of 0..n (partial Fisher–Yates), in ascending order.
fn choose(rng: &mut ChaCha8Rng, n: usize, k: usize) -> Vec<usize> {
    let mut pool: Vec<usize> = (0..n).collect();
    for i in 0..k {
        let j = rng.random_range(i..n);
        pool.swap(i, j);
    }
    pool.truncate(k);
    pool.sort_unstable();
    pool
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape_metrics::test_sets::{gaussian_points, squared};

    fn matrices(s: &[[f64; 3]], r: &[[f64; 3]]) -> [DistanceMatrix; 3] {
        [
            DistanceMatrix::between(s, r, squared),
            DistanceMatrix::between(s, s, squared),
            DistanceMatrix::between(r, r, squared),
        ]
    }

    /// PointFlow's construction: the (|R| + |S|)² block matrix with an infinite diagonal,
    /// each column labelled by its nearest row.
    fn brute_force(s: &[[f64; 3]], r: &[[f64; 3]]) -> f64 {
        let all: Vec<([f64; 3], bool)> = r
            .iter()
            .map(|p| (*p, true))
            .chain(s.iter().map(|p| (*p, false)))
            .collect();
        let correct = (0..all.len())
            .filter(|&c| {
                let nearest = (0..all.len())
                    .filter(|&k| k != c)
                    .min_by(|&a, &b| {
                        squared(&all[a].0, &all[c].0).total_cmp(&squared(&all[b].0, &all[c].0))
                    })
                    .unwrap();
                all[nearest].1 == all[c].1
            })
            .count();
        correct as f64 / all.len() as f64
    }

    #[test]
    fn accuracy_equals_pointflows_block_matrix_construction() {
        let s = gaussian_points(25, 0.4, 1);
        let r = gaussian_points(25, 0.0, 2);
        let [sr, ss, rr] = matrices(&s, &r);
        assert_eq!(one_nna(&sr, &ss, &rr).unwrap(), brute_force(&s, &r));
    }

    #[test]
    fn copies_score_zero_and_separated_sets_score_one() {
        let r = gaussian_points(20, 0.0, 3);
        let [sr, ss, rr] = matrices(&r, &r);
        assert_eq!(one_nna(&sr, &ss, &rr).unwrap(), 0.0);
        let far = gaussian_points(20, 50.0, 4);
        let [sr, ss, rr] = matrices(&far, &r);
        assert_eq!(one_nna(&sr, &ss, &rr).unwrap(), 1.0);
    }

    #[test]
    fn halves_of_one_population_score_near_one_half() {
        // 2 × 150 shapes: the accuracy's standard error is about √(¼/300) ≈ 0.03, so a
        // correct implementation lands within 0.1 (over 3 standard errors) of ½.
        let population = gaussian_points(300, 0.0, 5);
        let (s, r) = population.split_at(150);
        let [sr, ss, rr] = matrices(s, r);
        let a = one_nna(&sr, &ss, &rr).unwrap();
        assert!((a - 0.5).abs() < 0.1, "1-NNA {a}");
    }

    #[test]
    fn over_many_populations_the_mean_is_the_exchangeable_expectation() {
        // S and R of k points each from one law: a point's nearest other point is one of
        // the k − 1 of its own set or the k of the other with equal chance, so
        // E[1-NNA] = (k − 1)/(2k − 1) exactly; the mean of 400 draws has an sd near 0.006.
        let k = 10;
        let mean = (0..400u64)
            .map(|seed| {
                let s = gaussian_points(k, 0.0, 100 + seed);
                let r = gaussian_points(k, 0.0, 900 + seed);
                let [sr, ss, rr] = matrices(&s, &r);
                one_nna(&sr, &ss, &rr).unwrap()
            })
            .sum::<f64>()
            / 400.0;
        let want = (k - 1) as f64 / (2 * k - 1) as f64;
        assert!((mean - want).abs() < 0.025, "mean {mean} vs {want}");
    }

    #[test]
    fn ties_count_as_the_share_of_same_labelled_neighbours() {
        // s0 at 0, r0 and r1 both at distance 1 from s0 and 2 from each other; s1 far.
        let sr = DistanceMatrix::from_rows("sr", &[vec![1.0, 1.0], vec![9.0, 9.0]]).unwrap();
        let ss = DistanceMatrix::from_rows("ss", &[vec![0.0, 9.0], vec![9.0, 0.0]]).unwrap();
        let rr = DistanceMatrix::from_rows("rr", &[vec![0.0, 2.0], vec![2.0, 0.0]]).unwrap();
        // s0 → r0/r1 (wrong), s1 → s0 (9, tied with r0 and r1: ⅓ right),
        // r0 → s0 (wrong), r1 → s0 (wrong)
        let a = one_nna(&sr, &ss, &rr).unwrap();
        assert!((a - (1.0 / 3.0) / 4.0).abs() < 1e-15, "{a}");
    }

    #[test]
    fn unequal_sets_are_subsampled_reproducibly_with_an_interval() {
        let s = gaussian_points(60, 0.0, 6);
        let r = gaussian_points(20, 0.0, 7);
        let [sr, ss, rr] = matrices(&s, &r);
        let config = NnaConfig {
            subsets: 100,
            seed: 9,
        };
        let e = one_nna_subsampled(&sr, &ss, &rr, &config).unwrap();
        assert_eq!((e.subset_size, e.subsets), (20, 100));
        assert!(
            e.low <= e.mean && e.mean <= e.high && e.low < e.high,
            "{e:?}"
        );
        assert!((e.mean - 0.5).abs() < 0.15, "{e:?}");
        assert_eq!(e, one_nna_subsampled(&sr, &ss, &rr, &config).unwrap());
        assert!(matches!(
            one_nna(&sr, &ss, &rr),
            Err(ShapeMetricsError::Dimension { .. })
        ));
        // equal sizes: one exact evaluation
        let [sr, ss, rr] = matrices(&s[..20], &r);
        let e = one_nna_subsampled(&sr, &ss, &rr, &config).unwrap();
        assert_eq!((e.subsets, e.low, e.high), (1, e.mean, e.mean));
        assert_eq!(e.mean, one_nna(&sr, &ss, &rr).unwrap());
    }
}
