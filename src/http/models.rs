//! `/v1/models`: the registered generative models, their training shapes and fidelity.

use axum::Json;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use serde::Serialize;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::error::{ApiError, Problem, Result};
use crate::db::states::ModelStatus;
use crate::db::{self, models::ModelRow};
use crate::engine::{ModelInfo, TrainingShapeInfo};

/// A model as the API shows it.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ModelView {
    /// Model id.
    pub id: String,
    /// training | ready | failed.
    pub status: ModelStatus,
    /// Registration time (UTC, RFC 3339).
    pub created_at: String,
    /// Latent code dimension (null while training).
    pub latent_dim: Option<usize>,
    /// Network description.
    #[schema(value_type = Object)]
    pub architecture: serde_json::Value,
    /// Number of training shapes (the largest usable arity).
    pub training_shapes: usize,
    /// Reconstruction Chamfer distances over training shapes (unit-ball coordinates).
    pub reconstruction_cd: Option<CdSummary>,
    /// Its training shapes.
    pub shapes_url: String,
    /// Its training shapes re-fitted with the network frozen (404 until requested).
    pub refit_url: String,
}

/// Summary of reconstruction Chamfer distances.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct CdSummary {
    /// Shapes with a measured value.
    pub count: usize,
    /// Mean.
    pub mean: f64,
    /// Median.
    pub median: f64,
    /// Maximum.
    pub max: f64,
}

/// A training shape.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct TrainingShapeView {
    /// Latent index (what cohorts' `training_indices` refer to).
    pub index: usize,
    /// Source name.
    pub name: String,
    /// Reconstruction Chamfer distance (unit-ball coordinates), if measured.
    pub reconstruction_cd: Option<f64>,
}

impl From<TrainingShapeInfo> for TrainingShapeView {
    fn from(t: TrainingShapeInfo) -> Self {
        Self {
            index: t.index,
            name: t.name,
            reconstruction_cd: t.reconstruction_cd,
        }
    }
}

fn manifest(row: &ModelRow) -> Option<ModelInfo> {
    row.info().cloned()
}

impl ModelView {
    fn from_row(row: ModelRow) -> Self {
        let info = manifest(&row);
        let mut cds: Vec<f64> = info
            .iter()
            .flat_map(|i| i.training_shapes.iter().filter_map(|s| s.reconstruction_cd))
            .collect();
        cds.sort_by(f64::total_cmp);
        let reconstruction_cd = (!cds.is_empty()).then(|| CdSummary {
            count: cds.len(),
            mean: cds.iter().sum::<f64>() / cds.len() as f64,
            median: if cds.len() % 2 == 1 {
                cds[cds.len() / 2]
            } else {
                0.5 * (cds[cds.len() / 2 - 1] + cds[cds.len() / 2])
            },
            max: cds[cds.len() - 1],
        });
        Self {
            shapes_url: format!("/v1/models/{}/shapes", row.model_id),
            refit_url: format!("/v1/models/{}/refit", row.model_id),
            id: row.model_id,
            status: row.status,
            created_at: row.created_at,
            latent_dim: info.as_ref().map(|i| i.latent_dim),
            architecture: info
                .as_ref()
                .map_or(serde_json::Value::Null, |i| i.architecture.clone()),
            training_shapes: info.as_ref().map_or(0, |i| i.training_shape_count()),
            reconstruction_cd,
        }
    }
}

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_models, super::model_upload::create_model))
        .routes(routes!(get_model, delete_model))
        .routes(routes!(list_model_shapes))
}

/// All registered models.
#[utoipa::path(get, path = "/v1/models", tag = "models",
    responses((status = 200, body = Vec<ModelView>)))]
async fn list_models(State(state): State<AppState>) -> Result<Json<Vec<ModelView>>> {
    let rows = db::models::list(&state.pool).await?;
    Ok(Json(rows.into_iter().map(ModelView::from_row).collect()))
}

/// One model: architecture, training set size, reconstruction Chamfer summary.
#[utoipa::path(get, path = "/v1/models/{id}", tag = "models",
    params(("id" = String, Path, description = "Model id")),
    responses((status = 200, body = ModelView),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn get_model(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<ModelView>> {
    Ok(Json(ModelView::from_row(load(&state, &id).await?)))
}

/// The model's training shapes with their reconstruction Chamfer distance.
#[utoipa::path(get, path = "/v1/models/{id}/shapes", tag = "models",
    params(("id" = String, Path, description = "Model id")),
    responses((status = 200, body = Vec<TrainingShapeView>),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn list_model_shapes(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<Vec<TrainingShapeView>>> {
    let info = manifest(&load(&state, &id).await?);
    let shapes = info.map(|i| i.training_shapes).unwrap_or_default();
    Ok(Json(shapes.into_iter().map(Into::into).collect()))
}

/// Unregisters a model and removes the files the service made for it (an uploaded model's
/// directory; the bundled model's stays). Refused while cohorts use it.
#[utoipa::path(delete, path = "/v1/models/{id}", tag = "models",
    params(("id" = String, Path, description = "Model id")),
    responses((status = 204, description = "Deleted"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "In use or training")))]
async fn delete_model(State(state): State<AppState>, Path(id): Path<String>) -> Result<StatusCode> {
    let model = load(&state, &id).await?;
    if model.status == ModelStatus::Training {
        return Err(ApiError::Conflict(format!(
            "model {id:?} is still training"
        )));
    }
    if super::refits::is_running(&state, &id).await? {
        return Err(ApiError::Conflict(format!(
            "model {id:?} is being re-fitted; cancel its refit job first"
        )));
    }
    let cohorts = db::models::cohort_count(&state.pool, &id).await?;
    if cohorts > 0 {
        return Err(ApiError::Conflict(format!(
            "model {id:?} is used by {cohorts} cohort(s); delete them first"
        )));
    }
    if db::models::delete(&state.pool, &id).await? {
        remove_model_files(&state.config.storage.models_dir, &model).await;
    }
    Ok(StatusCode::NO_CONTENT)
}

/// Removes a deleted model's directory when the service made it (an upload's
/// `models_dir/<id>`: its inputs, checkpoints and weights), so a new model under the same id
/// starts from nothing; the bundled model's directory stays (it is registered again at the
/// next start). A failure is logged: the row is gone, and the next upload under that id
/// clears what is left.
async fn remove_model_files(models_dir: &std::path::Path, model: &ModelRow) {
    let dir = models_dir.join(&model.model_id);
    if model.model_id == crate::startup::DEFAULT_MODEL_ID
        || std::path::Path::new(&model.dir_path) != dir
    {
        return;
    }
    match tokio::fs::remove_dir_all(&dir).await {
        Ok(()) => tracing::info!(model_id = %model.model_id, "model files removed"),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => tracing::warn!(
            model_id = %model.model_id,
            dir = %dir.display(),
            error = %e,
            "cannot remove a deleted model's files"
        ),
    }
}

async fn load(state: &AppState, id: &str) -> Result<ModelRow> {
    db::models::get(&state.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("model", id))
}
