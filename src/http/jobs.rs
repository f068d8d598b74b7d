//! `GET /v1/jobs/{id}`: the state of background work; `POST /v1/jobs/{id}/cancel` stops it.

use axum::Json;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::IntoResponse;
use serde::Serialize;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::error::{ApiError, Problem, Result};
use super::extractors::parse_id;
use crate::db::states::{JobKind, JobStatus};
use crate::db::{self, jobs::JobRow};
use crate::jobs::{self, CancelOutcome, Job};

/// A job as the API shows it.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct JobView {
    /// Job id.
    pub id: i64,
    /// What it does.
    pub kind: JobKind,
    /// Where it stands.
    pub status: JobStatus,
    /// Units of work done and in total (shapes for a cohort).
    pub progress: Progress,
    /// Times a worker claimed the job (more than 1 after restarts).
    pub attempts: i64,
    /// Whether cancellation was requested.
    pub cancel_requested: bool,
    /// Enqueue time (UTC, RFC 3339).
    pub created_at: String,
    /// First start.
    pub started_at: Option<String>,
    /// End.
    pub finished_at: Option<String>,
    /// Error chain when failed.
    pub error: Option<String>,
    /// The resource the job works on.
    pub subject: Option<String>,
}

/// Done / total.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct Progress {
    /// Units done.
    pub done: i64,
    /// Units in total.
    pub total: i64,
}

impl From<JobRow> for JobView {
    fn from(j: JobRow) -> Self {
        let subject = match Job::parse(j.kind, &j.payload) {
            Ok(Job::Cohort(p)) => Some(format!("/v1/cohorts/{}", p.cohort_id)),
            Ok(Job::Training(p)) => Some(format!("/v1/models/{}", p.model_id)),
            Ok(Job::Fit(p)) => Some(format!("/v1/anchors/{}", p.anchor_id)),
            Ok(Job::Validation(p)) => Some(format!("/v1/validations/{}", p.validation_id)),
            Ok(Job::Refit(p)) => Some(format!("/v1/models/{}/refit", p.model_id)),
            Err(_) => None,
        };
        Self {
            id: j.job_id,
            kind: j.kind,
            status: j.status,
            progress: Progress {
                done: j.progress_done,
                total: j.progress_total,
            },
            attempts: j.attempts,
            cancel_requested: j.cancel_requested.0,
            created_at: j.created_at,
            started_at: j.started_at,
            finished_at: j.finished_at,
            error: j.error,
            subject,
        }
    }
}

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(get_job))
        .routes(routes!(cancel_job))
}

/// One job: kind, state, progress, timings, error text when failed.
#[utoipa::path(get, path = "/v1/jobs/{id}", tag = "jobs",
    params(("id" = i64, Path, description = "Job id")),
    responses((status = 200, body = JobView),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn get_job(State(state): State<AppState>, Path(id): Path<String>) -> Result<Json<JobView>> {
    let job_id = parse_id("job", &id)?;
    let job = db::jobs::get(&state.pool, job_id)
        .await?
        .ok_or_else(|| ApiError::not_found("job", &id))?;
    Ok(Json(job.into()))
}

/// Stops a job of any kind: a queued one at once, a running one at its next check (within
/// seconds). What it worked on ends as when the job is interrupted: a cohort keeps its finished
/// shapes, a model being trained and an anchor being fitted become `failed` ("cancelled").
#[utoipa::path(post, path = "/v1/jobs/{id}/cancel", tag = "jobs",
    params(("id" = i64, Path, description = "Job id")),
    responses((status = 202, body = JobView, description = "Cancelled or cancellation under way"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Already finished")))]
async fn cancel_job(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<impl IntoResponse> {
    let job_id = parse_id("job", &id)?;
    let job = db::jobs::get(&state.pool, job_id)
        .await?
        .ok_or_else(|| ApiError::not_found("job", &id))?;
    if stop_job(&state, job_id).await? == CancelOutcome::AlreadyFinished {
        return Err(ApiError::Conflict(format!(
            "job {id} has already {}",
            job.status
        )));
    }
    let job = db::jobs::get(&state.pool, job_id)
        .await?
        .ok_or_else(|| ApiError::not_found("job", &id))?;
    Ok((StatusCode::ACCEPTED, Json(JobView::from(job))))
}

/// Asks a job to stop: one no worker holds is cancelled at once; one being worked on is
/// flagged, its tasks in this process interrupted now and those elsewhere at their next
/// lease renewal.
pub(super) async fn stop_job(state: &AppState, job_id: i64) -> Result<CancelOutcome> {
    Ok(jobs::lifecycle::cancel(&state.jobs, job_id).await?)
}
