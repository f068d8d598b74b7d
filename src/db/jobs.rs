//! The `job` table: a small durable queue. Enqueue inside the caller's transaction, claim
//! the oldest queued row atomically, record progress and the final state.

use serde::Serialize;
use sqlx::{SqliteConnection, SqlitePool};

use super::states::{JobKind, JobStatus};

/// A job row as the API reports it.
#[derive(Debug, Clone, Serialize, sqlx::FromRow)]
pub struct JobRow {
    /// Primary key.
    pub job_id: i64,
    /// What it does.
    pub kind: JobKind,
    /// JSON payload.
    pub payload: String,
    /// Where it stands.
    pub status: JobStatus,
    /// How many times a worker claimed it.
    pub attempts: i64,
    /// Units of work done.
    pub progress_done: i64,
    /// Units of work in total.
    pub progress_total: i64,
    /// Whether a cancel was requested.
    pub cancel_requested: bool,
    /// The last error chain.
    pub error: Option<String>,
    /// When it was enqueued.
    pub created_at: String,
    /// When a worker first claimed it.
    pub started_at: Option<String>,
    /// When it reached a final state.
    pub finished_at: Option<String>,
}

/// A job a worker has just claimed.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct ClaimedJob {
    /// Primary key.
    pub job_id: i64,
    /// What it does.
    pub kind: JobKind,
    /// JSON payload (typed by [`crate::jobs::Job`]).
    pub payload: String,
    /// Claims so far, this one included.
    pub attempts: i64,
}

/// The final states a worker can record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FinalStatus {
    /// All work done.
    Succeeded,
    /// Gave up with an error.
    Failed,
    /// Stopped on request.
    Cancelled,
}

impl FinalStatus {
    /// The `status` column value.
    pub fn status(self) -> JobStatus {
        match self {
            Self::Succeeded => JobStatus::Succeeded,
            Self::Failed => JobStatus::Failed,
            Self::Cancelled => JobStatus::Cancelled,
        }
    }
}

/// Adds a queued job inside the caller's transaction and returns its id (only
/// [`crate::jobs::queue`] calls it, with a typed payload).
pub async fn enqueue(
    conn: &mut SqliteConnection,
    kind: JobKind,
    payload: &str,
    progress_total: i64,
) -> sqlx::Result<i64> {
    let job_id = super::ids::allocate(&mut *conn, super::ids::IdKind::Job).await?;
    sqlx::query_scalar(
        "insert into job (job_id, kind, payload, progress_total) values (?, ?, ?, ?)
         returning job_id",
    )
    .bind(job_id)
    .bind(kind)
    .bind(payload)
    .bind(progress_total)
    .fetch_one(conn)
    .await
}

