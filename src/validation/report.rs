//! The validation report: every figure of both levels, the acceptance checks and the
//! verdict, under a credibility dossier (FDA 2023 guidance, ASME V&V 40, Pathmanathan et
//! al. 2024) naming the context of use, the question of interest, the model and its hash,
//! the software version, the cohort's seed and request, the reference and the criteria as
//! they were set before the run. Written as JSON (this type) and as HTML
//! ([`crate::report::validation`]).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::criteria::{Check, Criteria, Verdict, evaluate};
use super::features::Feature;
use super::measures::{
    FeatureComparison, JointComparison, MeasureSettings, compare_feature, compare_jointly,
};
use super::population::Population;
use super::shapes::{Progress, ShapeInputs, ShapeLevel, ShapeSettings, compare_shapes};

/// Value of the report's `format` field.
pub const REPORT_FORMAT: &str = "aortagen-validation";

/// Who asks what, and of which cohort, model and reference.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Dossier {
    /// The context of use: the role and scope of the virtual cohort in the trial.
    pub context_of_use: Option<String>,
    /// The question of interest the cohort helps answer.
    pub question_of_interest: Option<String>,
    /// The model's id.
    pub model_id: String,
    /// SHA-256 of the model's weights, when known.
    pub model_sha256: Option<String>,
    /// aortagen version that computed the report.
    pub software_version: String,
    /// The cohort: its label, id, seed and request as stored.
    pub cohort: Subject,
    /// The reference population.
    pub reference: Subject,
    /// The acceptance criteria as given with the request (set before the run).
    pub criteria: super::criteria::AcceptanceCriteria,
    /// When the report was computed (UTC, RFC 3339).
    pub computed_at: String,
}

/// A compared population as the dossier describes it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Subject {
    /// Its label.
    pub label: String,
    /// Its id in the service, if it has one.
    pub id: Option<i64>,
    /// Its kind (`cohort`, `training`, `heldout`, `meshes`, `measurements`, `directory`).
    pub kind: String,
    /// Its shapes.
    pub shapes: usize,
    /// The cohort's seed.
    pub seed: Option<u64>,
    /// The cohort's request, or how the reference was given.
    #[schema(value_type = Object)]
    pub details: serde_json::Value,
    /// SHA-256 of its data (reference meshes or table), when known.
    pub sha256: Option<String>,
}

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ValidationReport {
    /// Always [`REPORT_FORMAT`].
    pub format: String,
    /// Layout version (1).
    pub format_version: u32,
    /// The credibility dossier.
    pub dossier: Dossier,
    /// The shape level (absent when the reference has no surfaces; see `not_computed`).
    pub shapes: Option<ShapeLevel>,
    /// The measurement level, one entry per feature measured on both sides.
    pub features: Vec<FeatureComparison>,
    /// The joint comparison.
    pub joint: JointComparison,
    /// Features not compared, with the reason.
    pub not_compared: BTreeMap<String, String>,
    /// The acceptance checks.
    pub checks: Vec<Check>,
    /// pass, fail or inconclusive.
    pub verdict: Verdict,
    /// Why a part is missing (`shapes`).
    pub not_computed: BTreeMap<String, String>,
}

/// Everything a validation compares.
pub struct ValidationInput<'a> {
    /// Populations and the DCR newcomers.
    pub shapes: ShapeInputs<'a>,
    /// Shape-level settings.
    pub shape_settings: ShapeSettings,
    /// Measurement-level settings.
    pub measure_settings: MeasureSettings,
    /// Acceptance criteria.
    pub criteria: &'a Criteria,
    /// Features the reference does not compare, with the reason (a table's ignored columns).
    pub ignored: Vec<(String, String)>,
    /// The dossier to fill in.
    pub dossier: Dossier,
}

/// Runs a validation; `progress` counts the Chamfer distances done (see
/// [`ShapeInputs::pairs`]) and may stop them (the shape level is then not computed).
pub fn validate(input: ValidationInput<'_>, progress: Progress<'_>) -> ValidationReport {
    let (cohort, reference) = (input.shapes.cohort, input.shapes.reference);
    let mut not_computed = BTreeMap::new();
    let shapes = compare_shapes(&input.shapes, &input.shape_settings, progress);
    let (compared, mut not_compared) = compared_features(cohort, reference);
    for (column, why) in input.ignored {
        not_compared.insert(column, why);
    }
    let features: Vec<FeatureComparison> = compared
        .iter()
        .map(|&f| compare_feature(f, cohort, reference, &input.measure_settings))
        .collect();
    let joint = compare_jointly(&compared, cohort, reference);
    let checks = evaluate(
        input.criteria,
        shapes.as_ref().map_err(String::as_str),
        &features,
    );
    let shapes = shapes
        .map_err(|e| not_computed.insert("shapes".to_owned(), e))
        .ok();
    ValidationReport {
        format: REPORT_FORMAT.into(),
        format_version: 1,
        dossier: input.dossier,
        shapes,
        verdict: Verdict::of(&checks),
        features,
        joint,
        not_compared,
        checks,
        not_computed,
    }
}

/// The current time as UTC RFC 3339 with seconds (`2026-12-04T10:30:00Z`).
pub fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    utc_rfc3339(secs)
}

/// `secs` after the Unix epoch as UTC RFC 3339 (the civil-from-days algorithm of Howard
/// Hinnant's `chrono`-compatible date library).
pub fn utc_rfc3339(secs: u64) -> String {
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// The features measured on at least one shape of each side, and why the others are not.
fn compared_features(
    cohort: &Population,
    reference: &Population,
) -> (Vec<Feature>, BTreeMap<String, String>) {
    let mut compared = Vec::new();
    let mut skipped = BTreeMap::new();
    for f in Feature::ALL {
        let (c, r) = (cohort.values(f).len(), reference.values(f).len());
        match (c, r) {
            (0, 0) => {}
            (_, 0) => {
                drop(skipped.insert(f.name().into(), "the reference does not have it".into()))
            }
            (0, _) => drop(skipped.insert(
                f.name().into(),
                "no cohort shape could be measured for it".into(),
            )),
            _ => compared.push(f),
        }
    }
    (compared, skipped)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_are_civil_utc_dates() {
        assert_eq!(utc_rfc3339(0), "1970-01-01T00:00:00Z");
        // 2000-02-29 (a leap day of a century leap year) 12:34:56.
        assert_eq!(utc_rfc3339(951_827_696), "2000-02-29T12:34:56Z");
        // 2026-12-31 23:59:59.
        assert_eq!(utc_rfc3339(1_798_761_599), "2026-12-31T23:59:59Z");
    }
}
