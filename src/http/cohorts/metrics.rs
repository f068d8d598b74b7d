//! `GET /v1/cohorts/{id}/metrics`: pairwise Chamfer distances among a cohort's shapes
//! (squared distances in unit-ball coordinates), as summary JSON or CSV.

use std::fmt::Write as _;

use axum::Json;
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};

use crate::anatomy::measurement::Measurement;
use crate::anatomy::shape::ShapeAnatomy;
use crate::cohort::targets::TargetRange;
use crate::db;
use crate::http::AppState;
use crate::http::error::{ApiError, Problem, Result};
use crate::http::extractors::{ApiQuery, parse_id};
use crate::http::rendering::render_off_executor;
use crate::jobs::stats::{PairDistances, PairwiseSummary, ValueSummary, summarize_values};

/// The metrics endpoint's formats, the default first.
pub const METRICS_FORMATS: [&str; 2] = ["json", "csv"];

/// Largest cohort whose matrix is served (its JSON grows as the square of the shapes).
const MATRIX_MAX_SHAPES: usize = 2_000;

/// Options of the metrics endpoint.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct MetricsQuery {
    /// `json` (default) or `csv`.
    pub format: Option<String>,
    /// Include the full matrix (JSON) or return it instead of the pair list (CSV); for a
    /// sampled cohort, pairs outside the sample are null (JSON) or empty (CSV). Served up to
    /// 2 000 shapes.
    pub matrix: Option<bool>,
}

/// Pairwise metrics of a cohort.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct CohortMetrics {
    /// Cohort id.
    pub cohort_id: i64,
    /// What the numbers are.
    pub measure: &'static str,
    /// Shape ids in matrix order.
    pub shape_ids: Vec<i64>,
    /// Statistics over distinct pairs (null for a single shape): every pair up to 100
    /// shapes, a uniform random sample of 4 950 pairs beyond (`sampled`, with confidence
    /// intervals).
    pub summary: Option<PairwiseSummary>,
    /// The symmetric matrix, when `matrix=true`; null where a pair is outside the sample.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub matrix: Option<Vec<Vec<Option<f64>>>>,
    /// When it was computed.
    pub computed_at: String,
    /// Distances of the shapes to their nearest training shapes.
    pub novelty: NoveltyMetrics,
    /// Anatomical measurements over the shapes (mm).
    pub anatomy: AnatomyMetrics,
}

/// Per-measurement statistics over a cohort's measured shapes, in mm; a summary is null
/// when no shape has that measurement (the root landmarks need a root-shaped surface).
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct AnatomyMetrics {
    /// Shapes measured (as a root or a vessel).
    pub measured: i64,
    /// Shapes measured with the aortic-root landmarks.
    pub roots: i64,
    /// Shapes that could not be measured.
    pub failed: i64,
    /// Annulus diameter (mean of major and minor).
    pub annulus_mm: Option<ValueSummary>,
    /// Sinus of Valsalva diameter.
    pub sinus_mm: Option<ValueSummary>,
    /// Sinotubular junction diameter.
    pub stj_mm: Option<ValueSummary>,
    /// Sinus height.
    pub sinus_height_mm: Option<ValueSummary>,
    /// Centreline length.
    pub length_mm: Option<ValueSummary>,
    /// Each target of a conditioned cohort with the share of shapes inside it (empty
    /// without targets).
    pub targets: Vec<TargetMetrics>,
    /// Candidates drawn over the shapes (targeted cohorts; 0 otherwise).
    pub candidates_total: i64,
}

/// How a cohort's shapes sit against one target range.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct TargetMetrics {
    /// Measurement name (e.g. `annulus_mm`).
    pub measurement: String,
    /// The target range (mm).
    pub target: TargetRange,
    /// Shapes with this measurement.
    pub measured: i64,
    /// Of those, shapes inside the range.
    pub inside: i64,
    /// `inside` over all the cohort's shapes (a shape without the measurement is outside).
    pub fraction_inside: f64,
    /// Achieved distribution of the measurement (null when no shape has it).
    pub achieved: Option<ValueSummary>,
}

