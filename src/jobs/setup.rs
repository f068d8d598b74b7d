//! What cohorts of a model need before their first shape and the service keeps with the
//! model: the training shapes' measurements, computed once per model (by the first targeted
//! request or job that needs them) and stored in its row; and the novelty reference's
//! training surfaces, computed once per model and resolution and stored one by one, so a
//! restart continues the setup where it stopped instead of starting it again.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::Context;

use super::priority::spawn_background;
use super::{JobContext, JobError, join_error};
use crate::cohort::targets::feasibility::{TrainingAnatomy, measure_training_shapes};
use crate::db;
use crate::engine::Engine;
use crate::formats::mesh_blob;
use crate::sdf::inference::novelty::NoveltyReference;

/// Where a cohort's novelty reference comes from.
pub struct ReferenceSource<'a> {
    /// The model's id.
    pub model_id: &'a str,
    /// The model's directory.
    pub model_dir: &'a Path,
    /// The model's training shapes.
    pub count: usize,
    /// The cohort's resolution.
    pub resolution: usize,
}

/// The novelty reference of a model at a resolution: the engine's own when it holds it,
/// else built from the training surfaces the cohort's setup steps stored (off the executor)
/// and kept by the engine.
pub async fn novelty_reference(
    ctx: &JobContext,
    source: &ReferenceSource<'_>,
) -> Result<Arc<NoveltyReference>, JobError> {
    let ReferenceSource {
        model_id,
        model_dir,
        count,
        resolution,
    } = *source;
    if let Some(reference) = ctx.engine.cached_novelty_reference(model_dir, resolution) {
        return Ok(reference);
    }
    let blobs: BTreeMap<usize, Vec<u8>> =
        db::novelty_surfaces::stored(&ctx.pool, model_id, resolution)
            .await?
            .into_iter()
            .filter_map(|(i, blob)| Some((usize::try_from(i).ok()?, blob)))
            .filter(|(i, _)| *i < count)
            .collect();
    if let Some(missing) = (0..count).find(|i| !blobs.contains_key(i)) {
        let e = anyhow::anyhow!(
            "training shape {missing} at resolution {resolution} is not stored (its setup step has not run)"
        );
        return Err(JobError::Failed(e.context("novelty reference")));
    }
    let (engine, dir) = (ctx.engine.clone(), model_dir.to_path_buf());
    let reference = spawn_background(move || -> anyhow::Result<Arc<NoveltyReference>> {
        let surfaces = blobs
            .values()
            .map(|blob| mesh_blob::decode(blob))
            .collect::<Result<Vec<_>, _>>()
            .context("a stored novelty surface")?;
        engine.novelty_reference_from(&dir, resolution, &surfaces)
    })
    .await
    .map_err(join_error)?
    .context("novelty reference")?;
    Ok(reference)
}

/// One measurement of training shapes at a time: a request and the job it queued (or two
/// first uses) wait for the same result instead of computing it twice.
static MEASURING: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// The model's stored training-shape measurements, when they cover all `count` shapes and
/// were taken by today's method (older ones are measured again and replaced).
pub async fn stored_training_anatomy(
    pool: &db::Pool,
    model_id: &str,
    count: usize,
) -> anyhow::Result<Option<TrainingAnatomy>> {
    let stored = db::models::training_anatomy(pool, model_id).await?;
    Ok(stored.filter(|s| s.shapes.len() == count && s.is_current()))
}

/// The model's training-shape measurements: stored ones, or computed off the executor and
/// stored. The computation runs as its own task, so a caller that stops waiting for it
/// (a request past its wait budget) still leaves the result stored for the next one.
pub async fn training_anatomy(
    pool: &db::Pool,
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
