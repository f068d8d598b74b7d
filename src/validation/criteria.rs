//! Acceptance criteria, set before the run (ASME V&V 40, FDA 2023): each becomes one or
//! more checks that pass or fail on the computed figures, and the validation's verdict is
//! `pass` when every check passes, `fail` when one fails, `inconclusive` when none fails
//! but one could not be evaluated (its figure could not be computed).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::InputError;
use super::features::Feature;
use super::measures::FeatureComparison;
use super::shapes::ShapeLevel;

/// What a validation request may require, every field optional.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AcceptanceCriteria {
    /// Largest accepted 1-NNA (mean over subsets; 0.5 is ideal), in (0, 1].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nna_max: Option<f64>,
    /// Smallest accepted COV (mean over subsets of the reference's size), in [0, 1].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cov_min: Option<f64>,
    /// COV must reach the real-vs-real baseline's (the training shapes' own COV).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cov_at_least_baseline: Option<bool>,
    /// A non-inferiority margin for `cov_at_least_baseline`, in [0, 1]: COV may fall this
    /// far below the baseline (e.g. 0.05, one shape of a 20-shape reference). A cohort
    /// drawn from the population itself lands below the baseline about half the time, so
    /// a margin is what makes the check one an ideal sampler passes. Implies the check.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cov_baseline_margin: Option<f64>,
    /// Largest accepted MMD (common-scale squared distance), ≥ 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mmd_max: Option<f64>,
    /// Largest accepted relative difference of the pairwise-distance medians,
    /// |cohort / reference − 1| (e.g. 0.15), ≥ 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pairwise_median_tolerance: Option<f64>,
    /// Smallest accepted DCR median ratio (cohort over new patients; 1: no closer to the
    /// training patients than a new patient), ≥ 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dcr_ratio_min: Option<f64>,
    /// No near-copies of training shapes allowed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub no_near_copies: Option<bool>,
    /// Smallest accepted KS p-value of every compared feature (e.g. 0.05), in [0, 1].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ks_p_min: Option<f64>,
    /// Largest accepted SIMCor band p of every compared feature (share of the real
    /// density outside the bootstrap band), in [0, 0.5].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub band_p_max: Option<f64>,
    /// Largest accepted Wasserstein-1 distance, by feature, in its unit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wasserstein_max: Option<BTreeMap<String, f64>>,
    /// TOST equivalence margins (±, in the feature's unit, > 0) by feature: each must be
    /// shown equivalent at α = 0.05.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(example = json!({"annulus_mm": 1.0}))]
    pub tost_margin_mm: Option<BTreeMap<String, f64>>,
    /// Features the per-feature criteria (`ks_p_min`, `band_p_max`) apply to (default:
    /// every compared feature).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub features: Option<Vec<String>>,
}

/// Checked criteria.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Criteria {
    /// As given (the dossier records them).
    pub given: AcceptanceCriteria,
    /// TOST margins by feature.
    pub tost_margins: BTreeMap<Feature, f64>,
    /// Wasserstein limits by feature.
    pub wasserstein_max: BTreeMap<Feature, f64>,
    /// Features the per-feature criteria apply to (none: all compared).
    pub features: Option<Vec<Feature>>,
}

impl AcceptanceCriteria {
    /// Checks every value's range and every feature name, naming the field
    /// (`criteria.tost_margin_mm.D_lvot`, …).
    pub fn check(self) -> Result<Criteria, InputError> {
        let range = |name: &str, v: Option<f64>, lo: f64, hi: f64, open_lo: bool| match v {
            Some(x) if !(x.is_finite() && x <= hi && (x > lo || (!open_lo && x == lo))) => {
                let bracket = if open_lo { "(" } else { "[" };
                let msg = format!("must lie in {bracket}{lo}, {hi}], got {x}");
                Err(InputError::new(format!("criteria.{name}"), "range", msg))
            }
            _ => Ok(()),
        };
        range("nna_max", self.nna_max, 0.0, 1.0, true)?;
        range("cov_min", self.cov_min, 0.0, 1.0, false)?;
        range(
            "cov_baseline_margin",
            self.cov_baseline_margin,
            0.0,
            1.0,
            false,
        )?;
        if self.cov_baseline_margin.is_some() && self.cov_at_least_baseline == Some(false) {
            return Err(InputError::new(
                "criteria.cov_baseline_margin",
                "conflict",
                "a margin for the baseline check, which cov_at_least_baseline: false turns off",
            ));
        }
        range("mmd_max", self.mmd_max, 0.0, f64::MAX, false)?;
        range(
            "pairwise_median_tolerance",
            self.pairwise_median_tolerance,
            0.0,
            f64::MAX,
            false,
        )?;
        range("dcr_ratio_min", self.dcr_ratio_min, 0.0, f64::MAX, false)?;
        range("ks_p_min", self.ks_p_min, 0.0, 1.0, false)?;
        range("band_p_max", self.band_p_max, 0.0, 0.5, false)?;
        let tost_margins = feature_map("tost_margin_mm", self.tost_margin_mm.as_ref())?;
        let wasserstein_max = feature_map("wasserstein_max", self.wasserstein_max.as_ref())?;
        let features = match &self.features {
            None => None,
            Some(names) => Some(
                names
                    .iter()
                    .enumerate()
                    .map(|(i, n)| parse_feature(&format!("criteria.features[{i}]"), n))
                    .collect::<Result<Vec<_>, _>>()?,
            ),
        };
        Ok(Criteria {
            given: self,
            tost_margins,
            wasserstein_max,
            features,
        })
    }
}

