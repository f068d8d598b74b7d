//! The fit job: the engine fits a latent to an uploaded mesh for a ready model; the anchor
//! row turns `ready` with the latent and its Chamfer distance, or `failed`. A fit has no
//! checkpoint: an interrupted one starts again (it is short, and determined by its seed).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use super::{JobContext, JobError, RunOutcome, run_with_progress, stopped, stopped_or_failed};
use crate::db;
use crate::engine::FitSpec;

/// The payload of a `fit` job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
    job_id: i64,
    payload: &FitPayload,
    flag: &Arc<AtomicBool>,
) -> Result<(), JobError> {
    tracing::Span::current().record("model_id", payload.model_id.as_str());
    stopped(flag)?;
    let model = db::models::get(&ctx.pool, &payload.model_id)
        .await?
        .with_context(|| format!("model {:?} no longer exists", payload.model_id))?;
    let engine = ctx.engine.clone();
    let model_dir = PathBuf::from(&model.dir_path);
    let (spec, task_flag) = (payload.spec.clone(), flag.clone());
    let fitted = run_with_progress(ctx, job_id, PROGRESS_INTERVAL, move |steps| {
        engine.fit_anchor(&model_dir, &spec, &task_flag, steps)
    })
    .await?;
    let fitted = fitted.map_err(|e| stopped_or_failed(flag, e.context("fitting")))?;
    if !(fitted.chamfer.is_finite() && fitted.latent.iter().all(|v| v.is_finite())) {
        let e = anyhow::anyhow!("the engine returned a non-finite latent or Chamfer distance");
        return Err(e.into());
    }
    db::anchors::set_fitted(
        &ctx.pool,
        payload.anchor_id,
        &fitted.latent,
        fitted.chamfer,
        &fitted.transform,
    )
    .await?;
    Ok(())
}

/// Marks the anchor failed when its fit ended without success (a released job stays
/// `fitting` and runs again).
pub(super) async fn finish(
    ctx: &JobContext,
    payload: &FitPayload,
    outcome: &RunOutcome,
) -> anyhow::Result<()> {
    let reason = match outcome {
        RunOutcome::Failed(e) => e.as_str(),
        RunOutcome::Cancelled => "cancelled",
        _ => return Ok(()),
    };
    db::anchors::set_failed(&ctx.pool, payload.anchor_id, reason).await?;
    Ok(())
}
