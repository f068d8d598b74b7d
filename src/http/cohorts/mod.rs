//! `/v1/cohorts`: request a cohort (a queued job), follow it, cancel or delete it.

pub mod dto;
pub mod metrics;

use axum::Json;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::error::{ApiError, Problem, Result};
use super::extractors::{ApiJson, ApiQuery, parse_id};
use super::jobs::stop_job;
use crate::cohort::targets::feasibility::check_feasible;
use crate::cohort::{CohortRequest, LatentSource, RequestLimits, Targets};
use crate::db::states::{JobStatus, ModelStatus};
use crate::db::{self, cohorts::CohortRow, models::ModelRow};
use crate::engine::ModelInfo;
use crate::jobs::CancelOutcome;
use crate::jobs::Job;
use crate::jobs::cohort::CohortPayload;
use crate::jobs::setup::training_anatomy;
use dto::{CohortSummary, CohortView, CreateCohort};

/// Header that makes a retried POST return the cohort of the first attempt.
pub const IDEMPOTENCY_KEY: &str = "idempotency-key";

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(create_cohort, list_cohorts))
        .routes(routes!(get_cohort, delete_cohort))
        .routes(routes!(cancel_cohort))
        .routes(routes!(retry_cohort))
        .routes(routes!(metrics::get_cohort_metrics))
}

/// Requests a cohort; generation runs as a background job.
#[utoipa::path(post, path = "/v1/cohorts", tag = "cohorts",
    request_body = CreateCohort,
    params(("Idempotency-Key" = Option<String>, Header, description = "Retry key: the same key and body return the same cohort")),
    responses(
        (status = 202, body = CohortView, description = "Accepted; `Location` names the cohort"),
        (status = 400, body = Problem, content_type = "application/problem+json"),
        (status = 404, body = Problem, content_type = "application/problem+json", description = "Unknown model"),
        (status = 413, body = Problem, content_type = "application/problem+json", description = "Body over the JSON size limit"),
        (status = 415, body = Problem, content_type = "application/problem+json"),
        (status = 422, body = Problem, content_type = "application/problem+json", description = "A rule is broken, e.g. `count` over the work budget `(count × draws per shape + training shapes not yet reconstructed at this resolution) × resolution³`, or a target the model cannot reach (rule `feasible`, naming the achievable range)"),
        (status = 429, body = Problem, content_type = "application/problem+json", description = "Queue full; see Retry-After"),
    ))]
async fn create_cohort(
    State(state): State<AppState>,
    headers: HeaderMap,
    ApiJson(body): ApiJson<CreateCohort>,
) -> Result<Response> {
    let key = idempotency_key(&headers)?;
    // The work budget is checked below, once the model's missing setup is known.
    let limits = RequestLimits {
        max_count: state.config.max_count,
        max_voxels: u64::MAX,
    };
    let request = CohortRequest::parse(body.fields(), limits, rand::random::<u64>)?;
    let model = db::models::get(&state.pool, &body.model_id)
        .await?
        .ok_or_else(|| ApiError::not_found("model", &body.model_id))?;
    let info = match (model.status, model.info()) {
        (ModelStatus::Ready, Some(info)) => info,
        _ => {
            let msg = format!("model {:?} is {}, not ready", model.model_id, model.status);
            return Err(ApiError::Conflict(msg));
        }
    };
    let mut info = info.clone();
    if request.sampler.latent_source() == Some(LatentSource::Refitted) {
        info.refitted_latents = has_refitted_latents(&state, &model).await?;
    }
    request.check_model(&info)?;
    let reconstructed =
        db::novelty_surfaces::stored_indices(&state.pool, &model.model_id, request.resolution)
            .await?
            .len();
    let setup_shapes = info.training_shape_count().saturating_sub(reconstructed);
    request.check_budget_with_setup(setup_shapes, state.config.max_cohort_voxels)?;
    if let Some(search) = &request.targets {
        check_targets(&state, &model, &info, &search.targets).await?;
    }
    if !request.anchors.is_empty() {
        crate::http::anchors::check_cohort_anchors(&state, &model.model_id, &request.anchors)
            .await?;
    }
    let fingerprint = body.fingerprint();

    let mut submission = state.queue.begin().await?;
    if let Some(key) = key.as_deref()
        && let Some(existing) = db::cohorts::find_by_idempotency_key(submission.conn(), key).await?
    {
        if existing.request_hash != fingerprint {
            let msg = "was already used with a different request body";
            return Err(ApiError::invalid("Idempotency-Key", "reused-key", msg));
        }
        return Ok(accepted(existing, true));
    }
    let cohort_id = db::cohorts::next_id(submission.conn()).await?;
    let job = Job::Cohort(CohortPayload { cohort_id });
    let job_id = submission.enqueue(&job, i64::from(request.count)).await?;
    let row = db::cohorts::NewCohort {
        cohort_id,
        model_id: &model.model_id,
        job_id,
        request: &request,
        idempotency_key: key.as_deref(),
        request_hash: &fingerprint,
    };
    db::cohorts::insert(submission.conn(), &row).await?;
    submission.commit().await?;
    tracing::info!(cohort_id, job_id, count = request.count, "cohort queued");

    let cohort = load(&state, cohort_id, &cohort_id.to_string()).await?;
    Ok(accepted(cohort, false))
}

