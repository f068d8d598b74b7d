//! The `model` table: the registry of generative models cohorts can be drawn from.

use super::Json;
use serde::Serialize;

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
    /// SHA-256 of the model's bundle in the object store, from which workers on any machine
    /// fetch it; null for a model not published (still training, or no files).
    #[serde(skip_serializing)]
    pub digest: Option<String>,
}

impl ModelRow {
    /// The engine's facts about the model (none while it trains or after it failed).
    pub fn info(&self) -> Option<&ModelInfo> {
        self.manifest.0.as_ref()
    }
}

/// Registers a model unless the id is taken; returns whether a row was inserted.
pub async fn insert_if_absent(
    conn: &mut super::Conn,
    model_id: &str,
    dir_path: &str,
    manifest: Option<&ModelInfo>,
    status: ModelStatus,
) -> sqlx::Result<bool> {
    let done = sqlx::query(
        "insert into model (model_id, dir_path, manifest, status) values ($1, $2, $3, $4)
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
pub async fn set_trained<'e>(
    pool: impl super::Executor<'e>,
    model_id: &str,
    status: ModelStatus,
    manifest: Option<&ModelInfo>,
) -> sqlx::Result<()> {
    sqlx::query(
        "update model set status = $1, manifest = coalesce($2, manifest),
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where model_id = $3",
    )
    .bind(status)
    .bind(manifest.map(Json))
    .bind(model_id)
    .execute(pool)
    .await?;
    Ok(())
}

/// Records the digest of the model's published bundle.
pub async fn set_digest<'e>(
    ex: impl super::Executor<'e>,
    model_id: &str,
    digest: &str,
) -> sqlx::Result<()> {
    sqlx::query("update model set digest = $1 where model_id = $2")
        .bind(digest)
        .bind(model_id)
        .execute(ex)
        .await?;
    Ok(())
}

/// One model by id.
pub async fn get(pool: &super::Pool, model_id: &str) -> sqlx::Result<Option<ModelRow>> {
    sqlx::query_as(
        "select model_id, dir_path, manifest, status, created_at, digest from model
         where model_id = $1",
    )
    .bind(model_id)
    .fetch_optional(pool)
    .await
}

/// All models, oldest first.
pub async fn list(pool: &super::Pool) -> sqlx::Result<Vec<ModelRow>> {
    sqlx::query_as(
        "select model_id, dir_path, manifest, status, created_at, digest from model
         order by created_at, model_id",
    )
    .fetch_all(pool)
    .await
}

/// Number of cohorts drawn from the model (a model in use cannot be deleted).
pub async fn cohort_count(pool: &super::Pool, model_id: &str) -> sqlx::Result<i64> {
    sqlx::query_scalar("select count(*) from cohort where model_id = $1")
        .bind(model_id)
        .fetch_one(pool)
        .await
}

/// Removes a model row; returns whether it existed.
pub async fn delete(pool: &super::Pool, model_id: &str) -> sqlx::Result<bool> {
    let done = sqlx::query("delete from model where model_id = $1")
        .bind(model_id)
        .execute(pool)
        .await?;
    Ok(done.rows_affected() == 1)
}

/// The model's stored training-shape measurements, if computed.
pub async fn training_anatomy(
    pool: &super::Pool,
    model_id: &str,
) -> sqlx::Result<Option<TrainingAnatomy>> {
    let stored: Option<Option<Json<TrainingAnatomy>>> =
        sqlx::query_scalar("select training_anatomy from model where model_id = $1")
            .bind(model_id)
            .fetch_optional(pool)
            .await?;
    Ok(stored.flatten().map(|j| j.0))
}

/// Stores the model's training-shape measurements.
pub async fn set_training_anatomy<'e>(
    pool: impl super::Executor<'e>,
    model_id: &str,
    measured: &TrainingAnatomy,
) -> sqlx::Result<()> {
    sqlx::query("update model set training_anatomy = $1 where model_id = $2")
        .bind(Json(measured))
        .bind(model_id)
        .execute(pool)
        .await?;
    Ok(())
}
