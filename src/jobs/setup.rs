//! What cohorts of a model need before their first shape and the service keeps with the
//! model: the training shapes' measurements, computed once per model (by the first targeted
//! request or job that needs them) and stored in its row.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use sqlx::SqlitePool;

use super::join_error;
use super::priority::spawn_background;
use crate::cohort::targets::feasibility::{TrainingAnatomy, measure_training_shapes};
use crate::db;
use crate::engine::Engine;

/// One measurement of training shapes at a time: a request and the job it queued (or two
/// first uses) wait for the same result instead of computing it twice.
static MEASURING: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// The model's stored training-shape measurements, when they cover all `count` shapes.
pub async fn stored_training_anatomy(
    pool: &SqlitePool,
    model_id: &str,
    count: usize,
) -> anyhow::Result<Option<TrainingAnatomy>> {
    let stored = db::models::training_anatomy(pool, model_id).await?;
    Ok(stored.filter(|s| s.shapes.len() == count))
}

/// The model's training-shape measurements: stored ones, or computed off the executor and
/// stored. The computation runs as its own task, so a caller that stops waiting for it
/// (a request past its wait budget) still leaves the result stored for the next one.
pub async fn training_anatomy(
    pool: &SqlitePool,
    engine: Arc<dyn Engine>,
    model_id: &str,
    model_dir: &Path,
    count: usize,
) -> anyhow::Result<TrainingAnatomy> {
    if let Some(stored) = stored_training_anatomy(pool, model_id, count).await? {
        return Ok(stored);
    }
    let (pool, model_id, dir) = (pool.clone(), model_id.to_owned(), model_dir.to_path_buf());
    let task = async move {
        let _one_at_a_time = MEASURING.lock().await;
        if let Some(stored) = stored_training_anatomy(&pool, &model_id, count).await? {
            return Ok(stored);
        }
        let measured = spawn_background(move || {
            measure_training_shapes(&*engine, &dir, count, &AtomicBool::new(false))
        })
        .await
        .map_err(join_error)??;
        db::models::set_training_anatomy(&pool, &model_id, &measured).await?;
        tracing::info!(model_id, count, "training shapes measured");
        Ok(measured)
    };
    tokio::spawn(tracing::Instrument::in_current_span(task))
        .await
        .map_err(join_error)?
}
