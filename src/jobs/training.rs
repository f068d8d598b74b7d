//! The training job, one task: the engine trains a model from uploaded meshes; the model
//! row turns `ready` with the engine's manifest, or `failed` when the job ends otherwise
//! ([`super::lifecycle::finish_job`]).

use std::time::Duration;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use super::{
    JobContext, JobError, TaskRun, lifecycle, run_with_progress, stopped, stopped_or_failed,
};
use crate::db::{self, jobs::FinalStatus, states::ModelStatus};
use crate::engine::TrainingSpec;

/// The payload of a `training` job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingPayload {
    /// The model row being trained.
    pub model_id: String,
    /// What the engine gets.
    pub spec: TrainingSpec,
}

pub(super) async fn run(
    ctx: &JobContext,
    run: &TaskRun,
    payload: &TrainingPayload,
) -> Result<(), JobError> {
    tracing::Span::current().record("model_id", payload.model_id.as_str());
    stopped(&run.flag)?;
    if let Some(digest) = &payload.spec.input_digest {
        crate::objects::bundle::ensure_unpacked(&ctx.objects, digest, &payload.spec.input_dir)
            .await
            .context("the training inputs")?;
    }
    let engine = ctx.engine.clone();
    let (spec, task_flag) = (payload.spec.clone(), run.flag.clone());
    // Saved epochs are the training's progress: lease renewals report them, so a training
    // interrupted often but saving checkpoints is never given up as stuck.
    let trained = run_with_progress(ctx, run, PROGRESS_INTERVAL, move |saved| {
        engine.train_model(&spec, &task_flag, saved)
    })
    .await?;
    let info = trained.map_err(|e| stopped_or_failed(&run.flag, e.context("training")))?;
    // Published before the row turns ready, so every machine can fetch what it names.
    let digest = crate::objects::bundle::publish(&ctx.objects, &payload.spec.model_dir)
        .await
        .context("cannot publish the trained model")?;
    let mut tx = db::begin_write(&ctx.pool).await?;
    db::tasks::complete(&mut tx, &run.lease).await?;
    db::models::set_trained(&mut *tx, &payload.model_id, ModelStatus::Ready, Some(&info)).await?;
    if let Some(digest) = &digest {
        db::models::set_digest(&mut *tx, &payload.model_id, digest).await?;
    }
    lifecycle::finish_job(&mut tx, run.lease.job_id, FinalStatus::Succeeded, None).await?;
    tx.commit()
        .await
        .context("cannot commit the trained model")?;
    Ok(())
}

/// How often the saved epochs of a running training are copied to the job row.
const PROGRESS_INTERVAL: Duration = Duration::from_secs(1);

/// Makes the uploaded training meshes of a model the service trained readable on this
/// machine at the path its manifest names, fetching them from the object store when this
/// machine lacks them (the upload reached another machine's API): a refit or a validation
/// against the model's own shapes reads them. Models the service did not train (the
/// bundled one, or one registered from a directory) are left alone.
pub(super) async fn ensure_training_inputs(ctx: &JobContext, model_id: &str) -> anyhow::Result<()> {
    for payload in db::jobs::training_payloads(&ctx.pool).await? {
        let Ok(training) = serde_json::from_str::<TrainingPayload>(&payload) else {
            continue;
        };
        if training.model_id != model_id {
            continue;
        }
        if let Some(digest) = &training.spec.input_digest {
            crate::objects::bundle::ensure_unpacked(&ctx.objects, digest, &training.spec.input_dir)
                .await
                .context("the model's training inputs")?;
        }
        return Ok(());
    }
    Ok(())
}
