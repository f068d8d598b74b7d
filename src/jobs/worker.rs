//! The worker loop: take jobs until the queue is empty, then sleep until woken (a new job
//! was enqueued), a poll interval passed, or shutdown began.

use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{Notify, watch};

use super::{ExecutionOutcome, JobContext, MAX_STORAGE_BACKOFF, try_execute_job};
use crate::db;

/// Fallback poll interval, for jobs enqueued by another process on the same database.
const POLL_INTERVAL: Duration = Duration::from_secs(5);
/// Pause after an unexpected error (e.g. the database is locked for long).
const ERROR_BACKOFF: Duration = Duration::from_secs(1);

/// Runs jobs until `stop` turns true. Each attempt runs in its own task, so even a panic
/// outside the engine ends that job's attempt, not the worker.
pub async fn run_worker_until_stopped(
    worker: usize,
    ctx: JobContext,
    wake: Arc<Notify>,
    mut stop: watch::Receiver<bool>,
) {
    tracing::info!(worker, "worker started");
    // Grows while storage refuses writes (claims are writes), so a read-only database or a
    // full disk is polled ever more slowly instead of flooding the log.
    let mut storage_backoff = ERROR_BACKOFF;
    while !*stop.borrow() {
        let attempt = tokio::spawn({
            let ctx = ctx.clone();
            async move { try_execute_job(&ctx).await }
        });
        let result = attempt.await;
        if !matches!(&result, Ok(Err(e)) if db::storage_fault_in(e).is_some()) {
            storage_backoff = ERROR_BACKOFF;
        }
        let pause = match result {
            Ok(Ok(ExecutionOutcome::TaskCompleted { .. })) => continue,
            Ok(Ok(ExecutionOutcome::EmptyQueue)) => POLL_INTERVAL,
            Ok(Err(e)) if db::storage_fault_in(&e).is_some() => {
                let pause = storage_backoff;
                tracing::warn!(worker, error = format!("{e:#}"), retry_in = ?pause, "storage cannot take writes");
                storage_backoff = (storage_backoff * 2).min(MAX_STORAGE_BACKOFF);
                pause
            }
            Ok(Err(e)) => {
                tracing::error!(worker, error = format!("{e:#}"), "cannot run a job");
                ERROR_BACKOFF
            }
            Err(e) => {
                tracing::error!(worker, error = %e, "job task panicked");
                ERROR_BACKOFF
            }
        };
        tokio::select! {
            _ = wake.notified() => {}
            _ = tokio::time::sleep(pause) => {}
            _ = stop.changed() => {}
        }
    }
    tracing::info!(worker, "worker stopped");
}