/// Novelty of a cohort's shapes against the model's training shapes.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct NoveltyMetrics {
    /// What the numbers are.
    pub measure: &'static str,
    /// The cohort's minimum, if it set one.
    pub min_novelty: Option<f64>,
    /// Statistics over the shapes' distances (null without shapes).
    pub summary: Option<ValueSummary>,
    /// Draws rejected over all shapes.
    pub redraws_total: i64,
    /// Shapes kept although no draw reached `min_novelty`.
    pub not_met: i64,
    /// How many shapes have each training shape as their nearest (index → count).
    pub nearest_training_counts: Vec<i64>,
}

const NOVELTY_MEASURE: &str = "Chamfer distance to the nearest training shape (the model's reconstruction of its latent), unit-ball coordinates";

const MEASURE: &str = "Chamfer distance (sum of both mean squared nearest-neighbour distances), unit-ball coordinates";

/// Pairwise Chamfer distances among the cohort's shapes, computed after its meshes.
#[utoipa::path(get, path = "/v1/cohorts/{id}/metrics", tag = "cohorts",
    params(("id" = i64, Path, description = "Cohort id"), MetricsQuery),
    responses((status = 200, description = "JSON, or CSV (`text/csv`) with `format=csv`",
               content((CohortMetrics = "application/json"), ("text/csv"))),
              (status = 400, body = Problem, content_type = "application/problem+json"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Not computed yet")))]
pub(super) async fn get_cohort_metrics(
    State(state): State<AppState>,
    Path(id): Path<String>,
    ApiQuery(q): ApiQuery<MetricsQuery>,
) -> Result<Response> {
    let format = q.format.as_deref().unwrap_or(METRICS_FORMATS[0]);
    if !METRICS_FORMATS.contains(&format) {
        let message = format!(
            "format must be {}, got {format:?}",
            METRICS_FORMATS.join(" or ")
        );
        return Err(ApiError::BadRequest {
            field: Some("format".into()),
            message,
        });
    }
    let csv = format == "csv";
    let cohort = super::load(&state, parse_id("cohort", &id)?, &id).await?;
    let Some(row) = db::cohort_metrics::get(&state.pool, cohort.cohort_id).await? else {
        return Err(ApiError::Conflict(format!(
            "cohort {id} has no metrics yet (status {}); they are computed after all shapes",
            cohort.status
        )));
    };
    let shape_ids = db::shapes::cohort_shape_ids(&state.pool, cohort.cohort_id).await?;
    let science = db::shapes::cohort_science(&state.pool, cohort.cohort_id).await?;
    let training_shapes = match db::models::get(&state.pool, &cohort.model_id).await? {
        Some(model) => model.info().map_or(0, |i| i.training_shape_count()),
        None => 0,
    };
    let with_matrix = q.matrix.unwrap_or(false);
    if with_matrix && shape_ids.len() > MATRIX_MAX_SHAPES {
        return Err(ApiError::BadRequest {
            field: Some("matrix".into()),
            message: format!(
                "the matrix is served for cohorts of at most {MATRIX_MAX_SHAPES} shapes, this one \
                 has {}; the pair list (without matrix=true) holds every computed pair",
                shape_ids.len()
            ),
        });
    }
    // The distances can be n × n: parsed and written out off the executor.
    render_off_executor(move || {
        let distances: PairDistances =
            serde_json::from_str(&row.matrix).map_err(anyhow::Error::from)?;
        let summary = PairwiseSummary::from_stored(&row.summary).map_err(anyhow::Error::from)?;
        if csv {
            let body = if with_matrix {
                matrix_csv(&shape_ids, &distances.matrix())
            } else {
                pairs_csv(&shape_ids, &distances.pairs())
            };
            return Ok(([(header::CONTENT_TYPE, "text/csv; charset=utf-8")], body).into_response());
        }
        Ok(Json(CohortMetrics {
            cohort_id: cohort.cohort_id,
            measure: MEASURE,
            shape_ids,
            summary,
            matrix: with_matrix.then(|| distances.matrix()),
            computed_at: row.created_at,
            novelty: novelty_metrics(&cohort, &science, training_shapes),
            anatomy: anatomy_metrics(&science, cohort.targets.as_ref().map(|t| &t.0)),
        })
        .into_response())
    })
    .await
}

fn novelty_metrics(
    cohort: &db::cohorts::CohortRow,
    shapes: &[db::shapes::ScienceRow],
    training_shapes: usize,
) -> NoveltyMetrics {
    let mut counts = vec![0; training_shapes];
    for i in shapes.iter().filter_map(|s| s.nearest_training_index) {
        let i = i.max(0) as usize;
        if counts.len() <= i {
            counts.resize(i + 1, 0);
        }
        counts[i] += 1;
    }
    NoveltyMetrics {
        measure: NOVELTY_MEASURE,
        min_novelty: cohort.min_novelty,
        summary: summarize_values(shapes.iter().filter_map(|s| s.novelty_cd).collect()),
        redraws_total: shapes.iter().map(|s| s.redraws).sum(),
        not_met: shapes
            .iter()
            .filter(|s| s.novelty_met.is_some_and(|m| !m.0))
            .count() as i64,
        nearest_training_counts: counts,
    }
}

fn anatomy_metrics(
    shapes: &[db::shapes::ScienceRow],
    targets: Option<&std::collections::BTreeMap<String, TargetRange>>,
) -> AnatomyMetrics {
    let measured: Vec<&ShapeAnatomy> = shapes
        .iter()
        .filter_map(|s| s.anatomy.as_ref().map(|a| &a.0))
        .collect();
    let targets = targets
        .into_iter()
        .flatten()
        .map(|(name, target)| (name.clone(), *target))
        .filter_map(|(name, target)| {
            let m = Measurement::parse(&name)?;
            let values: Vec<f64> = measured.iter().filter_map(|a| m.value(a)).collect();
            let inside = values.iter().filter(|&&v| target.contains(v)).count() as i64;
            Some(TargetMetrics {
                measurement: name,
                target,
                measured: values.len() as i64,
                inside,
                fraction_inside: match shapes.len() {
                    0 => 0.0,
                    n => inside as f64 / n as f64,
                },
                achieved: summarize_values(values),
            })
        })
        .collect();
    let summary = |f: fn(&ShapeAnatomy) -> Option<f64>| {
        summarize_values(measured.iter().copied().filter_map(f).collect())
    };
    AnatomyMetrics {
        measured: measured.len() as i64,
        roots: measured.iter().filter(|a| a.method == "root").count() as i64,
        failed: (shapes.len() - measured.len()) as i64,
        annulus_mm: summary(|a| a.annulus_mm),
        sinus_mm: summary(|a| a.sinus_mm),
        stj_mm: summary(|a| a.stj_mm),
        sinus_height_mm: summary(|a| a.sinus_height_mm),
        length_mm: summary(|a| Some(a.length_mm)),
        targets,
        candidates_total: shapes.iter().filter_map(|s| s.candidates).sum(),
    }
}

fn pairs_csv(ids: &[i64], pairs: &[(u32, u32, f64)]) -> String {
    let mut out = String::from("shape_a,shape_b,chamfer\n");
    for &(i, j, d) in pairs {
        let _ = writeln!(out, "{},{},{d}", ids[i as usize], ids[j as usize]);
    }
    out
}

fn matrix_csv(ids: &[i64], m: &[Vec<Option<f64>>]) -> String {
    let mut out = String::from("shape");
    for id in ids {
        let _ = write!(out, ",{id}");
    }
    out.push('\n');
    for (id, row) in ids.iter().zip(m) {
        let _ = write!(out, "{id}");
        for v in row {
            match v {
                Some(v) => {
                    let _ = write!(out, ",{v}");
                }
                None => out.push(','),
            }
        }
        out.push('\n');
    }
    out
}
