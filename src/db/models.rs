//! The `model` table: the registry of generative models cohorts can be drawn from.

use serde::Serialize;
use sqlx::types::Json;
use sqlx::{SqliteConnection, SqlitePool};

use super::states::ModelStatus;
use crate::cohort::targets::feasibility::TrainingAnatomy;
use crate::engine::ModelInfo;

/// A registered model.
#[derive(Debug, Clone, Serialize, sqlx::FromRow)]
pub struct ModelRow {
    /// Public id (`default` for the bundled model).
    pub model_id: String,
    /// Directory the engine loads it from.
    pub dir_path: String,
    /// Engine-reported facts; null until its training succeeds.
    pub manifest: Json<Option<ModelInfo>>,
    /// Where it stands.
    pub status: ModelStatus,
    /// Registration time.
    pub created_at: String,
}

impl ModelRow {
    /// The engine's facts about the model (none while it trains or after it failed).
    pub fn info(&self) -> Option<&ModelInfo> {
        self.manifest.0.as_ref()
    }
}

/// Registers a model unless the id is taken; returns whether a row was inserted.
pub async fn insert_if_absent(
    conn: &mut SqliteConnection,
    model_id: &str,
    dir_path: &str,
    manifest: Option<&ModelInfo>,
    status: ModelStatus,
) -> sqlx::Result<bool> {
    let done = sqlx::query(
        "insert into model (model_id, dir_path, manifest, status) values (?, ?, ?, ?)
         on conflict (model_id) do nothing",
    )
    .bind(model_id)
    .bind(dir_path)
    .bind(Json(manifest))
    .bind(status)
    .execute(conn)
    .await?;
    Ok(done.rows_affected() == 1)
}

/// Records the outcome of a training job.
pub async fn set_trained(
    pool: &SqlitePool,
    model_id: &str,
    status: ModelStatus,
    manifest: Option<&ModelInfo>,
) -> sqlx::Result<()> {
    sqlx::query(
        "update model set status = ?, manifest = coalesce(?, manifest),
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where model_id = ?",
    )
    .bind(status)
    .bind(manifest.map(Json))
    .bind(model_id)
    .execute(pool)
    .await?;
    Ok(())
}

/// One model by id.
pub async fn get(pool: &SqlitePool, model_id: &str) -> sqlx::Result<Option<ModelRow>> {
    sqlx::query_as(
        "select model_id, dir_path, manifest, status, created_at from model where model_id = ?",
    )
    .bind(model_id)
    .fetch_optional(pool)
    .await
}

/// All models, oldest first.
pub async fn list(pool: &SqlitePool) -> sqlx::Result<Vec<ModelRow>> {
    sqlx::query_as(
        "select model_id, dir_path, manifest, status, created_at from model
         order by created_at, model_id",
    )
    .fetch_all(pool)
    .await
}

/// Number of cohorts drawn from the model (a model in use cannot be deleted).
pub async fn cohort_count(pool: &SqlitePool, model_id: &str) -> sqlx::Result<i64> {
    sqlx::query_scalar("select count(*) from cohort where model_id = ?")
        .bind(model_id)
        .fetch_one(pool)
        .await
}

/// Removes a model row; returns whether it existed.
pub async fn delete(pool: &SqlitePool, model_id: &str) -> sqlx::Result<bool> {
    let done = sqlx::query("delete from model where model_id = ?")
        .bind(model_id)
        .execute(pool)
        .await?;
    Ok(done.rows_affected() == 1)
}

/// The model's stored training-shape measurements, if computed.
pub async fn training_anatomy(
    pool: &SqlitePool,
    model_id: &str,
) -> sqlx::Result<Option<TrainingAnatomy>> {
    let stored: Option<Option<Json<TrainingAnatomy>>> =
        sqlx::query_scalar("select training_anatomy from model where model_id = ?")
            .bind(model_id)
            .fetch_optional(pool)
            .await?;
    Ok(stored.flatten().map(|j| j.0))
}

/// Stores the model's training-shape measurements.
pub async fn set_training_anatomy(
    pool: &SqlitePool,
    model_id: &str,
    measured: &TrainingAnatomy,
) -> sqlx::Result<()> {
    sqlx::query("update model set training_anatomy = ? where model_id = ?")
        .bind(Json(measured))
        .bind(model_id)
        .execute(pool)
        .await?;
    Ok(())
}