/// Whether every training shape of the model has a re-fitted latent now: from the
/// service's refit (`POST /v1/models/{id}/refit`), else asked of the engine, since
/// `aortagen refit` may have run on the model's directory after the model was registered.
/// An unreadable file counts as none (and is logged).
async fn has_refitted_latents(state: &AppState, model: &ModelRow) -> Result<bool> {
    let count = model.info().map_or(0, |i| i.training_shape_count());
    if db::refits::latents(&state.pool, &model.model_id, count)
        .await?
        .is_some()
    {
        return Ok(true);
    }
    let model_dir = state.jobs.model_dir(model).await?;
    let engine = state.jobs.engine.clone();
    let found = tokio::task::spawn_blocking(move || engine.refitted_latents(&model_dir))
        .await
        .map_err(|e| anyhow::anyhow!("reading the re-fitted latents failed: {e}"))?;
    Ok(match found {
        Ok(latents) => latents.is_some(),
        Err(e) => {
            tracing::warn!(model_id = %model.model_id, error = %e, "re-fitted latents unreadable");
            false
        }
    })
}

/// Checks targets against the model's training shapes. The first targeted request on a
/// model measures them; it waits for that only a third of the request deadline, past which
/// the cohort is accepted and its job, which waits for the same measurement, checks the
/// targets instead.
async fn check_targets(
    state: &AppState,
    model: &ModelRow,
    info: &ModelInfo,
    targets: &Targets,
) -> Result<()> {
    let model_dir = state.jobs.model_dir(model).await?;
    let measuring = training_anatomy(
        &state.pool,
        state.jobs.engine.clone(),
        &model.model_id,
        &model_dir,
        info.training_shape_count(),
    );
    let budget = std::time::Duration::from_secs(state.config.request_timeout_secs) / 3;
    match tokio::time::timeout(budget, measuring).await {
        Ok(training) => check_feasible(targets, &training?.shapes)?,
        Err(_) => tracing::info!(
            model_id = %model.model_id,
            "training shapes still being measured; the cohort's job checks its targets"
        ),
    }
    Ok(())
}

fn accepted(cohort: CohortRow, replayed: bool) -> Response {
    let location = format!("/v1/cohorts/{}", cohort.cohort_id);
    let mut response = (
        StatusCode::ACCEPTED,
        [(header::LOCATION, location)],
        Json(CohortView::from_row(cohort)),
    )
        .into_response();
    if replayed {
        response
            .headers_mut()
            .insert("idempotent-replayed", "true".parse().expect("valid header"));
    }
    response
}

fn idempotency_key(headers: &HeaderMap) -> Result<Option<String>> {
    let Some(value) = headers.get(IDEMPOTENCY_KEY) else {
        return Ok(None);
    };
    let key = value.to_str().unwrap_or("").trim();
    if key.is_empty() || key.len() > 255 {
        let msg = "must be 1 to 255 visible ASCII characters";
        return Err(ApiError::invalid("Idempotency-Key", "format", msg));
    }
    Ok(Some(key.to_owned()))
}