fn parse_feature(field: &str, name: &str) -> Result<Feature, InputError> {
    Feature::parse(name).ok_or_else(|| {
        let msg = format!(
            "{name:?} is not a measurement; expected {}",
            Feature::names()
        );
        InputError::new(field, "unknown-measurement", msg)
    })
}

fn feature_map(
    name: &str,
    map: Option<&BTreeMap<String, f64>>,
) -> Result<BTreeMap<Feature, f64>, InputError> {
    let mut out = BTreeMap::new();
    for (key, &value) in map.into_iter().flatten() {
        let field = format!("criteria.{name}.{key}");
        let feature = parse_feature(&field, key)?;
        if !(value.is_finite() && value > 0.0) {
            let msg = format!("must be a finite number > 0, got {value}");
            return Err(InputError::new(field, "positive", msg));
        }
        out.insert(feature, value);
    }
    Ok(out)
}

/// One evaluated check.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Check {
    /// The criterion (`nna_max`, `ks_p_min`, …).
    pub criterion: String,
    /// The feature it concerns, for per-feature criteria.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub feature: Option<String>,
    /// The threshold, as a sentence (`≤ 0.55`).
    pub requirement: String,
    /// The computed figure, if it could be computed.
    pub value: Option<f64>,
    /// Whether it passed (null: could not be evaluated).
    pub passed: Option<bool>,
    /// Why it could not be evaluated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// The overall outcome.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Every check passed (or none was asked for).
    Pass,
    /// At least one check failed.
    Fail,
    /// None failed, but at least one could not be evaluated.
    Inconclusive,
}

impl Verdict {
    /// The verdict of `checks`.
    pub fn of(checks: &[Check]) -> Self {
        if checks.iter().any(|c| c.passed == Some(false)) {
            Self::Fail
        } else if checks.iter().any(|c| c.passed.is_none()) {
            Self::Inconclusive
        } else {
            Self::Pass
        }
    }
}

