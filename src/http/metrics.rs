//! `GET /metrics`: Prometheus text exposition of request latencies, jobs by state, job
//! durations and shapes generated.

use axum::extract::State;
use axum::http::header;
use axum::response::IntoResponse;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::error::Result;
use crate::db;

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(get_metrics))
}

/// Prometheus metrics.
#[utoipa::path(get, path = "/metrics", tag = "operations",
    responses((status = 200, description = "Prometheus text format 0.0.4", content_type = "text/plain")))]
async fn get_metrics(State(state): State<AppState>) -> Result<impl IntoResponse> {
    let by_state = db::jobs::count_by_status(&state.pool).await?;
    let body = state.jobs.metrics.render(&by_state);
    Ok((
        [(
            header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        body,
    ))
}
