//! `GET /v1/cohorts/{id}/metrics`: pairwise Chamfer distances among a cohort's shapes
//! (squared distances in unit-ball coordinates), as summary JSON or CSV.

use std::fmt::Write as _;

use axum::Json;
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};

use crate::db;
use crate::http::AppState;
use crate::http::error::{ApiError, Problem, Result};
use crate::http::extract::{ApiQuery, parse_id};
use crate::jobs::stats::PairwiseSummary;

/// Options of the metrics endpoint.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct MetricsQuery {
    /// `json` (default) or `csv`.
    pub format: Option<String>,
    /// Include the full matrix (JSON) or return it instead of the pair list (CSV).
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
    /// Statistics over distinct pairs (null for a single shape).
    pub summary: Option<PairwiseSummary>,
    /// The symmetric matrix, when `matrix=true`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub matrix: Option<Vec<Vec<f64>>>,
    /// When it was computed.
    pub computed_at: String,
}

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
    let csv = match q.format.as_deref() {
        None | Some("json") => false,
        Some("csv") => true,
        Some(other) => {
            let message = format!("format must be json or csv, got {other:?}");
            return Err(ApiError::BadRequest {
                field: Some("format".into()),
                message,
            });
        }
    };
    let cohort = super::load(&state, parse_id("cohort", &id)?, &id).await?;
    let Some(row) = db::cohort_metrics::get(&state.pool, cohort.cohort_id).await? else {
        return Err(ApiError::Conflict(format!(
            "cohort {id} has no metrics yet (status {}); they are computed after all shapes",
            cohort.status
        )));
    };
    let matrix: Vec<Vec<f64>> = serde_json::from_str(&row.matrix).map_err(anyhow::Error::from)?;
    let summary: Option<PairwiseSummary> =
        serde_json::from_str(&row.summary).map_err(anyhow::Error::from)?;
    let shape_ids: Vec<i64> = db::shapes::cohort_meshes(&state.pool, cohort.cohort_id)
        .await?
        .into_iter()
        .map(|s| s.shape_id)
        .collect();
    let with_matrix = q.matrix.unwrap_or(false);
    if csv {
        let body = if with_matrix {
            matrix_csv(&shape_ids, &matrix)
        } else {
            pairs_csv(&shape_ids, &matrix)
        };
        return Ok(([(header::CONTENT_TYPE, "text/csv; charset=utf-8")], body).into_response());
    }
    Ok(Json(CohortMetrics {
        cohort_id: cohort.cohort_id,
        measure: MEASURE,
        shape_ids,
        summary,
        matrix: with_matrix.then_some(matrix),
        computed_at: row.created_at,
    })
    .into_response())
}

fn pairs_csv(ids: &[i64], m: &[Vec<f64>]) -> String {
    let mut out = String::from("shape_a,shape_b,chamfer\n");
    for i in 0..m.len() {
        for j in i + 1..m.len() {
            let _ = writeln!(out, "{},{},{}", ids[i], ids[j], m[i][j]);
        }
    }
    out
}

fn matrix_csv(ids: &[i64], m: &[Vec<f64>]) -> String {
    let mut out = String::from("shape");
    for id in ids {
        let _ = write!(out, ",{id}");
    }
    out.push('\n');
    for (id, row) in ids.iter().zip(m) {
        let _ = write!(out, "{id}");
        for v in row {
            let _ = write!(out, ",{v}");
        }
        out.push('\n');
    }
    out
}
