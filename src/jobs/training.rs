//! The training job: the engine trains a model from uploaded meshes; the model row turns
//! `ready` with the engine's manifest, or `failed`.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::{JobContext, JobError, RunOutcome, run_with_progress, stopped, stopped_or_failed};
use crate::db::{self, states::ModelStatus};
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
    job_id: i64,
    payload: &TrainingPayload,
    flag: &Arc<AtomicBool>,
) -> Result<(), JobError> {
    tracing::Span::current().record("model_id", payload.model_id.as_str());
    stopped(flag)?;
    let engine = ctx.engine.clone();
    let (spec, task_flag) = (payload.spec.clone(), flag.clone());
    // Saved epochs are the training job's progress: recovery after a killed process
    // compares them with the progress at the claim to tell a slow job from a stuck one.
    let trained = run_with_progress(ctx, job_id, PROGRESS_INTERVAL, move |saved| {
        engine.train_model(&spec, &task_flag, saved)
    })
    .await?;
    let info = trained.map_err(|e| stopped_or_failed(flag, e.context("training")))?;
    db::models::set_trained(
        &ctx.pool,
        &payload.model_id,
        ModelStatus::Ready,
        Some(&info),
    )
    .await?;
    Ok(())
}

/// How often the saved epochs of a running training are copied to the job row.
const PROGRESS_INTERVAL: Duration = Duration::from_secs(1);

/// Marks the model failed when its training ended without success.
pub(super) async fn finish(
    ctx: &JobContext,
    payload: &TrainingPayload,
    outcome: &RunOutcome,
) -> anyhow::Result<()> {
    if matches!(outcome, RunOutcome::Cancelled | RunOutcome::Failed(_)) {
        db::models::set_trained(&ctx.pool, &payload.model_id, ModelStatus::Failed, None).await?;
    }
    Ok(())
}