/// Evaluates `criteria` on the computed figures (`shapes` none: the reference has no
/// surfaces, or the shape level failed with the reason).
pub fn evaluate(
    criteria: &Criteria,
    shapes: Result<&ShapeLevel, &str>,
    features: &[FeatureComparison],
) -> Vec<Check> {
    let g = &criteria.given;
    let mut checks = Vec::new();
    let shape_figure = |get: &dyn Fn(&ShapeLevel) -> Result<f64, String>| match shapes {
        Ok(level) => get(level),
        Err(why) => Err(why.to_owned()),
    };
    let missing = |level: &ShapeLevel, name: &str| {
        level
            .not_computed
            .get(name)
            .cloned()
            .unwrap_or_else(|| format!("{name} was not computed"))
    };
    if let Some(max) = g.nna_max {
        let v = shape_figure(&|l| {
            l.nna
                .as_ref()
                .map(|n| n.mean)
                .ok_or_else(|| missing(l, "nna"))
        });
        checks.push(check("nna_max", None, format!("≤ {max}"), v, |x| {
            x <= max
        }));
    }
    if let Some(min) = g.cov_min {
        let v = shape_figure(&|l| {
            l.coverage
                .as_ref()
                .map(|c| c.cov_subsets.mean)
                .ok_or_else(|| missing(l, "coverage"))
        });
        checks.push(check("cov_min", None, format!("≥ {min}"), v, |x| {
            x >= min
        }));
    }
    if g.cov_at_least_baseline == Some(true) || g.cov_baseline_margin.is_some() {
        let margin = g.cov_baseline_margin.unwrap_or(0.0);
        let figures = shapes.map_err(str::to_owned).and_then(|l| {
            let base = l.baseline.as_ref().map(|b| b.coverage.cov_subsets.mean);
            let cov = l.coverage.as_ref().map(|c| c.cov_subsets.mean);
            Ok((
                cov.ok_or_else(|| missing(l, "coverage"))?,
                base.ok_or_else(|| missing(l, "baseline"))?,
            ))
        });
        let base = figures.as_ref().map_or(f64::INFINITY, |f| f.1);
        let requirement = if margin > 0.0 {
            format!("≥ the real-vs-real baseline's {base:.3} − {margin}")
        } else {
            format!("≥ the real-vs-real baseline's {base:.3}")
        };
        let v = figures.map(|f| f.0);
        checks.push(check("cov_at_least_baseline", None, requirement, v, |x| {
            x >= base - margin
        }));
    }
    if let Some(max) = g.mmd_max {
        let v = shape_figure(&|l| {
            l.coverage
                .as_ref()
                .map(|c| c.mmd_subsets.mean)
                .ok_or_else(|| missing(l, "coverage"))
        });
        checks.push(check("mmd_max", None, format!("≤ {max}"), v, |x| {
            x <= max
        }));
    }
    if let Some(tol) = g.pairwise_median_tolerance {
        let v = shape_figure(&|l| {
            l.pairwise
                .as_ref()
                .map(|p| p.median_ratio)
                .ok_or_else(|| missing(l, "pairwise"))
        });
        let requirement = format!("cohort/reference median within 1 ± {tol}");
        checks.push(check(
            "pairwise_median_tolerance",
            None,
            requirement,
            v,
            |r| (r - 1.0).abs() <= tol,
        ));
    }
    if let Some(min) = g.dcr_ratio_min {
        let v = shape_figure(&|l| {
            l.dcr
                .as_ref()
                .and_then(|d| d.dcr.median_ratio)
                .ok_or_else(|| missing(l, "dcr"))
        });
        checks.push(check("dcr_ratio_min", None, format!("≥ {min}"), v, |x| {
            x >= min
        }));
    }
    if g.no_near_copies == Some(true) {
        let v = shape_figure(&|l| {
            l.dcr
                .as_ref()
                .map(|d| d.near_copies as f64)
                .ok_or_else(|| missing(l, "dcr"))
        });
        checks.push(check(
            "no_near_copies",
            None,
            "0 near-copies".into(),
            v,
            |x| x == 0.0,
        ));
    }
    feature_checks(criteria, features, &mut checks);
    checks
}

fn feature_checks(criteria: &Criteria, features: &[FeatureComparison], checks: &mut Vec<Check>) {
    let g = &criteria.given;
    let applies = |f: Feature| {
        criteria
            .features
            .as_ref()
            .is_none_or(|list| list.contains(&f))
    };
    let find = |f: Feature| features.iter().find(|c| c.feature == f);
    let why = |c: Option<&FeatureComparison>, name: &str| match c {
        None => "the feature is not measured on both sides".to_owned(),
        Some(c) => c
            .not_computed
            .get(name)
            .cloned()
            .unwrap_or_else(|| format!("{name} was not computed")),
    };
    let listed: Vec<Feature> = match &criteria.features {
        Some(list) => list.clone(),
        None => features.iter().map(|c| c.feature).collect(),
    };
    for f in listed.iter().copied().filter(|&f| applies(f)) {
        let c = find(f);
        if let Some(min) = g.ks_p_min {
            let v = c
                .and_then(|c| c.ks.map(|k| k.p_value))
                .ok_or_else(|| why(c, "ks"));
            checks.push(check(
                "ks_p_min",
                Some(f),
                format!("KS p ≥ {min}"),
                v,
                |p| p >= min,
            ));
        }
        if let Some(max) = g.band_p_max {
            let v = c
                .and_then(|c| c.density_band.as_ref().map(|b| b.p_value))
                .ok_or_else(|| why(c, "density_band"));
            checks.push(check(
                "band_p_max",
                Some(f),
                format!("band p ≤ {max}"),
                v,
                |p| p <= max,
            ));
        }
    }
    for (&f, &max) in &criteria.wasserstein_max {
        let c = find(f);
        let v = c
            .and_then(|c| c.wasserstein)
            .ok_or_else(|| why(c, "wasserstein"));
        let requirement = format!("W₁ ≤ {max} {}", f.unit());
        checks.push(check("wasserstein_max", Some(f), requirement, v, |w| {
            w <= max
        }));
    }
    for (&f, &margin) in &criteria.tost_margins {
        let c = find(f);
        let v = c
            .and_then(|c| c.equivalence.as_ref().map(|e| e.test.p_value))
            .ok_or_else(|| why(c, "equivalence"));
        let requirement = format!("TOST p < 0.05 at ±{margin} {}", f.unit());
        checks.push(check("tost_margin_mm", Some(f), requirement, v, |p| {
            p < super::measures::TOST_ALPHA
        }));
    }
}

