//! The worker loop: take tasks until none is claimable, then sleep until woken (a job was
//! enqueued in this process), a poll interval passed (work queued by another process, a
//! lease that expired), or shutdown began.

use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{Notify, watch};

use super::{AbortOnDrop, ExecutionOutcome, JobContext, MAX_STORAGE_BACKOFF, try_execute_job};
use crate::db;

/// Poll interval when idle: jobs enqueued by another process, leases that expired.
const POLL_INTERVAL: Duration = Duration::from_secs(1);
/// Pause after an unexpected error (e.g. the database is locked for long).
const ERROR_BACKOFF: Duration = Duration::from_secs(1);

/// Runs tasks as worker `worker` of this process until `stop` turns true. Each attempt runs
/// in its own task, so even a panic outside the engine ends that attempt, not the worker.
pub async fn run_worker_until_stopped(
    worker: usize,
    ctx: JobContext,
    wake: Arc<Notify>,
    mut stop: watch::Receiver<bool>,
) {
    let ctx = ctx.for_worker(worker);
    tracing::info!(worker, owner = ctx.owner, "worker started");
    // Grows while storage refuses writes (claims are writes), so a read-only database or a
    // full disk is polled ever more slowly instead of flooding the log.
    let mut storage_backoff = ERROR_BACKOFF;
    // The job of the last task this worker ran: if shutdown comes between two of its tasks,
    // it shows as queued rather than running.
    let mut last_job = None;
    while !*stop.borrow() {
        let attempt = AbortOnDrop(tokio::spawn({
            let ctx = ctx.clone();
            async move { try_execute_job(&ctx).await }
        }));
        let result = attempt.await;
        if !matches!(&result, Ok(Err(e)) if db::storage_fault_in(e).is_some()) {
            storage_backoff = ERROR_BACKOFF;
        }
        let pause = match result {
            Ok(Ok(ExecutionOutcome::TaskCompleted { job_id, .. })) => {
                last_job = Some(job_id);
                continue;
            }
            Ok(Ok(ExecutionOutcome::EmptyQueue)) => POLL_INTERVAL,
            Ok(Err(e)) if db::storage_fault_in(&e).is_some() => {
                let pause = storage_backoff;
                tracing::warn!(worker, error = format!("{e:#}"), retry_in = ?pause, "storage cannot take writes");
                storage_backoff = (storage_backoff * 2).min(MAX_STORAGE_BACKOFF);
                pause
            }
            Ok(Err(e)) => {
                tracing::error!(worker, error = format!("{e:#}"), "cannot run a task");
                ERROR_BACKOFF
            }
            Err(e) => {
                tracing::error!(worker, error = %e, "task run panicked");
                ERROR_BACKOFF
            }
        };
        tokio::select! {
            _ = wake.notified() => {}
            _ = tokio::time::sleep(pause) => {}
            _ = stop.changed() => {}
        }
    }
    if let Some(job_id) = last_job
        && let Err(e) = queue_if_idle(&ctx, job_id).await
    {
        tracing::warn!(worker, job_id, error = %e, "cannot show the job as queued");
    }
    tracing::info!(worker, "worker stopped");
}

async fn queue_if_idle(ctx: &JobContext, job_id: i64) -> sqlx::Result<()> {
    let mut tx = db::begin_write(&ctx.pool).await?;
    db::jobs::queue_if_idle(&mut tx, job_id).await?;
    tx.commit().await
}
