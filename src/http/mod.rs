//! The HTTP edge: application state, the router (one sub-router per resource), request
//! tracing and latency metrics. Only this module knows HTTP.

pub mod access;
pub mod anchors;
pub mod cohort_meshes;
pub mod cohorts;
pub mod contract;
pub mod cross_site;
pub mod dashboard;
pub mod error;
pub mod events;
pub mod extractors;
pub mod health;
pub mod jobs;
pub mod limits;
pub mod mesh_cache;
pub mod metrics;
pub mod model_upload;
pub mod models;
pub mod openapi;
pub mod refits;
pub mod rendering;
pub mod reports;
pub mod server;
pub mod shapes;
pub mod simulation_meshes;
pub mod thumbnails;
pub mod upload_archive;
pub mod validations;

use std::sync::Arc;
use std::time::Instant;

use axum::extract::{DefaultBodyLimit, MatchedPath, Request, State};
use axum::http::Uri;
use axum::middleware::{self, Next};
use axum::response::Response;
use axum::{Extension, Router};
use tower_http::trace::TraceLayer;
use utoipa_axum::router::OpenApiRouter;

use crate::config::Config;
use crate::db::ReadOnlySwitch;
use crate::jobs::{JobContext, JobQueue};
use access::AccessPolicy;
use error::ApiError;
use extractors::JsonBodyLimit;
use limits::Limits;

/// Everything handlers share; cheap to clone.
#[derive(Clone)]
pub struct AppState {
    /// The database.
    pub pool: crate::db::Pool,
    /// Settings.
    pub config: Arc<Config>,
    /// Engine, job controls and metrics, shared with the workers.
    pub jobs: JobContext,
    /// The one way into the job queue.
    pub queue: JobQueue,
    /// API keys and what they protect.
    pub access: Arc<AccessPolicy>,
    /// Fault injection: makes the database refuse writes (tests of storage faults).
    pub read_only_switch: ReadOnlySwitch,
    /// Encoded mesh downloads.
    pub mesh_cache: Arc<mesh_cache::MeshCache>,
    /// The readiness probe's write, shared by concurrent `/readyz` calls.
    pub readiness: Arc<health::ReadinessProbe>,
    /// Simulation meshes being made: bounded, deduplicated, stored.
    pub simulations: Arc<crate::jobs::simulation::SimulationWork>,
}

/// Every documented route, with its OpenAPI description.
pub fn api_router() -> OpenApiRouter<AppState> {
    OpenApiRouter::with_openapi(openapi::base_document())
        .merge(health::router())
        .merge(openapi::router())
        .merge(metrics::router())
        .merge(models::router())
        .merge(anchors::router())
        .merge(refits::router())
        .merge(cohorts::router())
        .merge(shapes::router())
        .merge(simulation_meshes::router())
        .merge(cohort_meshes::router())
        .merge(jobs::router())
        .merge(reports::router())
        .merge(validations::router())
        .merge(thumbnails::router())
        .merge(events::router())
        .merge(dashboard::router())
}

/// The complete application: routes, fallbacks, limits, access control, tracing and
/// metrics. From the outside in: tracing, metrics (so refused and timed-out requests are
/// counted), the in-flight bound, the deadline, the cross-site check, the key check, body
/// limits, the handler.
pub fn router(state: AppState) -> Router {
    let (routes, _) = api_router().split_for_parts();
    let limit = state.config.max_upload_bytes;
    let limits = Limits::from_config(&state.config);
    routes
        .fallback(|uri: Uri| async move { ApiError::not_found("route", uri.path()) })
        .layer(DefaultBodyLimit::max(limit))
        .layer(Extension(JsonBodyLimit(state.config.max_json_bytes)))
        .layer(middleware::from_fn_with_state(
            state.access.clone(),
            access::require_key,
        ))
        .layer(middleware::from_fn(cross_site::refuse_cross_site_writes))
        .layer(middleware::from_fn_with_state(
            limits.clone(),
            limits::deadline,
        ))
        .layer(middleware::from_fn_with_state(
            limits,
            limits::bound_in_flight,
        ))
        .layer(middleware::from_fn_with_state(state.clone(), track_metrics))
        .layer(TraceLayer::new_for_http().make_span_with(|req: &Request| {
            let route = req
                .extensions()
                .get::<MatchedPath>()
                .map(|p| p.as_str().to_owned());
            tracing::info_span!(
                "http",
                method = %req.method(),
                uri = %req.uri(),
                route = route.as_deref().unwrap_or("unmatched"),
            )
        }))
        .with_state(state)
}

/// Records each request's latency under its route template (not the raw path, which would
/// make one series per id).
async fn track_metrics(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_owned(), |p| p.as_str().to_owned());
    let method = req.method().to_string();
    let start = Instant::now();
    let response = next.run(req).await;
    let seconds = start.elapsed().as_secs_f64();
    state
        .jobs
        .metrics
        .observe_http(&method, &route, response.status().as_u16(), seconds);
    response
}
