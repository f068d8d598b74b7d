//! The fit job, one task: the engine fits a latent to an uploaded mesh for a ready model;
//! the anchor row turns `ready` with the latent and its Chamfer distance, or `failed` when
//! the job ends otherwise ([`super::lifecycle::finish_job`]). A fit has no
//! checkpoint: an interrupted one starts again (it is short, and determined by its seed).

use std::time::Duration;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use super::{
    JobContext, JobError, TaskRun, lifecycle, run_with_progress, stopped, stopped_or_failed,
};
use crate::db::{self, jobs::FinalStatus};
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
    run: &TaskRun,
    payload: &FitPayload,
) -> Result<(), JobError> {
    tracing::Span::current().record("model_id", payload.model_id.as_str());
    stopped(&run.flag)?;
    let model = super::existing_model(&ctx.pool, &payload.model_id).await?;
    if let Some(sha) = &payload.spec.mesh_sha256 {
        crate::objects::bundle::ensure_file(&ctx.objects, sha, &payload.spec.mesh_path)
            .await
            .context("the mesh to fit")?;
    }
    let engine = ctx.engine.clone();
    let model_dir = ctx.model_dir(&model).await?;
    let (spec, task_flag) = (payload.spec.clone(), run.flag.clone());
    let fitted = run_with_progress(ctx, run, PROGRESS_INTERVAL, move |steps| {
        engine.fit_anchor(&model_dir, &spec, &task_flag, steps)
    })
    .await?;
    let fitted = fitted.map_err(|e| stopped_or_failed(&run.flag, e.context("fitting")))?;
    fitted.check_finite()?;
    let mut tx = db::begin_write(&ctx.pool).await?;
    db::tasks::complete(&mut tx, &run.lease).await?;
    db::anchors::set_fitted(
        &mut *tx,
        payload.anchor_id,
        &fitted.latent,
        fitted.chamfer,
        &fitted.transform,
    )
    .await?;
    lifecycle::finish_job(&mut tx, run.lease.job_id, FinalStatus::Succeeded, None).await?;
    tx.commit()
        .await
        .context("cannot commit the fitted anchor")?;
    Ok(())
}
