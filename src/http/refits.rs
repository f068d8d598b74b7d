//! Re-fitting a model's training shapes in the service: `POST /v1/models/{id}/refit` queues
//! a `refit` job that fits every training shape again with the network frozen, as a new
//! patient is fitted (`aortagen refit` does the same beside a model directory), and
//! `GET /v1/models/{id}/refit` shows how far it got and, per shape, the fitted latent. Once
//! every shape has one, cohorts may ask for `"sampler": {"latents": "refitted"}`.
//!
//! A model has one refit: its settings are fixed by the first request. Asking again with the
//! same settings returns it, or continues it with a new job when it failed or was cancelled
//! (the shapes already fitted are kept); other settings are refused.

use axum::Json;
use axum::extract::{Path, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::anchors::TransformView;
use super::error::{ApiError, Problem, Result};
use super::extractors::{ApiJson, bounded};
use crate::db::refits::{RefitRow, RefitShapeRow};
use crate::db::states::{JobStatus, ModelStatus};
use crate::db::{self, jobs::JobRow, models::ModelRow};
use crate::jobs::Job;
use crate::jobs::refit::RefitPayload;
use crate::sdf::training::fit::{DEFAULT_FIT_ITERATIONS, MAX_FIT_ITERATIONS};

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(create_refit, get_refit))
}

/// A refit request; every field is optional and defaults as `aortagen refit`.
#[derive(Debug, Default, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateRefit {
    /// Adam steps of each shape's fit, 1–10000 (default 800).
    #[schema(minimum = 1, maximum = 10000)]
    pub iterations: Option<u64>,
    /// Seed of training shape 0's fit; shape i uses seed + 2 i (default 0; at most
    /// 2^63 − 1).
    #[schema(minimum = 0, maximum = 9223372036854775807_i64)]
    pub seed: Option<u64>,
}

/// Where a refit stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum RefitStatus {
    /// Its job fits the shapes still missing.
    Refitting,
    /// Every training shape has its re-fitted latent.
    Ready,
    /// Its job failed (see `error`); asking again continues it.
    Failed,
    /// Its job was cancelled; asking again continues it.
    Cancelled,
}

/// Training shapes re-fitted so far.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct RefitProgress {
    /// Shapes with a stored fit.
    pub done: i64,
    /// The model's training shapes.
    pub total: i64,
}

/// One re-fitted training shape.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct RefitShapeView {
    /// The training shape's index (its latent's).
    pub index: i64,
    /// Its name in the model.
    pub name: Option<String>,
    /// Seed of its fit (the refit's seed + 2 × index).
    pub seed: u64,
    /// Reconstruction Chamfer distance of the fitted latent (unit-ball coordinates,
    /// squared distances: the measure reported for training shapes and anchors).
    pub chamfer: f64,
    /// The fitted latent code.
    pub latent: Vec<f32>,
    /// The shape's unit-ball transform.
    pub transform: TransformView,
}

/// URLs of a refit's related resources.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct RefitLinks {
    /// This refit.
    #[serde(rename = "self")]
    pub this: String,
    /// Its current job.
    pub job: String,
    /// Its model.
    pub model: String,
}

/// A model's refit.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct RefitView {
    /// The model.
    pub model_id: String,
    /// Where it stands.
    pub status: RefitStatus,
    /// Adam steps of each fit.
    pub iterations: i64,
    /// Seed of shape 0's fit.
    pub seed: u64,
    /// Shapes fitted so far.
    pub progress: RefitProgress,
    /// Median reconstruction Chamfer distance of the fits so far.
    pub median_chamfer: Option<f64>,
    /// The current job (a continued refit has a new one).
    pub job_id: i64,
    /// Why its job failed.
    pub error: Option<String>,
    /// The fitted shapes, by index.
    pub shapes: Vec<RefitShapeView>,
    /// When it was first requested (UTC, RFC 3339).
    pub created_at: String,
    /// Related resources.
    pub links: RefitLinks,
}

impl RefitView {
    fn new(
        model: &ModelRow,
        row: RefitRow,
        job: Option<JobRow>,
        shapes: Vec<RefitShapeRow>,
    ) -> Self {
        let names = model.info().map(|i| &i.training_shapes);
        let total = names.map_or(0, |n| n.len() as i64);
        let done = shapes.len() as i64;
        let status = match job.as_ref().map(|j| j.status) {
            _ if total > 0 && done >= total => RefitStatus::Ready,
            Some(JobStatus::Queued | JobStatus::Running) => RefitStatus::Refitting,
            Some(JobStatus::Cancelled) => RefitStatus::Cancelled,
            Some(JobStatus::Failed | JobStatus::Succeeded) | None => RefitStatus::Failed,
        };
        let chamfers: Vec<f64> = shapes.iter().map(|s| s.chamfer).collect();
        let seed = row.seed as u64;
        let id = &row.model_id;
        Self {
            model_id: id.clone(),
            status,
            iterations: row.iterations,
            seed,
            progress: RefitProgress { done, total },
            median_chamfer: crate::stats::descriptive::quantile(&chamfers, 0.5).ok(),
            job_id: row.job_id,
            error: job.and_then(|j| j.error),
            shapes: shapes
                .into_iter()
                .map(|s| RefitShapeView {
                    index: s.shape_index,
                    name: names
                        .and_then(|n| n.get(s.shape_index as usize))
                        .map(|t| t.name.clone()),
                    seed: seed.wrapping_add(2 * s.shape_index as u64),
                    chamfer: s.chamfer,
                    latent: s.latent_values(),
                    transform: {
                        let t = s.transform();
                        TransformView {
                            centre: t.centre,
                            radius: t.radius,
                        }
                    },
                })
                .collect(),
            created_at: row.created_at.clone(),
            links: RefitLinks {
                this: format!("/v1/models/{id}/refit"),
                job: format!("/v1/jobs/{}", row.job_id),
                model: format!("/v1/models/{id}"),
            },
        }
    }
}

