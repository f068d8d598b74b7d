//! The `model` table: the registry of generative models cohorts can be drawn from.

use serde::Serialize;
use sqlx::{SqliteConnection, SqlitePool};

/// A registered model.
#[derive(Debug, Clone, Serialize, sqlx::FromRow)]
pub struct ModelRow {
    /// Public id (`default` for the bundled model).
    pub model_id: String,
    /// Directory the engine loads it from.
    pub dir_path: String,
    /// Engine-reported facts as JSON ([`crate::jobs::engine::ModelInfo`]).
    pub manifest: String,
    /// training | ready | failed.
    pub status: String,
    /// Registration time.
    pub created_at: String,
}

/// Registers a model unless the id is taken; returns whether a row was inserted.
pub async fn insert_if_absent(
    conn: &mut SqliteConnection,
    model_id: &str,
    dir_path: &str,
    manifest: &serde_json::Value,
    status: &str,
) -> sqlx::Result<bool> {
    let done = sqlx::query(
        "insert into model (model_id, dir_path, manifest, status) values (?, ?, ?, ?)
         on conflict (model_id) do nothing",
    )
    .bind(model_id)
    .bind(dir_path)
    .bind(manifest.to_string())
    .bind(status)
    .execute(conn)
    .await?;
    Ok(done.rows_affected() == 1)
}

/// Records the outcome of a training job.
pub async fn set_trained(
    pool: &SqlitePool,
    model_id: &str,
    status: &str,
    manifest: Option<&serde_json::Value>,
) -> sqlx::Result<()> {
    sqlx::query(
        "update model set status = ?, manifest = coalesce(?, manifest),
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where model_id = ?",
    )
    .bind(status)
    .bind(manifest.map(|m| m.to_string()))
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

/// The model's stored training-shape measurements (JSON), if computed.
pub async fn training_anatomy(pool: &SqlitePool, model_id: &str) -> sqlx::Result<Option<String>> {
    sqlx::query_scalar("select training_anatomy from model where model_id = ?")
        .bind(model_id)
        .fetch_optional(pool)
        .await
        .map(Option::flatten)
}

/// Stores the model's training-shape measurements (JSON).
pub async fn set_training_anatomy(
    pool: &SqlitePool,
    model_id: &str,
    json: &str,
) -> sqlx::Result<()> {
    sqlx::query("update model set training_anatomy = ? where model_id = ?")
        .bind(json)
        .bind(model_id)
        .execute(pool)
        .await?;
    Ok(())
}
