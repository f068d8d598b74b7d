//! The training job: the engine trains a model from uploaded meshes; the model row turns
//! `ready` with the engine's manifest, or `failed`.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use super::engine::TrainingSpec;
use super::{JobContext, RunOutcome, run_with_progress, stop_outcome};
use crate::db::{self, jobs::ClaimedJob};

/// The payload of a `training` job.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TrainingPayload {
    /// The model row being trained.
    pub model_id: String,
    /// What the engine gets.
    pub spec: TrainingSpec,
}

pub(super) async fn run(
    ctx: &JobContext,
    job: &ClaimedJob,
    flag: &Arc<AtomicBool>,
) -> anyhow::Result<RunOutcome> {
    let payload: TrainingPayload = serde_json::from_str(&job.payload).context("bad job payload")?;
    tracing::Span::current().record("model_id", payload.model_id.as_str());
    if let Some(stop) = stop_outcome(ctx, job.job_id, flag).await? {
        return finish(ctx, &payload.model_id, stop).await;
    }
    let engine = ctx.engine.clone();
    let (spec, task_flag) = (payload.spec.clone(), flag.clone());
    // Saved epochs are the training job's progress: recovery after a killed process
    // compares them with the progress at the claim to tell a slow job from a stuck one.
    let trained = run_with_progress(ctx, job.job_id, PROGRESS_INTERVAL, move |saved| {
        engine.train_model(&spec, &task_flag, saved)
    })
    .await?;
    match trained {
        Ok(info) => {
            let manifest = serde_json::to_value(&info)?;
            db::models::set_trained(&ctx.pool, &payload.model_id, "ready", Some(&manifest)).await?;
            Ok(RunOutcome::Succeeded)
        }
        Err(e) if db::storage_fault_in(&e).is_some() => Err(e.context("training")),
        Err(e) => {
            let outcome = match stop_outcome(ctx, job.job_id, flag).await? {
                Some(stop) => stop,
                None => RunOutcome::Failed(format!("training: {e:#}")),
            };
            finish(ctx, &payload.model_id, outcome).await
        }
    }
}

/// How often the saved epochs of a running training are copied to the job row.
const PROGRESS_INTERVAL: Duration = Duration::from_secs(1);

/// Marks the model of a job cancelled before it ran.
pub(super) async fn finish_cancelled(ctx: &JobContext, payload: &str) -> anyhow::Result<()> {
    let payload: TrainingPayload = serde_json::from_str(payload).context("bad job payload")?;
    finish(ctx, &payload.model_id, RunOutcome::Cancelled).await?;
    Ok(())
}

/// Marks the model according to a run that did not succeed.
async fn finish(
    ctx: &JobContext,
    model_id: &str,
    outcome: RunOutcome,
) -> anyhow::Result<RunOutcome> {
    if outcome != RunOutcome::Released {
        db::models::set_trained(&ctx.pool, model_id, "failed", None).await?;
    }
    Ok(outcome)
}
