//! A job's life from the queue's side: planned into tasks, started by its first claim, and
//! ended exactly once. Every way a job ends (its last task's result, a task given up, a
//! cancel with no worker left on it, a task that kept killing its workers) goes through
//! [`finish_job`], which also ends what the job worked on (a model left `training`, an
//! anchor left `fitting`) in the same transaction, so no final job leaves its subject
//! behind.

use anyhow::Context;

use super::{Job, JobContext, cohort, refit};
use crate::db::tasks::NewTask;
use crate::db::{
    self,
    jobs::FinalStatus,
    states::{JobStatus, ModelStatus, TaskKind},
};

/// What a cancel request did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CancelOutcome {
    /// No worker held any of its tasks: the job is cancelled now.
    Cancelled,
    /// Workers hold some of its tasks; they stop at their next heartbeat and the last one
    /// to stop cancels the job.
    Requested,
    /// The job had already reached a final state.
    AlreadyFinished,
}

/// Ends a job in `status` unless it has ended already, with everything it works on, inside
/// the caller's transaction: its unfinished tasks are cancelled, and a training's model or
/// a fit's anchor that did not succeed is marked failed. Returns whether the job changed.
pub async fn finish_job(
    conn: &mut db::Conn,
    job_id: i64,
    status: FinalStatus,
    error: Option<&str>,
) -> anyhow::Result<bool> {
    if !db::jobs::finish(conn, job_id, status, error).await? {
        return Ok(false);
    }
    db::tasks::cancel_unfinished(conn, job_id).await?;
    if status == FinalStatus::Succeeded {
        return Ok(true);
    }
    let Some((kind, payload)) = db::jobs::kind_and_payload(conn, job_id).await? else {
        return Ok(true);
    };
    match Job::parse(kind, &payload) {
        Ok(Job::Training(p)) => {
            db::models::set_trained(conn, &p.model_id, ModelStatus::Failed, None).await?;
        }
        Ok(Job::Fit(p)) => {
            let reason = error.unwrap_or("cancelled");
            db::anchors::set_failed(conn, p.anchor_id, reason).await?;
        }
        Ok(Job::Cohort(_) | Job::Validation(_) | Job::Refit(_)) | Err(_) => {}
    }
    Ok(true)
}

/// Cancels a job once no worker holds a live lease on it; returns whether it did. Called
/// in the transaction of a cancel request and by whoever last stops working on the job.
pub async fn settle_cancel(conn: &mut db::Conn, job_id: i64) -> anyhow::Result<bool> {
    if db::tasks::live_count(conn, job_id).await? > 0 {
        return Ok(false);
    }
    finish_job(conn, job_id, FinalStatus::Cancelled, None).await
}

/// A cancel request: a job no worker holds is cancelled at once; otherwise it is flagged,
/// the tasks running in this process are interrupted now and those elsewhere at their
/// next heartbeat.
pub async fn cancel(ctx: &JobContext, job_id: i64) -> anyhow::Result<CancelOutcome> {
    let mut tx = db::begin_write(&ctx.pool).await?;
    let status = db::jobs::request_cancel(&mut tx, job_id).await?;
    if !status.is_some_and(JobStatus::is_pending) {
        return Ok(CancelOutcome::AlreadyFinished);
    }
    let outcome = match settle_cancel(&mut tx, job_id).await? {
        true => CancelOutcome::Cancelled,
        false => CancelOutcome::Requested,
    };
    tx.commit().await?;
    ctx.controls.interrupt(job_id);
    Ok(outcome)
}

/// Turns a queued job without tasks into its tasks (a cohort's setup steps and shapes, a
/// training, a fit). A job that cannot be planned (its cohort or model is gone) fails
/// with the reason.
pub async fn plan(pool: &db::Pool, job_id: i64) -> anyhow::Result<()> {
    let Some(row) = db::jobs::get(pool, job_id).await? else {
        return Ok(());
    };
    if row.status != JobStatus::Queued {
        return Ok(());
    }
    let planned = match Job::parse(row.kind, &row.payload) {
        Ok(Job::Cohort(p)) => cohort::plan(pool, &p).await,
        Ok(Job::Training(_)) => Ok(vec![NewTask::whole(TaskKind::Training)]),
        Ok(Job::Fit(_)) => Ok(vec![NewTask::whole(TaskKind::Fit)]),
        Ok(Job::Validation(_)) => Ok(vec![NewTask::whole(TaskKind::Validation)]),
        Ok(Job::Refit(p)) => refit::plan(pool, &p).await,
        Err(e) => Err(anyhow::anyhow!("bad job payload: {e}")),
    };
    let mut tx = db::begin_write(pool).await?;
    match planned {
        // Everything the job would make exists already (a refit retried after its last
        // shape was stored): it has nothing left to do.
        Ok(tasks) if tasks.is_empty() => {
            finish_job(&mut tx, job_id, FinalStatus::Succeeded, None).await?;
        }
        Ok(tasks) => {
            let added = db::tasks::insert_missing(&mut tx, job_id, &tasks).await?;
            tracing::debug!(job_id, tasks = added, "job planned");
        }
        Err(e) => {
            let message = format!("{:#}", e.context("cannot plan the job"));
            tracing::error!(job_id, error = %message, "job failed");
            finish_job(&mut tx, job_id, FinalStatus::Failed, Some(&message)).await?;
        }
    }
    tx.commit().await.context("cannot store the job's tasks")?;
    Ok(())
}

/// Housekeeping any worker does between claims: tasks that keep killing their workers are
/// failed with their jobs, jobs flagged for cancellation that no worker holds any more
/// are cancelled, and queued jobs without tasks (a submitter that stopped before planning
/// them, a job queued by an older version) are planned.
pub async fn maintain(ctx: &JobContext, max_stalls: i64) -> anyhow::Result<()> {
    for (job_id, error) in db::tasks::fail_stalled(&ctx.pool, max_stalls).await? {
        let mut tx = db::begin_write(&ctx.pool).await?;
        if finish_job(&mut tx, job_id, FinalStatus::Failed, Some(&error)).await? {
            tracing::error!(job_id, error, "job failed");
        }
        tx.commit().await?;
    }
    for job_id in db::jobs::cancel_requested_pending(&ctx.pool).await? {
        let mut tx = db::begin_write(&ctx.pool).await?;
        if settle_cancel(&mut tx, job_id).await? {
            tracing::info!(job_id, "job cancelled");
        }
        tx.commit().await?;
    }
    for job_id in db::tasks::unplanned_jobs(&ctx.pool, 16).await? {
        plan(&ctx.pool, job_id).await?;
    }
    Ok(())
}
