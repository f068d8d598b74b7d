//! Conditioned cohorts: target ranges for anatomical measurements (mm), their feasibility
//! against a model's training shapes, and the bounded candidate search that meets them.
//!
//! - [`Targets`]: the request's ranges, checked on the way in;
//! - [`feasibility`]: the training shapes' measurements and what a mixture can reach;
//! - [`search`]: the candidate search, engine-agnostic behind [`search::CandidateSource`];
//! - [`refine`]: weight refinement on the simplex towards the targets.

pub mod feasibility;
pub mod refine;
pub mod search;

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

pub use crate::anatomy::measurement::Measurement;
use crate::anatomy::shape::ShapeAnatomy;

/// Candidates tried per shape when the request does not say.
pub const DEFAULT_MAX_CANDIDATES: u32 = 20;
/// Hard cap on candidates per shape (each costs one coarse extraction).
pub const MAX_CANDIDATES: u32 = 100;

/// An accepted interval in mm; either bound may be absent (not both).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TargetRange {
    /// Smallest accepted value (mm, ≥ 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// Largest accepted value (mm, ≥ min).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
}

impl TargetRange {
    /// How far `value` lies outside the range (0 inside).
    pub fn miss(&self, value: f64) -> f64 {
        let below = self.min.map_or(0.0, |m| (m - value).max(0.0));
        let above = self.max.map_or(0.0, |m| (value - m).max(0.0));
        below + above
    }

    /// Whether `value` lies inside.
    pub fn contains(&self, value: f64) -> bool {
        self.miss(value) == 0.0
    }
}

impl std::fmt::Display for TargetRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.min, self.max) {
            (Some(lo), Some(hi)) => write!(f, "[{lo}, {hi}] mm"),
            (Some(lo), None) => write!(f, "≥ {lo} mm"),
            (None, Some(hi)) => write!(f, "≤ {hi} mm"),
            (None, None) => write!(f, "any value"),
        }
    }
}

/// A broken rule of a target list; [`Self::field`] and [`Self::rule`] name it for API errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TargetError {
    /// No measurement named.
    #[error("must name at least one measurement ({})", Measurement::names())]
    Empty,
    /// A name that is not a measurement.
    #[error(
        "{name:?} is not a measurement; expected one of {}",
        Measurement::names()
    )]
    Unknown {
        /// The name given.
        name: String,
    },
    /// Neither bound given.
    #[error("{name} needs a min, a max or both")]
    NoBound {
        /// The measurement.
        name: &'static str,
    },
    /// A bound that is not a finite number.
    #[error("{name}.{bound} must be a finite number, got {value}")]
    NonFinite {
        /// The measurement.
        name: &'static str,
        /// `min` or `max`.
        bound: &'static str,
        /// The value.
        value: f64,
    },
    /// A negative bound (every measurement is a length).
    #[error("{name}.{bound} must be ≥ 0 mm, got {value}")]
    Negative {
        /// The measurement.
        name: &'static str,
        /// `min` or `max`.
        bound: &'static str,
        /// The value.
        value: f64,
    },
    /// `min` above `max`.
    #[error("{name}: min {min} must not exceed max {max}")]
    Inverted {
        /// The measurement.
        name: &'static str,
        /// Lower bound.
        min: f64,
        /// Upper bound.
        max: f64,
    },
}

impl TargetError {
    /// The offending request field, e.g. `targets.annulus_mm.min`.
    pub fn field(&self) -> String {
        match self {
            Self::Empty => "targets".into(),
            Self::Unknown { name } => format!("targets.{name}"),
            Self::NoBound { name } | Self::Inverted { name, .. } => format!("targets.{name}"),
            Self::NonFinite { name, bound, .. } | Self::Negative { name, bound, .. } => {
                format!("targets.{name}.{bound}")
            }
        }
    }