/// Filters and page of `GET /v1/cohorts`.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct CohortFilter {
    /// Only cohorts of this model.
    pub model_id: Option<String>,
    /// Only cohorts in this state (queued, running, succeeded, failed, cancelled).
    pub status: Option<String>,
    /// Page size, 1–100 (default 20).
    pub limit: Option<i64>,
    /// Items to skip (default 0).
    pub offset: Option<i64>,
}

/// A page of cohorts.
#[derive(Debug, serde::Serialize, utoipa::ToSchema)]
pub struct CohortPage {
    /// The cohorts, newest first.
    pub items: Vec<CohortView>,
    /// Offset of the next page, when there may be one.
    pub next_offset: Option<i64>,
}

/// Lists cohorts, newest first.
#[utoipa::path(get, path = "/v1/cohorts", tag = "cohorts", params(CohortFilter),
    responses((status = 200, body = CohortPage),
              (status = 400, body = Problem, content_type = "application/problem+json")))]
async fn list_cohorts(
    State(state): State<AppState>,
    ApiQuery(f): ApiQuery<CohortFilter>,
) -> Result<Json<CohortPage>> {
    let status = match f.status.as_deref() {
        None => None,
        Some(s) => Some(JobStatus::parse(s).ok_or_else(|| {
            let names: Vec<&str> = JobStatus::ALL.iter().map(|s| s.as_str()).collect();
            ApiError::BadRequest {
                field: Some("status".into()),
                message: format!("status must be one of {}, got {s:?}", names.join(", ")),
            }
        })?),
    };
    let (limit, offset) = page(f.limit, f.offset)?;
    let rows = db::cohorts::list(&state.pool, f.model_id.as_deref(), status, limit, offset).await?;
    let next_offset = next_offset(rows.len(), limit, offset);
    Ok(Json(CohortPage {
        items: rows.into_iter().map(CohortView::from_row).collect(),
        next_offset,
    }))
}

/// Page sizes a listing accepts.
pub const PAGE_LIMIT: std::ops::RangeInclusive<i64> = 1..=100;
/// Page size when `limit` is absent.
pub const DEFAULT_PAGE_LIMIT: i64 = 20;

/// The offset of the page after a full one; none after a short page or past the largest
/// offset.
pub fn next_offset(rows: usize, limit: i64, offset: i64) -> Option<i64> {
    (rows as i64 == limit).then(|| offset.checked_add(limit))?
}

/// Validates paging parameters (shared with the shapes listing).
pub fn page(limit: Option<i64>, offset: Option<i64>) -> Result<(i64, i64)> {
    let limit = limit.unwrap_or(DEFAULT_PAGE_LIMIT);
    if !PAGE_LIMIT.contains(&limit) {
        let (lo, hi) = (PAGE_LIMIT.start(), PAGE_LIMIT.end());
        let message = format!("limit must be between {lo} and {hi}, got {limit}");
        return Err(ApiError::BadRequest {
            field: Some("limit".into()),
            message,
        });
    }
    let offset = offset.unwrap_or(0);
    if offset < 0 {
        let message = format!("offset must not be negative, got {offset}");
        return Err(ApiError::BadRequest {
            field: Some("offset".into()),
            message,
        });
    }
    Ok((limit, offset))
}

