//! The fit job: the engine fits a latent to an uploaded mesh for a ready model; the anchor
//! row turns `ready` with the latent and its Chamfer distance, or `failed`. A fit has no
//! checkpoint: an interrupted one starts again (it is short, and determined by its seed).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use super::engine::FitSpec;
use super::{JobContext, RunOutcome, run_with_progress, stop_outcome};
use crate::db::{self, jobs::ClaimedJob};

/// The payload of a `fit` job.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FitPayload {
    /// The anchor row being fitted.
    pub anchor_id: i64,
    /// Its model.
    pub model_id: String,
    /// What the engine gets.
    pub spec: FitSpec,
}

/// How often the steps done are copied to the job row.
const PROGRESS_INTERVAL: Duration = Duration::from_millis(500);

pub(super) async fn run(
    ctx: &JobContext,
    job: &ClaimedJob,
    flag: &Arc<AtomicBool>,
) -> anyhow::Result<RunOutcome> {
    let payload: FitPayload = serde_json::from_str(&job.payload).context("bad job payload")?;
    tracing::Span::current().record("model_id", payload.model_id.as_str());
    let anchor_id = payload.anchor_id;
    if let Some(stop) = stop_outcome(ctx, job.job_id, flag).await? {
        return finish(ctx, anchor_id, stop).await;
    }
    let Some(model) = db::models::get(&ctx.pool, &payload.model_id).await? else {
        let message = format!("model {:?} no longer exists", payload.model_id);
        return finish(ctx, anchor_id, RunOutcome::Failed(message)).await;
    };
    let engine = ctx.engine.clone();
    let model_dir = PathBuf::from(&model.dir_path);
    let (spec, task_flag) = (payload.spec.clone(), flag.clone());
    let fitted = run_with_progress(ctx, job.job_id, PROGRESS_INTERVAL, move |steps| {
        engine.fit_anchor(&model_dir, &spec, &task_flag, steps)
    })
    .await?;
    match fitted {
        Ok(fitted) => {
            anyhow::ensure!(
                fitted.chamfer.is_finite() && fitted.latent.iter().all(|v| v.is_finite()),
                "the engine returned a non-finite latent or Chamfer distance"
            );
            db::anchors::set_fitted(
                &ctx.pool,
                anchor_id,
                &fitted.latent,
                fitted.chamfer,
                &fitted.transform,
            )
            .await?;
            Ok(RunOutcome::Succeeded)
        }
        Err(e) if db::storage_fault_in(&e).is_some() => Err(e.context("fitting")),
        Err(e) => {
            let outcome = match stop_outcome(ctx, job.job_id, flag).await? {
                Some(stop) => stop,
                None => RunOutcome::Failed(format!("fitting: {e:#}")),
            };
            finish(ctx, anchor_id, outcome).await
        }
    }
}

/// Marks the anchor of a job cancelled before it ran.
pub(super) async fn finish_cancelled(ctx: &JobContext, payload: &str) -> anyhow::Result<()> {
    let payload: FitPayload = serde_json::from_str(payload).context("bad job payload")?;
    finish(ctx, payload.anchor_id, RunOutcome::Cancelled).await?;
    Ok(())
}

/// Marks the anchor according to a run that did not succeed (a released job stays
/// `fitting` and runs again).
async fn finish(
    ctx: &JobContext,
    anchor_id: i64,
    outcome: RunOutcome,
) -> anyhow::Result<RunOutcome> {
    match &outcome {
        RunOutcome::Released => {}
        RunOutcome::Failed(e) => db::anchors::set_failed(&ctx.pool, anchor_id, e).await?,
        _ => db::anchors::set_failed(&ctx.pool, anchor_id, "cancelled").await?,
    }
    Ok(outcome)
}
