//! The HTTP edge: application state, the router (one sub-router per resource), request
//! tracing and latency metrics. Only this module knows HTTP.

pub mod cohorts;
pub mod error;
pub mod extract;
pub mod health;
pub mod jobs;
pub mod metrics;
pub mod model_upload;
pub mod models;
pub mod openapi;
pub mod shapes;
pub mod upload_archive;

use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::extract::{DefaultBodyLimit, MatchedPath, Request, State};
use axum::http::{StatusCode, Uri};
use axum::middleware::{self, Next};
use axum::response::Response;
use axum::{Extension, Router};
use sqlx::SqlitePool;
use tokio::sync::Notify;
use tower_http::timeout::TimeoutLayer;
use tower_http::trace::TraceLayer;
use utoipa_axum::router::OpenApiRouter;

use crate::config::Config;
use crate::jobs::JobContext;
use error::ApiError;
use extract::BodyLimit;

/// Everything handlers share; cheap to clone.
#[derive(Clone)]
pub struct AppState {
    /// The database.
    pub pool: SqlitePool,
    /// Settings.
    pub config: Arc<Config>,
    /// Engine, job controls and metrics, shared with the workers.
    pub jobs: JobContext,
    /// Wakes an idle worker when a job is enqueued.
    pub job_wake: Arc<Notify>,
}

/// Every documented route, with its OpenAPI description.
pub fn api_router() -> OpenApiRouter<AppState> {
    OpenApiRouter::with_openapi(openapi::base_document())
        .merge(health::router())
        .merge(openapi::router())
        .merge(metrics::router())
        .merge(models::router())
        .merge(cohorts::router())
        .merge(shapes::router())
        .merge(jobs::router())
}

/// The complete application: routes, fallbacks, limits, tracing and metrics.
pub fn router(state: AppState) -> Router {
    let (routes, _) = api_router().split_for_parts();
    let limit = state.config.max_upload_bytes;
    let timeout = Duration::from_secs(state.config.request_timeout_secs);
    routes
        .fallback(|uri: Uri| async move { ApiError::not_found("route", uri.path()) })
        .layer(middleware::from_fn_with_state(state.clone(), track_metrics))
        .layer(DefaultBodyLimit::max(limit))
        .layer(Extension(BodyLimit(limit)))
        .layer(TimeoutLayer::with_status_code(
            StatusCode::REQUEST_TIMEOUT,
            timeout,
        ))
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