/// One cohort: state, progress and summary statistics.
#[utoipa::path(get, path = "/v1/cohorts/{id}", tag = "cohorts",
    params(("id" = i64, Path, description = "Cohort id")),
    responses((status = 200, body = CohortView),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn get_cohort(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<CohortView>> {
    let cohort = load(&state, parse_id("cohort", &id)?, &id).await?;
    let measures = db::shapes::measure_summary(&state.pool, cohort.cohort_id).await?;
    let pairwise = match db::cohort_metrics::get(&state.pool, cohort.cohort_id).await? {
        Some(m) => crate::jobs::stats::PairwiseSummary::from_stored(&m.summary)
            .map_err(anyhow::Error::from)?,
        None => None,
    };
    let mut view = CohortView::from_row(cohort);
    view.summary = Some(CohortSummary::new(&measures, pairwise));
    Ok(Json(view))
}

/// Stops a cohort: a queued one at once, a running one within seconds; finished shapes stay.
#[utoipa::path(post, path = "/v1/cohorts/{id}/cancel", tag = "cohorts",
    params(("id" = i64, Path, description = "Cohort id")),
    responses((status = 202, body = CohortView, description = "Cancelled or cancellation under way"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Already finished")))]
async fn cancel_cohort(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<impl IntoResponse> {
    let cohort = load(&state, parse_id("cohort", &id)?, &id).await?;
    if stop_job(&state, cohort.job_id).await? == CancelOutcome::AlreadyFinished {
        return Err(ApiError::Conflict(format!(
            "cohort {id} has already {}",
            cohort.status
        )));
    }
    let cohort = load(&state, cohort.cohort_id, &id).await?;
    Ok((StatusCode::ACCEPTED, Json(CohortView::from_row(cohort))))
}

/// Resumes a failed or cancelled cohort: its stored shapes stay and the missing ones are
/// generated from the same seeds, so the result equals an uninterrupted run.
#[utoipa::path(post, path = "/v1/cohorts/{id}/retry", tag = "cohorts",
    params(("id" = i64, Path, description = "Cohort id")),
    responses((status = 202, body = CohortView, description = "Queued again; `Location` names the cohort"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Queued, running or succeeded: only a failed or cancelled cohort can be retried"),
              (status = 429, body = Problem, content_type = "application/problem+json", description = "Queue full; see Retry-After")))]
async fn retry_cohort(State(state): State<AppState>, Path(id): Path<String>) -> Result<Response> {
    let cohort = load(&state, parse_id("cohort", &id)?, &id).await?;
    let mut submission = state.queue.begin().await?;
    if !submission.requeue(cohort.job_id).await? {
        drop(submission);
        // Read again: the state may have changed since the cohort was loaded.
        let status = db::jobs::get(&state.pool, cohort.job_id)
            .await?
            .map_or(cohort.status, |job| job.status);
        let msg =
            format!("cohort {id} is {status}; only a failed or cancelled cohort can be retried");
        return Err(ApiError::Conflict(msg));
    }
    submission.commit().await?;
    tracing::info!(
        cohort_id = cohort.cohort_id,
        job_id = cohort.job_id,
        "cohort queued again"
    );
    let cohort = load(&state, cohort.cohort_id, &id).await?;
    Ok(accepted(cohort, false))
}

/// Deletes a cohort with its shapes and metrics; a running cohort must be cancelled first.
#[utoipa::path(delete, path = "/v1/cohorts/{id}", tag = "cohorts",
    params(("id" = i64, Path, description = "Cohort id")),
    responses((status = 204, description = "Deleted"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Still running")))]
async fn delete_cohort(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode> {
    let cohort = load(&state, parse_id("cohort", &id)?, &id).await?;
    if cohort.status == JobStatus::Running {
        let msg = format!("cohort {id} is running; cancel it first (POST /v1/cohorts/{id}/cancel)");
        return Err(ApiError::Conflict(msg));
    }
    // A queued cohort is cancelled first so no worker claims it while it is deleted.
    if stop_job(&state, cohort.job_id).await? == CancelOutcome::Requested {
        let msg =
            format!("cohort {id} started running; it is being cancelled, delete it afterwards");
        return Err(ApiError::Conflict(msg));
    }
    let mut tx = db::begin_write(&state.pool).await?;
    // Its validations go with it, once none runs.
    let validation_jobs = db::validations::job_ids_for_cohort(&mut tx, cohort.cohort_id).await?;
    for job_id in &validation_jobs {
        let pending = db::jobs::get(&state.pool, *job_id)
            .await?
            .is_some_and(|j| j.status.is_pending());
        if pending {
            let msg = format!(
                "cohort {id} has a validation still running (job {job_id}); cancel it first"
            );
            return Err(ApiError::Conflict(msg));
        }
    }
    db::cohorts::delete(&mut tx, cohort.cohort_id).await?;
    db::jobs::delete(&mut tx, cohort.job_id).await?;
    for job_id in validation_jobs {
        db::jobs::delete(&mut tx, job_id).await?;
    }
    tx.commit().await?;
    Ok(StatusCode::NO_CONTENT)
}

/// Loads a cohort or answers 404.
pub(super) async fn load(state: &AppState, cohort_id: i64, raw: &str) -> Result<CohortRow> {
    db::cohorts::get(&state.pool, cohort_id)
        .await?
        .ok_or_else(|| ApiError::not_found("cohort", raw))
}
