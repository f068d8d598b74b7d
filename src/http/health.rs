//! Liveness and readiness probes.

use axum::Json;
use axum::extract::State;
use serde::Serialize;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::error::{ApiError, Result};

/// Probe answer.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct HealthStatus {
    /// `ok` when healthy.
    pub status: &'static str,
}

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(get_healthz))
        .routes(routes!(get_readyz))
}

/// Liveness: the process answers HTTP.
#[utoipa::path(get, path = "/healthz", tag = "operations",
    responses((status = 200, body = HealthStatus)))]
async fn get_healthz() -> Json<HealthStatus> {
    Json(HealthStatus { status: "ok" })
}

/// Readiness: the database takes a write (a one-row probe) and the process is not shutting
/// down. A read-only database or a full disk makes the service not ready until it clears.
#[utoipa::path(get, path = "/readyz", tag = "operations",
    responses((status = 200, body = HealthStatus),
              (status = 503, body = super::error::Problem, content_type = "application/problem+json")))]
async fn get_readyz(State(state): State<AppState>) -> Result<Json<HealthStatus>> {
    if state.jobs.controls.is_shutting_down() {
        return Err(ApiError::Unavailable("the service is shutting down".into()));
    }
    if let Err(e) = crate::db::probe_write(&state.pool).await {
        let reason = match crate::db::storage_fault(&e) {
            Some(fault) => format!("storage unavailable: {fault}"),
            None => format!("the database does not answer: {e}"),
        };
        return Err(ApiError::Unavailable(reason));
    }
    Ok(Json(HealthStatus { status: "ok" }))
}
