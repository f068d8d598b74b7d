//! The refit job: a model's training shapes fitted once more with the network frozen, one
//! task per shape, so workers on several machines share the work and an interruption loses
//! at most the shapes in flight. Each task stores its shape's latent with its own result;
//! the job's progress is the shapes stored, and the last task ends the job. A retry plans
//! only the shapes still missing.

use std::collections::HashSet;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use super::{JobContext, JobError, TaskRun, join_error, lifecycle, priority, stopped};
use crate::db::tasks::NewTask;
use crate::db::{self, jobs::FinalStatus, states::TaskKind};
use crate::engine::RefitSpec;

/// The payload of a `refit` job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefitPayload {
    /// The model whose training shapes are re-fitted (its `model_refit` row holds the
    /// settings).
    pub model_id: String,
}

/// One task per training shape without a stored fit.
pub(super) async fn plan(pool: &db::Pool, payload: &RefitPayload) -> anyhow::Result<Vec<NewTask>> {
    let model = super::existing_model(pool, &payload.model_id).await?;
    let count = model
        .info()
        .with_context(|| format!("model {:?} is not trained", model.model_id))?
        .training_shape_count();
    let stored: HashSet<i64> = db::refits::shapes(pool, &model.model_id)
        .await?
        .into_iter()
        .map(|r| r.shape_index)
        .collect();
    Ok((0..count as i64)
        .filter(|i| !stored.contains(i))
        .map(|item| NewTask {
            kind: TaskKind::Refit,
            item,
        })
        .collect())
}

/// Fits one training shape and stores it; the job succeeds with its last shape.
pub(super) async fn shape(
    ctx: &JobContext,
    run: &TaskRun,
    payload: &RefitPayload,
) -> Result<(), JobError> {
    tracing::Span::current().record("model_id", payload.model_id.as_str());
    stopped(&run.flag)?;
    let model = super::existing_model(&ctx.pool, &payload.model_id).await?;
    let refit = db::refits::get(&ctx.pool, &model.model_id)
        .await?
        .with_context(|| format!("model {:?} has no refit", model.model_id))?;
    let spec = RefitSpec {
        iterations: usize::try_from(refit.iterations).context("the stored iterations")?,
        seed: refit.seed as u64,
    };
    let index = usize::try_from(run.lease.item).context("the task's shape index")?;
    let model_dir = ctx.model_dir(&model).await?;
    super::training::ensure_training_inputs(ctx, &model.model_id).await?;
    let engine = ctx.engine.clone();
    let (flag, steps) = (run.flag.clone(), run.progress.clone());
    // The steps go to the task's counter (lease renewals report them, so a long fit is never
    // taken for a stuck one); the job's progress counts stored shapes.
    let fitted = priority::spawn_background(move || {
        engine.refit_training_shape(&model_dir, index, &spec, &flag, &steps)
    })
    .await
    .map_err(join_error)
    .and_then(|r| r)
    .map_err(|e| super::stopped_or_failed(&run.flag, e.context("re-fitting")))?;
    fitted.check_finite()?;
    let job_id = run.lease.job_id;
    let mut tx = db::begin_write(&ctx.pool).await?;
    db::tasks::complete(&mut tx, &run.lease).await?;
    db::refits::insert_shape(&mut tx, &model.model_id, run.lease.item, &fitted).await?;
    let done = db::refits::shape_count(&mut *tx, &model.model_id).await?;
    // Updating the job row locks it, so of two last tasks committing at once the second
    // sees the first's task done (and its shape) from here on.
    db::jobs::set_progress(&mut tx, job_id, done).await?;
    if db::tasks::unfinished_count(&mut tx, job_id, TaskKind::Refit).await? == 0 {
        let done = db::refits::shape_count(&mut *tx, &model.model_id).await?;
        db::jobs::set_progress(&mut tx, job_id, done).await?;
        lifecycle::finish_job(&mut tx, job_id, FinalStatus::Succeeded, None).await?;
    }
    tx.commit()
        .await
        .context("cannot commit the re-fitted shape")?;
    Ok(())
}