    /// The short rule name.
    pub fn rule(&self) -> &'static str {
        match self {
            Self::Empty => "non-empty",
            Self::Unknown { .. } => "unknown-measurement",
            Self::NoBound { .. } => "bound-required",
            Self::NonFinite { .. } => "finite",
            Self::Negative { .. } => "non-negative",
            Self::Inverted { .. } => "min-le-max",
        }
    }
}

/// Parses a command-line target `NAME=MIN:MAX` (either bound may be empty, e.g.
/// `length_mm=:90`); the name and bounds are validated by [`Targets::parse`].
pub fn parse_target_arg(text: &str) -> Result<(String, TargetRange), String> {
    let (name, range) = text
        .split_once('=')
        .ok_or_else(|| format!("{text:?} is not NAME=MIN:MAX"))?;
    let (lo, hi) = range
        .split_once(':')
        .ok_or_else(|| format!("{range:?} is not MIN:MAX (either may be empty)"))?;
    let bound = |s: &str, which: &str| -> Result<Option<f64>, String> {
        match s.trim() {
            "" => Ok(None),
            t => t
                .parse::<f64>()
                .map(Some)
                .map_err(|e| format!("{name} {which} {t:?} is not a number: {e}")),
        }
    };
    let range = TargetRange {
        min: bound(lo, "min")?,
        max: bound(hi, "max")?,
    };
    Ok((name.trim().to_string(), range))
}

/// Validated targets, one range per measurement, in [`Measurement`] order.
#[derive(Debug, Clone, PartialEq)]
pub struct Targets(Vec<(Measurement, TargetRange)>);

impl Targets {
    /// Validates ranges keyed by measurement name.
    pub fn parse(ranges: &BTreeMap<String, TargetRange>) -> Result<Self, TargetError> {
        if ranges.is_empty() {
            return Err(TargetError::Empty);
        }
        let mut out = Vec::with_capacity(ranges.len());
        for (key, range) in ranges {
            let measurement = Measurement::parse(key)
                .ok_or_else(|| TargetError::Unknown { name: key.clone() })?;
            let name = measurement.name();
            if range.min.is_none() && range.max.is_none() {
                return Err(TargetError::NoBound { name });
            }
            for (bound, value) in [("min", range.min), ("max", range.max)] {
                let Some(value) = value else { continue };
                if !value.is_finite() {
                    return Err(TargetError::NonFinite { name, bound, value });
                }
                if value < 0.0 {
                    return Err(TargetError::Negative { name, bound, value });
                }
            }
            if let (Some(min), Some(max)) = (range.min, range.max)
                && min > max
            {
                return Err(TargetError::Inverted { name, min, max });
            }
            out.push((measurement, *range));
        }
        out.sort_by_key(|(m, _)| *m);
        Ok(Self(out))
    }

    /// The ranges keyed by name (what is stored and shown).
    pub fn to_map(&self) -> BTreeMap<String, TargetRange> {
        self.0
            .iter()
            .map(|(m, r)| (m.name().to_string(), *r))
            .collect()
    }

    /// The targeted measurements with their ranges.
    pub fn iter(&self) -> impl Iterator<Item = (Measurement, TargetRange)> + '_ {
        self.0.iter().copied()
    }

    /// Total distance in mm of a shape's measurements outside their ranges: 0 when every
    /// target is met, infinite when a targeted measurement is missing (or the shape could
    /// not be measured).
    pub fn miss(&self, anatomy: Option<&ShapeAnatomy>) -> f64 {
        let Some(a) = anatomy else {
            return f64::INFINITY;
        };
        self.0
            .iter()
            .map(|(m, r)| m.value(a).map_or(f64::INFINITY, |v| r.miss(v)))
            .sum()
    }
}

#[cfg(test)]
pub(crate) mod test_support {
    //! Measured shapes and target lists for the tests of this module's parts.
    use super::*;