/// Atomically marks the oldest queued job as running and returns it (None when idle).
/// One statement, so two workers can never claim the same row.
pub async fn claim_next(pool: &SqlitePool) -> sqlx::Result<Option<ClaimedJob>> {
    sqlx::query_as(
        "update job set status = 'running', attempts = attempts + 1,
             claim_progress = progress_done, claim_setup = setup_done,
             started_at = coalesce(started_at, strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = (select job_id from job where status = 'queued' order by job_id limit 1)
         returning job_id, kind, payload, attempts",
    )
    .fetch_optional(pool)
    .await
}

/// At startup: jobs left `running` by a stopped process go back to the queue. An
/// interrupted run that committed progress (`progress_done` or its stored setup,
/// `setup_done`, grew since the claim) clears the job's stall count; one that did not adds to it, and a job stalled `max_attempts` times in
/// a row fails, so a job that keeps killing the process cannot loop forever while a long
/// job on a host that is restarted often still finishes. Returns (re-queued, failed).
pub async fn requeue_interrupted(pool: &SqlitePool, max_attempts: i64) -> sqlx::Result<(u64, u64)> {
    let mut tx = pool.begin_with(super::BEGIN_WRITE).await?;
    sqlx::query(
        "update job set stalled_attempts = case when progress_done > claim_progress
                                                     or setup_done > claim_setup then 0
                                                else stalled_attempts + 1 end
         where status = 'running'",
    )
    .execute(&mut *tx)
    .await?;
    let failed = sqlx::query(
        "update job set status = 'failed', cancel_requested = 0,
             error = 'interrupted ' || stalled_attempts ||
                     ' times in a row without progress; not retried again',
             finished_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now'),
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where status = 'running' and stalled_attempts >= ?",
    )
    .bind(max_attempts)
    .execute(&mut *tx)
    .await?
    .rows_affected();
    let requeued = sqlx::query(
        "update job set status = case when cancel_requested = 1 then 'cancelled' else 'queued' end,
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where status = 'running'",
    )
    .execute(&mut *tx)
    .await?
    .rows_affected();
    tx.commit().await?;
    Ok((requeued, failed))
}

/// Puts a failed or cancelled job back in the queue (inside the caller's transaction, the
/// one [`crate::jobs::Submission`] opened), its attempt and stall counts cleared; returns
/// whether it was in such a state.
pub async fn requeue_finished(conn: &mut SqliteConnection, job_id: i64) -> sqlx::Result<bool> {
    let done = sqlx::query(
        "update job set status = 'queued', cancel_requested = 0, error = null,
             finished_at = null, attempts = 0, stalled_attempts = 0,
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = ? and status in ('failed', 'cancelled')",
    )
    .bind(job_id)
    .execute(conn)
    .await?;
    Ok(done.rows_affected() == 1)
}

/// Puts a running job back in the queue (graceful shutdown in the middle of it).
pub async fn release(pool: &SqlitePool, job_id: i64) -> sqlx::Result<()> {
    sqlx::query(
        "update job set status = 'queued', updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = ? and status = 'running'",
    )
    .bind(job_id)
    .execute(pool)
    .await?;
    Ok(())
}

/// Records a running job's final state.
pub async fn finish(
    pool: &SqlitePool,
    job_id: i64,
    status: FinalStatus,
    error: Option<&str>,
) -> sqlx::Result<()> {
    sqlx::query(
        "update job set status = ?, error = ?,
             finished_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now'),
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = ?",
    )
    .bind(status.status())
    .bind(error)
    .bind(job_id)
    .execute(pool)
    .await?;
    Ok(())
}

/// Sets the progress counters (inside the transaction that committed the unit of work).
pub async fn set_progress(conn: &mut SqliteConnection, job_id: i64, done: i64) -> sqlx::Result<()> {
    sqlx::query(
        "update job set progress_done = ?, updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = ?",
    )
    .bind(done)
    .bind(job_id)
    .execute(conn)
    .await?;
    Ok(())
}

/// What a cancel request did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CancelOutcome {
    /// The job was still queued and is now cancelled.
    CancelledWhileQueued,
    /// The job is running; its worker will stop at the next check.
    Requested,
    /// The job had already reached a final state.
    AlreadyFinished,
}

/// Cancels a queued job at once, or flags a running one for its worker.
pub async fn request_cancel(pool: &SqlitePool, job_id: i64) -> sqlx::Result<CancelOutcome> {
    let queued = sqlx::query(
        "update job set status = 'cancelled', cancel_requested = 1,
             finished_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now'),
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = ? and status = 'queued'",
    )
    .bind(job_id)
    .execute(pool)
    .await?;
    if queued.rows_affected() == 1 {
        return Ok(CancelOutcome::CancelledWhileQueued);
    }
    let running = sqlx::query(
        "update job set cancel_requested = 1, updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = ? and status = 'running'",
    )
    .bind(job_id)
    .execute(pool)
    .await?;
    Ok(if running.rows_affected() == 1 {
        CancelOutcome::Requested
    } else {
        CancelOutcome::AlreadyFinished
    })
}

/// Whether a cancel was requested for the job (checked by workers between units of work).
pub async fn is_cancel_requested(pool: &SqlitePool, job_id: i64) -> sqlx::Result<bool> {
    let flag: Option<bool> =
        sqlx::query_scalar("select cancel_requested from job where job_id = ?")
            .bind(job_id)
            .fetch_optional(pool)
            .await?;
    Ok(flag.unwrap_or(true))
}

/// One job by id.
pub async fn get(pool: &SqlitePool, job_id: i64) -> sqlx::Result<Option<JobRow>> {
    sqlx::query_as(
        "select job_id, kind, payload, status, attempts, progress_done, progress_total,
                cancel_requested, error, created_at, started_at, finished_at
         from job where job_id = ?",
    )
    .bind(job_id)
    .fetch_optional(pool)
    .await
}

/// Jobs waiting or running: the queue length that bounds new submissions.
pub async fn count_pending<'e>(ex: impl sqlx::SqliteExecutor<'e>) -> sqlx::Result<i64> {
    sqlx::query_scalar("select count(*) from job where status in ('queued', 'running')")
        .fetch_one(ex)
        .await
}

/// Number of jobs in each state (for /metrics).
pub async fn count_by_status(pool: &SqlitePool) -> sqlx::Result<Vec<(JobStatus, i64)>> {
    sqlx::query_as("select status, count(*) from job group by status order by status")
        .fetch_all(pool)
        .await
}

/// Deletes a job row (after its cohort was deleted).
pub async fn delete(conn: &mut SqliteConnection, job_id: i64) -> sqlx::Result<()> {
    sqlx::query("delete from job where job_id = ?")
        .bind(job_id)
        .execute(conn)
        .await?;
    Ok(())
}
