//! What a convex mixture of a model's training shapes can reach: each training shape meshed
//! alone and measured once per model, and the feasibility of targets against that.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use serde::{Deserialize, Serialize};

use super::{TargetRange, Targets};
use crate::anatomy::measurement::Measurement;
use crate::anatomy::shape::{
    MEASUREMENT_VERSION, ShapeAnatomy, first_measurement_version, measure_shape,
};
use crate::engine::{Engine, GeneratedShape, ShapeSpec};

/// Grid resolution of the coarse extraction candidates are screened with and the training
/// shapes measured at.
pub const SCREEN_RESOLUTION: usize = 64;
/// A target is feasible when it overlaps the training shapes' range of that measurement
/// widened on both sides by this fraction of the largest training value: convex mixtures
/// mostly interpolate the measurements, but the decoder and the mixed transform can move a
/// little past the extremes.
pub const FEASIBILITY_MARGIN: f64 = 0.05;

/// The measurements of a model's training shapes, each meshed alone (weight 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingAnatomy {
    /// Grid resolution they were meshed at.
    pub resolution: usize,
    /// The measurement method's version ([`MEASUREMENT_VERSION`]); 1 when absent (stored
    /// before the method had versions). Measurements of another version are taken again.
    #[serde(default = "first_measurement_version")]
    pub measurement_version: u32,
    /// One entry per training shape; null where the shape could not be measured.
    pub shapes: Vec<Option<ShapeAnatomy>>,
}

impl TrainingAnatomy {
    /// Whether these values were measured by today's method.
    pub fn is_current(&self) -> bool {
        self.measurement_version == MEASUREMENT_VERSION
    }
}

/// Meshes and measures each of the `count` training shapes of the model in `model_dir` at
/// [`SCREEN_RESOLUTION`]. Blocking; stops with an error once `cancel` is set.
pub fn measure_training_shapes(
    engine: &dyn Engine,
    model_dir: &Path,
    count: usize,
    cancel: &AtomicBool,
) -> anyhow::Result<TrainingAnatomy> {
    let shapes = (0..count)
        .map(|index| {
            anyhow::ensure!(!cancel.load(Ordering::Relaxed), "cancelled");
            let spec = ShapeSpec::single(index, SCREEN_RESOLUTION);
            let shape = engine
                .generate_shape(model_dir, &spec, cancel)
                .map_err(|e| e.context(format!("training shape {index}")))?;
            Ok(measure_mm(&shape).ok())
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(TrainingAnatomy {
        resolution: SCREEN_RESOLUTION,
        measurement_version: MEASUREMENT_VERSION,
        shapes,
    })
}

/// Measures a generated shape in mm; the error says why it could not be measured.
pub fn measure_mm(shape: &GeneratedShape) -> Result<ShapeAnatomy, String> {
    let mesh_mm = shape.transform.mesh_to_mesh_units(&shape.mesh_unit);
    measure_shape(&mesh_mm).map_err(|e| e.to_string())
}

/// The range of each measurement over a model's training shapes (`None`: measured on none).
pub fn training_ranges(training: &[Option<ShapeAnatomy>], m: Measurement) -> Option<(f64, f64)> {
    training
        .iter()
        .flatten()
        .filter_map(|a| m.value(a))
        .fold(None, |acc, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((f64::min(lo, v), f64::max(hi, v))),
        })
}

/// A target no convex mixture of the training shapes can plausibly reach.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Infeasible {
    /// The measurement was found on no training shape.
    #[error("{name} was measured on none of the model's training shapes, so it cannot be targeted")]
    NotMeasured {
        /// The measurement.
        name: &'static str,
    },
    /// The target misses the achievable range.
    #[error(
        "{name} target {target} lies outside the achievable range [{lo:.2}, {hi:.2}] mm \
         (the training shapes span [{train_lo:.2}, {train_hi:.2}] mm, widened by 5 % of the largest)"
    )]
    OutOfRange {
        /// The measurement.
        name: &'static str,
        /// The requested range.
        target: TargetRange,
        /// Achievable lower bound.
        lo: f64,
        /// Achievable upper bound.
        hi: f64,
        /// Smallest training value.
        train_lo: f64,
        /// Largest training value.
        train_hi: f64,
    },
}

impl Infeasible {
    /// The request field it is about (`targets.<name>`).
    pub fn field(&self) -> String {
        match self {
            Self::NotMeasured { name } | Self::OutOfRange { name, .. } => {
                format!("targets.{name}")
            }
        }
    }
}

/// Checks every target against the training shapes' measurements ([`FEASIBILITY_MARGIN`]).
pub fn check_feasible(
    targets: &Targets,
    training: &[Option<ShapeAnatomy>],
) -> Result<(), Infeasible> {
    for (m, target) in targets.iter() {
        let name = m.name();
        let (train_lo, train_hi) =
            training_ranges(training, m).ok_or(Infeasible::NotMeasured { name })?;
        let margin = FEASIBILITY_MARGIN * train_hi.abs();
        let (lo, hi) = (train_lo - margin, train_hi + margin);
        let below = target.max.is_some_and(|max| max < lo);
        let above = target.min.is_some_and(|min| min > hi);
        if below || above {
            return Err(Infeasible::OutOfRange {
                name,
                target,
                lo,
                hi,
                train_lo,
                train_hi,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::test_support::anatomy;
    use super::super::test_support::targets;
    use super::*;

    #[test]
    fn feasibility_uses_the_training_range_widened_by_the_margin() {
        let training = vec![
            Some(anatomy(Some(20.0), 60.0)),
            None,
            Some(anatomy(Some(30.0), 70.0)),
            Some(anatomy(None, 90.0)),
        ];
        assert_eq!(
            training_ranges(&training, Measurement::Annulus),
            Some((20.0, 30.0))
        );
        // Margin: 5 % of 30 = 1.5 mm → achievable [18.5, 31.5].
        for (min, max, ok) in [
            (Some(23.0), Some(27.0), true),
            (Some(31.0), Some(40.0), true),
            (Some(32.0), None, false),
            (None, Some(18.0), false),
            (Some(10.0), Some(19.0), true),
        ] {
            let t = targets(&[("annulus_mm", min, max)]).unwrap();
            let result = check_feasible(&t, &training);
            assert_eq!(result.is_ok(), ok, "{min:?}..{max:?}: {result:?}");
            if let Err(e) = result {
                assert_eq!(e.field(), "targets.annulus_mm");
                assert!(e.to_string().contains("[18.50, 31.50]"), "{e}");
            }
        }
        let vessels = vec![Some(anatomy(None, 60.0)), Some(anatomy(None, 70.0))];
        let t = targets(&[("annulus_mm", Some(23.0), Some(27.0))]).unwrap();
        assert!(matches!(
            check_feasible(&t, &vessels),
            Err(Infeasible::NotMeasured { name: "annulus_mm" })
        ));
    }
}
