//! Distance to the closest record (DCR), the privacy check: each generated shape's
//! distance to its nearest training shape, summarised beside the same figure for held-out
//! real shapes — how close a *new patient* comes to the training patients. A cohort whose
//! shapes sit closer to the training set than new patients do is reproducing training
//! anatomies rather than sampling the population.

use serde::{Deserialize, Serialize};

use super::{DistanceMatrix, ShapeMetricsError};
use crate::stats::descriptive::{Summary, quantile};

/// DCR of a generated set beside that of held-out real shapes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Dcr {
    /// Each generated shape's distance to its nearest training shape.
    pub generated: Vec<f64>,
    /// Each held-out shape's distance to its nearest training shape.
    pub heldout: Vec<f64>,
    /// Summary of `generated`.
    pub generated_summary: Summary,
    /// Summary of `heldout`.
    pub heldout_summary: Summary,
    /// median(generated) / median(held-out): below 1, the cohort is closer to the
    /// training patients than a new patient is (none when the held-out median is 0).
    pub median_ratio: Option<f64>,
    /// Share of generated shapes closer to the training set than the held-out shapes' 5 %
    /// quantile — near-copies of training patients.
    pub share_below_heldout_p05: f64,
}

/// DCR from the generated × training and held-out × training distances (≥ 2 generated
/// and ≥ 2 held-out shapes, ≥ 1 training shape).
pub fn dcr(
    generated_to_training: &DistanceMatrix,
    heldout_to_training: &DistanceMatrix,
) -> Result<Dcr, ShapeMetricsError> {
    if generated_to_training.cols() != heldout_to_training.cols() {
        return Err(ShapeMetricsError::Dimension {
            what: "DCR",
            detail: format!(
                "{} training columns for the generated shapes, {} for the held-out ones",
                generated_to_training.cols(),
                heldout_to_training.cols()
            ),
        });
    }
    let generated = nearest("DCR (generated shapes)", generated_to_training)?;
    let heldout = nearest("DCR (held-out shapes)", heldout_to_training)?;
    let summary = |what, v: &[f64]| {
        Summary::of(v).map_err(|_| ShapeMetricsError::TooFew {
            what,
            needed: 2,
            got: v.len(),
        })
    };
    let generated_summary = summary("DCR (generated shapes)", &generated)?;
    let heldout_summary = summary("DCR (held-out shapes)", &heldout)?;
    let threshold = quantile(&heldout, 0.05).unwrap_or(0.0);
    let below = generated.iter().filter(|d| **d < threshold).count();
    Ok(Dcr {
        median_ratio: (heldout_summary.median > 0.0)
            .then(|| generated_summary.median / heldout_summary.median),
        share_below_heldout_p05: below as f64 / generated.len() as f64,
        generated,
        heldout,
        generated_summary,
        heldout_summary,
    })
}

fn nearest(what: &'static str, m: &DistanceMatrix) -> Result<Vec<f64>, ShapeMetricsError> {
    if m.cols() == 0 {
        return Err(ShapeMetricsError::TooFew {
            what: "DCR (training shapes)",
            needed: 1,
            got: 0,
        });
    }
    if m.rows() < 2 {
        return Err(ShapeMetricsError::TooFew {
            what,
            needed: 2,
            got: m.rows(),
        });
    }
    Ok((0..m.rows())
        .map(|i| m.row(i).iter().copied().fold(f64::INFINITY, f64::min))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape_metrics::test_sets::{gaussian_points, squared};

    #[test]
    fn copies_of_training_shapes_sit_at_zero_and_are_flagged() {
        let training = gaussian_points(30, 0.0, 1);
        let heldout = gaussian_points(12, 0.0, 2);
        let copies: Vec<[f64; 3]> = training.iter().step_by(3).copied().collect();
        let d = dcr(
            &DistanceMatrix::between(&copies, &training, squared),
            &DistanceMatrix::between(&heldout, &training, squared),
        )
        .unwrap();
        assert!(d.generated.iter().all(|v| *v == 0.0));
        assert_eq!(
            (d.median_ratio, d.share_below_heldout_p05),
            (Some(0.0), 1.0)
        );
        assert!(d.heldout_summary.min > 0.0);
    }

    #[test]
    fn new_draws_from_the_population_look_like_held_out_patients() {
        let training = gaussian_points(40, 0.0, 3);
        let heldout = gaussian_points(40, 0.0, 4);
        let generated = gaussian_points(40, 0.0, 5);
        let d = dcr(
            &DistanceMatrix::between(&generated, &training, squared),
            &DistanceMatrix::between(&heldout, &training, squared),
        )
        .unwrap();
        // same law on both sides: the medians differ by sampling noise only
        let ratio = d.median_ratio.unwrap();
        assert!(ratio > 0.5 && ratio < 2.0, "{d:?}");
        assert!(d.share_below_heldout_p05 < 0.2, "{d:?}");
        // brute force: the first generated shape's nearest training distance
        let first = training
            .iter()
            .map(|t| squared(&generated[0], t))
            .fold(f64::INFINITY, f64::min);
        assert_eq!(d.generated[0], first);
    }

    #[test]
    fn mismatched_or_tiny_sets_say_why() {
        let a = gaussian_points(3, 0.0, 6);
        let b = gaussian_points(4, 0.0, 7);
        let m = DistanceMatrix::between(&a, &b, squared);
        let other = DistanceMatrix::between(&a, &a, squared);
        assert!(matches!(
            dcr(&m, &other),
            Err(ShapeMetricsError::Dimension { .. })
        ));
        let one = DistanceMatrix::between(&a[..1], &b, squared);
        assert!(matches!(
            dcr(&one, &m),
            Err(ShapeMetricsError::TooFew {
                needed: 2,
                got: 1,
                ..
            })
        ));
    }
}
