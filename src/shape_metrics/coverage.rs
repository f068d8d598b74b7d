//! Fidelity and coverage of a generated set S against a reference set R from the
//! |S| × |R| distance matrix (PointFlow's `lgan_mmd_cov`):
//! * MMD = mean over r ∈ R of min over s ∈ S of D(s, r) — how well the closest generated
//!   shape matches each reference shape (lower is better);
//! * COV = share of R that is the nearest reference of at least one s ∈ S — how much of
//!   the population the cohort reaches (higher is better; a cohort smaller than R cannot
//!   reach 1).
//!
//! A generated shape equally close to several references counts for the lowest-indexed
//! one (PointFlow's `torch.min` picks one of them too).

use serde::{Deserialize, Serialize};

use super::{DistanceMatrix, ShapeMetricsError};

/// MMD and COV of one generated set against one reference set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MmdCov {
    /// Mean over references of the distance to the nearest generated shape.
    pub mmd: f64,
    /// Share of references that are some generated shape's nearest reference.
    pub cov: f64,
    /// Mean over generated shapes of the distance to the nearest reference (PointFlow's
    /// `lgan_mmd_smp`).
    pub mmd_generated: f64,
    /// Index of each generated shape's nearest reference.
    pub nearest_reference: Vec<usize>,
}

/// MMD and COV from the generated × reference distances (both sets non-empty).
pub fn mmd_cov(generated_to_reference: &DistanceMatrix) -> Result<MmdCov, ShapeMetricsError> {
    let m = generated_to_reference;
    if m.rows() == 0 || m.cols() == 0 {
        return Err(ShapeMetricsError::TooFew {
            what: "MMD/COV (generated and reference sets)",
            needed: 1,
            got: m.rows().min(m.cols()),
        });
    }
    let nearest_reference: Vec<usize> = (0..m.rows()).map(|i| argmin(m.row(i))).collect();
    let mut covered = vec![false; m.cols()];
    for &j in &nearest_reference {
        covered[j] = true;
    }
    let mmd = (0..m.cols())
        .map(|j| {
            (0..m.rows())
                .map(|i| m.get(i, j))
                .fold(f64::INFINITY, f64::min)
        })
        .sum::<f64>()
        / m.cols() as f64;
    let mmd_generated = (0..m.rows())
        .map(|i| m.get(i, nearest_reference[i]))
        .sum::<f64>()
        / m.rows() as f64;
    Ok(MmdCov {
        mmd,
        cov: covered.iter().filter(|c| **c).count() as f64 / m.cols() as f64,
        mmd_generated,
        nearest_reference,
    })
}

/// Index of the smallest value, the first one on ties.
fn argmin(values: &[f64]) -> usize {
    let mut best = 0;
    for (k, v) in values.iter().enumerate() {
        if *v < values[best] {
            best = k;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape_metrics::test_sets::{gaussian_points, squared};

    #[test]
    fn copies_of_the_reference_cover_it_all_at_distance_zero() {
        let r = gaussian_points(15, 0.0, 1);
        let m = mmd_cov(&DistanceMatrix::between(&r, &r, squared)).unwrap();
        assert_eq!((m.mmd, m.cov, m.mmd_generated), (0.0, 1.0, 0.0));
        assert_eq!(m.nearest_reference, (0..15).collect::<Vec<_>>());
    }

    #[test]
    fn mmd_and_cov_equal_a_brute_force_count() {
        let s = gaussian_points(9, 0.3, 2);
        let r = gaussian_points(12, 0.0, 3);
        let m = mmd_cov(&DistanceMatrix::between(&s, &r, squared)).unwrap();
        let mut mmd = 0.0;
        for b in &r {
            let mut best = f64::INFINITY;
            for a in &s {
                best = best.min(squared(a, b));
            }
            mmd += best / r.len() as f64;
        }
        let mut hit = [false; 12];
        for a in &s {
            let d: Vec<f64> = r.iter().map(|b| squared(a, b)).collect();
            let j = (0..12).min_by(|&x, &y| d[x].total_cmp(&d[y])).unwrap();
            hit[j] = true;
        }
        assert!((m.mmd - mmd).abs() < 1e-12);
        assert_eq!(m.cov, hit.iter().filter(|h| **h).count() as f64 / 12.0);
    }

    #[test]
    fn a_collapsed_cohort_covers_one_reference() {
        // every generated shape is the same point: one nearest reference, COV = 1/|R|
        let s = vec![[0.1, 0.0, 0.0]; 8];
        let r = gaussian_points(10, 0.0, 4);
        let m = mmd_cov(&DistanceMatrix::between(&s, &r, squared)).unwrap();
        assert_eq!(m.cov, 0.1);
        assert!(mmd_cov(&DistanceMatrix::between(&s, &[], squared)).is_err());
    }
}
