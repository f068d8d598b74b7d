//! Liveness and readiness probes.

use std::sync::atomic::{AtomicU64, Ordering};

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
    let probe = state.readiness.check(&state.pool, || {
        state.jobs.metrics.inc_readiness_probes();
    });
    probe.await.map_err(ApiError::Unavailable)?;
    Ok(Json(HealthStatus { status: "ok" }))
}

/// The readiness probe's write, shared by concurrent checks: a check that arrives while a
/// probe is running waits for the next one to start and finish, and one that arrives while
/// a later probe is already done takes its answer. A flood of `/readyz` calls therefore makes
/// one database write at a time (not one per call), and every answer comes from a write that
/// started after the call arrived, so a fault is never hidden by an older success.
#[derive(Debug, Default)]
pub struct ReadinessProbe {
    started: AtomicU64,
    last: tokio::sync::Mutex<Option<(u64, Result<(), String>)>>,
}

impl ReadinessProbe {
    /// Whether the database takes a write; the error says why not. `on_write` runs once per
    /// write actually made.
    pub async fn check(
        &self,
        pool: &crate::db::Pool,
        on_write: impl FnOnce(),
    ) -> Result<(), String> {
        let arrived_after = self.started.load(Ordering::SeqCst);
        let mut last = self.last.lock().await;
        if let Some((probe, outcome)) = last.as_ref()
            && *probe > arrived_after
        {
            return outcome.clone();
        }
        let probe = self.started.fetch_add(1, Ordering::SeqCst) + 1;
        on_write();
        let outcome =
            crate::db::probe_write(pool)
                .await
                .map_err(|e| match crate::db::storage_fault(&e) {
                    Some(fault) => format!("storage unavailable: {fault}"),
                    None => format!("the database does not answer: {e}"),
                });
        *last = Some((probe, outcome.clone()));
        outcome
    }
}