/// Re-fits every training shape of a ready model with the network frozen, one task per
/// shape; answers 202 with the refit (its job's progress counts fitted shapes), or 200 with
/// the refit when one with the same settings is already running or done.
#[utoipa::path(post, path = "/v1/models/{id}/refit", tag = "models",
    params(("id" = String, Path, description = "Model id")),
    request_body = CreateRefit,
    responses((status = 202, body = RefitView, description = "Queued (or continued with a new job)"),
              (status = 200, body = RefitView, description = "Already running or done with these settings"),
              (status = 400, body = Problem, content_type = "application/problem+json", description = "Malformed JSON"),
              (status = 404, body = Problem, content_type = "application/problem+json", description = "Unknown model"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "The model is not ready, or was re-fitted with other settings"),
              (status = 415, body = Problem, content_type = "application/problem+json", description = "The body is not `application/json`"),
              (status = 422, body = Problem, content_type = "application/problem+json", description = "`iterations` or `seed` out of range"),
              (status = 429, body = Problem, content_type = "application/problem+json", description = "Queue full; see Retry-After")))]
async fn create_refit(
    State(state): State<AppState>,
    Path(id): Path<String>,
    ApiJson(body): ApiJson<CreateRefit>,
) -> Result<Response> {
    let iterations = bounded(
        "iterations",
        body.iterations,
        MAX_FIT_ITERATIONS as u64,
        DEFAULT_FIT_ITERATIONS as u64,
    )? as i64;
    let seed = match body.seed {
        None => 0,
        Some(s) => i64::try_from(s).map_err(|_| {
            let msg = format!("must be an integer from 0 to {}, got {s}", i64::MAX);
            ApiError::invalid("seed", "range", msg)
        })?,
    };
    let model = load_model(&state, &id).await?;
    let total = match (model.status, model.info()) {
        (ModelStatus::Ready, Some(info)) => info.training_shape_count() as i64,
        _ => {
            let msg = format!("model {id:?} is {}, not ready", model.status);
            return Err(ApiError::Conflict(msg));
        }
    };
    let existing = db::refits::get(&state.pool, &id).await?;
    let job = Job::Refit(RefitPayload {
        model_id: id.clone(),
    });
    let queued = match existing {
        None => {
            let mut submission = state.queue.begin().await?;
            let job_id = submission.enqueue(&job, total).await?;
            let inserted =
                db::refits::insert(submission.conn(), &id, job_id, iterations, seed).await;
            if let Err(e) = &inserted
                && db::is_unique_violation(e)
            {
                let msg = format!("a refit of model {id:?} was requested at the same time");
                return Err(ApiError::Conflict(msg));
            }
            inserted?;
            submission.commit().await?;
            tracing::info!(model_id = %id, job_id, iterations, seed, "refit queued");
            true
        }
        Some(row) if (row.iterations, row.seed) != (iterations, seed) => {
            let msg = format!(
                "model {id:?} is re-fitted with {} iterations and seed {}; a refit with other \
                 settings would mix two kinds of fit (ask with those settings to continue it)",
                row.iterations, row.seed
            );
            return Err(ApiError::Conflict(msg));
        }
        Some(row) => {
            let done = db::refits::shape_count(&state.pool, &id).await?;
            let status = db::jobs::get(&state.pool, row.job_id)
                .await?
                .map(|j| j.status);
            let continue_it = done < total && !status.is_some_and(JobStatus::is_pending);
            if continue_it {
                let mut submission = state.queue.begin().await?;
                let job_id = submission.enqueue(&job, total).await?;
                db::refits::set_job(submission.conn(), &id, job_id).await?;
                db::jobs::set_progress(submission.conn(), job_id, done).await?;
                submission.commit().await?;
                tracing::info!(model_id = %id, job_id, done, total, "refit continued");
            }
            continue_it
        }
    };
    let view = view(&state, &model).await?;
    let status = match queued {
        true => StatusCode::ACCEPTED,
        false => StatusCode::OK,
    };
    Ok((
        status,
        [(header::LOCATION, view.links.this.clone())],
        Json(view),
    )
        .into_response())
}

/// A model's refit: its status, progress and the latents fitted so far.
#[utoipa::path(get, path = "/v1/models/{id}/refit", tag = "models",
    params(("id" = String, Path, description = "Model id")),
    responses((status = 200, body = RefitView),
              (status = 404, body = Problem, content_type = "application/problem+json", description = "Unknown model, or no refit requested")))]
async fn get_refit(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<RefitView>> {
    let model = load_model(&state, &id).await?;
    Ok(Json(view(&state, &model).await?))
}

async fn load_model(state: &AppState, id: &str) -> Result<ModelRow> {
    db::models::get(&state.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("model", id))
}

async fn view(state: &AppState, model: &ModelRow) -> Result<RefitView> {
    let id = &model.model_id;
    let row = db::refits::get(&state.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("refit of model", id))?;
    let job = db::jobs::get(&state.pool, row.job_id).await?;
    let shapes = db::refits::shapes(&state.pool, id).await?;
    Ok(RefitView::new(model, row, job, shapes))
}

/// Whether a refit of the model is queued or running (the model cannot be deleted then).
pub(super) async fn is_running(state: &AppState, model_id: &str) -> Result<bool> {
    let Some(row) = db::refits::get(&state.pool, model_id).await? else {
        return Ok(false);
    };
    let job = db::jobs::get(&state.pool, row.job_id).await?;
    Ok(job.is_some_and(|j| j.status.is_pending()))
}