    pub(crate) fn anatomy(annulus: Option<f64>, length: f64) -> ShapeAnatomy {
        ShapeAnatomy {
            method: if annulus.is_some() { "root" } else { "vessel" }.into(),
            annulus_mm: annulus,
            sinus_mm: annulus.map(|a| a * 1.3),
            stj_mm: annulus.map(|a| a * 1.1),
            sinus_height_mm: annulus.map(|a| a * 0.8),
            ascending_mm: annulus.map(|a| a * 1.2),
            length_mm: length,
            max_diameter_mm: annulus.map_or(20.0, |a| a * 1.3),
            root_error: None,
            measurement_version: crate::anatomy::shape::MEASUREMENT_VERSION,
        }
    }

    /// A measurement name with its bounds.
    pub(crate) type Bounds<'a> = (&'a str, Option<f64>, Option<f64>);

    pub(crate) fn targets(pairs: &[Bounds]) -> Result<Targets, TargetError> {
        let map = pairs
            .iter()
            .map(|&(n, min, max)| (n.to_string(), TargetRange { min, max }))
            .collect();
        Targets::parse(&map)
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::{Bounds, anatomy, targets};
    use super::*;

    #[test]
    fn bad_targets_name_the_field_and_rule() {
        let cases: [(&[Bounds], &str, &str); 6] = [
            (&[], "targets", "non-empty"),
            (
                &[("aorta_mm", Some(1.0), None)],
                "targets.aorta_mm",
                "unknown-measurement",
            ),
            (
                &[("annulus_mm", None, None)],
                "targets.annulus_mm",
                "bound-required",
            ),
            (
                &[("stj_mm", Some(-1.0), Some(3.0))],
                "targets.stj_mm.min",
                "non-negative",
            ),
            (
                &[("sinus_mm", Some(1.0), Some(f64::NAN))],
                "targets.sinus_mm.max",
                "finite",
            ),
            (
                &[("length_mm", Some(30.0), Some(20.0))],
                "targets.length_mm",
                "min-le-max",
            ),
        ];
        for (pairs, field, rule) in cases {
            let err = targets(pairs).unwrap_err();
            assert_eq!((err.field().as_str(), err.rule()), (field, rule), "{err}");
        }
        let ok = targets(&[
            ("length_mm", Some(20.0), None),
            ("annulus_mm", Some(23.0), Some(27.0)),
        ])
        .unwrap();
        let names: Vec<_> = ok.iter().map(|(m, _)| m.name()).collect();
        assert_eq!(names, ["annulus_mm", "length_mm"]);
        assert_eq!(Targets::parse(&ok.to_map()).unwrap(), ok);
    }

    #[test]
    fn command_line_targets_parse_with_open_bounds() {
        let r = |min, max| TargetRange { min, max };
        assert_eq!(
            parse_target_arg("annulus_mm=23:27"),
            Ok(("annulus_mm".into(), r(Some(23.0), Some(27.0))))
        );
        assert_eq!(
            parse_target_arg("length_mm=:90.5"),
            Ok(("length_mm".into(), r(None, Some(90.5))))
        );
        assert_eq!(
            parse_target_arg("stj_mm=20:"),
            Ok(("stj_mm".into(), r(Some(20.0), None)))
        );
        for bad in ["annulus_mm", "annulus_mm=23", "annulus_mm=a:27"] {
            assert!(parse_target_arg(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_miss_is_the_distance_outside_and_infinite_when_unmeasured() {
        let t = targets(&[
            ("annulus_mm", Some(23.0), Some(27.0)),
            ("length_mm", None, Some(80.0)),
        ])
        .unwrap();
        assert_eq!(t.miss(Some(&anatomy(Some(25.0), 70.0))), 0.0);
        assert_eq!(t.miss(Some(&anatomy(Some(21.5), 82.0))), 3.5);
        assert_eq!(t.miss(Some(&anatomy(None, 70.0))), f64::INFINITY);
        assert_eq!(t.miss(None), f64::INFINITY);
    }
}