fn check(
    criterion: &str,
    feature: Option<Feature>,
    requirement: String,
    value: Result<f64, String>,
    passes: impl Fn(f64) -> bool,
) -> Check {
    let (value, note) = match value {
        Ok(v) => (Some(v), None),
        Err(why) => (None, Some(why)),
    };
    Check {
        criterion: criterion.to_owned(),
        feature: feature.map(|f| f.name().to_owned()),
        requirement,
        passed: value.map(passes),
        value,
        note,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn out_of_range_criteria_and_unknown_features_name_their_field() {
        let cases = [
            (
                AcceptanceCriteria {
                    nna_max: Some(0.0),
                    ..Default::default()
                },
                "criteria.nna_max",
                "range",
            ),
            (
                AcceptanceCriteria {
                    ks_p_min: Some(1.5),
                    ..Default::default()
                },
                "criteria.ks_p_min",
                "range",
            ),
            (
                AcceptanceCriteria {
                    cov_baseline_margin: Some(-0.01),
                    ..Default::default()
                },
                "criteria.cov_baseline_margin",
                "range",
            ),
            (
                AcceptanceCriteria {
                    cov_at_least_baseline: Some(false),
                    cov_baseline_margin: Some(0.05),
                    ..Default::default()
                },
                "criteria.cov_baseline_margin",
                "conflict",
            ),
            (
                AcceptanceCriteria {
                    band_p_max: Some(0.6),
                    ..Default::default()
                },
                "criteria.band_p_max",
                "range",
            ),
            (
                AcceptanceCriteria {
                    tost_margin_mm: Some([("D_lvot".to_owned(), 1.0)].into()),
                    ..Default::default()
                },
                "criteria.tost_margin_mm.D_lvot",
                "unknown-measurement",
            ),
            (
                AcceptanceCriteria {
                    tost_margin_mm: Some([("annulus_mm".to_owned(), 0.0)].into()),
                    ..Default::default()
                },
                "criteria.tost_margin_mm.annulus_mm",
                "positive",
            ),
            (
                AcceptanceCriteria {
                    features: Some(vec!["colour".into()]),
                    ..Default::default()
                },
                "criteria.features[0]",
                "unknown-measurement",
            ),
        ];
        for (c, field, rule) in cases {
            let err = c.clone().check().unwrap_err();
            assert_eq!((err.field.as_str(), err.rule), (field, rule), "{c:?}");
        }
        let ok = AcceptanceCriteria {
            cov_min: Some(0.0),
            tost_margin_mm: Some([("D_an".to_owned(), 1.0)].into()),
            ..Default::default()
        };
        let checked = ok.check().unwrap();
        assert_eq!(checked.tost_margins.len(), 1);
    }

    #[test]
    fn the_verdict_fails_on_any_failure_and_is_inconclusive_on_a_missing_figure() {
        let c = |passed| Check {
            criterion: "x".into(),
            feature: None,
            requirement: String::new(),
            value: None,
            passed,
            note: None,
        };
        assert_eq!(Verdict::of(&[]), Verdict::Pass);
        assert_eq!(
            Verdict::of(&[c(Some(true)), c(None)]),
            Verdict::Inconclusive
        );
        assert_eq!(Verdict::of(&[c(None), c(Some(false))]), Verdict::Fail);
        assert_eq!(Verdict::of(&[c(Some(true))]), Verdict::Pass);
    }

    #[test]
    fn a_shape_criterion_without_shapes_cannot_be_evaluated_and_says_why() {
        let criteria = AcceptanceCriteria {
            nna_max: Some(0.6),
            ..Default::default()
        }
        .check()
        .unwrap();
        let checks = evaluate(&criteria, Err("the reference is a measurements table"), &[]);
        assert_eq!(checks.len(), 1);
        assert_eq!(checks[0].passed, None);
        assert_eq!(
            checks[0].note.as_deref(),
            Some("the reference is a measurements table")
        );
    }
}
