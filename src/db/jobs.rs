//! The `job` table: a small durable queue. Enqueue inside the caller's transaction, claim
//! the oldest queued row atomically, record progress and the final state.

use serde::Serialize;

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
    pub cancel_requested: super::Flag,
    /// The last error chain.
    pub error: Option<String>,
    /// When it was enqueued.
    pub created_at: String,
    /// When a worker first claimed it.
    pub started_at: Option<String>,
    /// When it reached a final state.
    pub finished_at: Option<String>,
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
    conn: &mut super::Conn,
    kind: JobKind,
    payload: &str,
    progress_total: i64,
) -> sqlx::Result<i64> {
    let job_id = super::ids::allocate(&mut *conn, super::ids::IdKind::Job).await?;
    sqlx::query_scalar(
        "insert into job (job_id, kind, payload, progress_total) values ($1, $2, $3, $4)
         returning job_id",
    )
    .bind(job_id)
    .bind(kind)
    .bind(payload)
    .bind(progress_total)
    .fetch_one(conn)
    .await
}

/// Marks a queued job running (its first task was claimed) and counts the start.
pub async fn start(conn: &mut super::Conn, job_id: i64) -> sqlx::Result<()> {
    sqlx::query(
        "update job set status = 'running', attempts = attempts + 1,
             started_at = coalesce(started_at, strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = $1 and status = 'queued'",
    )
    .bind(job_id)
    .execute(conn)
    .await?;
    Ok(())
}

/// A running job none of whose tasks is held any more goes back to `queued` (its tasks
/// were given back at shutdown), so it shows as waiting, not as running.
pub async fn queue_if_idle(conn: &mut super::Conn, job_id: i64) -> sqlx::Result<()> {
    sqlx::query(
        "update job set status = 'queued', updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = $1 and status = 'running'
           and not exists (select 1 from task where task.job_id = job.job_id
                               and task.status = 'running')",
    )
    .bind(job_id)
    .execute(conn)
    .await?;
    Ok(())
}

/// Puts a failed or cancelled job back in the queue (inside the caller's transaction, the
/// one [`crate::jobs::Submission`] opened); returns whether it was in such a state.
pub async fn requeue_finished(conn: &mut super::Conn, job_id: i64) -> sqlx::Result<bool> {
    let done = sqlx::query(
        "update job set status = 'queued', cancel_requested = 0, error = null, attempts = 0,
             finished_at = null,
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = $1 and status in ('failed', 'cancelled')",
    )
    .bind(job_id)
    .execute(conn)
    .await?;
    Ok(done.rows_affected() == 1)
}

/// Records a job's final state unless it has one already; returns whether it changed (the
/// caller then ends what the job worked on, in the same transaction).
pub async fn finish(
    conn: &mut super::Conn,
    job_id: i64,
    status: FinalStatus,
    error: Option<&str>,
) -> sqlx::Result<bool> {
    let done = sqlx::query(
        "update job set status = $1, error = $2,
             finished_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now'),
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = $3 and status in ('queued', 'running')",
    )
    .bind(status.status())
    .bind(error)
    .bind(job_id)
    .execute(conn)
    .await?;
    Ok(done.rows_affected() == 1)
}

/// Sets the progress counters (inside the transaction that committed the unit of work).
pub async fn set_progress(conn: &mut super::Conn, job_id: i64, done: i64) -> sqlx::Result<()> {
    sqlx::query(
        "update job set progress_done = $1, updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = $2",
    )
    .bind(done)
    .bind(job_id)
    .execute(conn)
    .await?;
    Ok(())
}

/// Sets a job's units of work once a worker knows them (a validation counts its Chamfer
/// distances only when it has read its populations).
pub async fn set_progress_total(
    conn: &mut super::Conn,
    job_id: i64,
    total: i64,
) -> sqlx::Result<()> {
    sqlx::query(
        "update job set progress_total = $1, updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = $2",
    )
    .bind(total)
    .bind(job_id)
    .execute(conn)
    .await?;
    Ok(())
}

/// Flags a queued or running job for cancellation (inside the caller's transaction, which
/// then settles it); returns its status, or None when there is no such job.
pub async fn request_cancel(
    conn: &mut super::Conn,
    job_id: i64,
) -> sqlx::Result<Option<JobStatus>> {
    sqlx::query(
        "update job set cancel_requested = 1, updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = $1 and status in ('queued', 'running')",
    )
    .bind(job_id)
    .execute(&mut *conn)
    .await?;
    sqlx::query_scalar("select status from job where job_id = $1")
        .bind(job_id)
        .fetch_optional(conn)
        .await
}

/// A job's kind and payload (what ending it must also end).
pub async fn kind_and_payload(
    conn: &mut super::Conn,
    job_id: i64,
) -> sqlx::Result<Option<(JobKind, String)>> {
    sqlx::query_as("select kind, payload from job where job_id = $1")
        .bind(job_id)
        .fetch_optional(conn)
        .await
}

/// Pending jobs flagged for cancellation (their workers may all be gone: someone must
/// settle them).
pub async fn cancel_requested_pending(pool: &super::Pool) -> sqlx::Result<Vec<i64>> {
    sqlx::query_scalar(
        "select job_id from job where cancel_requested = 1 and status in ('queued', 'running')",
    )
    .fetch_all(pool)
    .await
}

/// Whether a cancel was requested for the job (checked by workers between units of work).
pub async fn is_cancel_requested(pool: &super::Pool, job_id: i64) -> sqlx::Result<bool> {
    let flag: Option<super::Flag> =
        sqlx::query_scalar("select cancel_requested from job where job_id = $1")
            .bind(job_id)
            .fetch_optional(pool)
            .await?;
    Ok(flag.is_none_or(bool::from))
}

/// One job by id.
pub async fn get(pool: &super::Pool, job_id: i64) -> sqlx::Result<Option<JobRow>> {
    sqlx::query_as(
        "select job_id, kind, payload, status, attempts, progress_done, progress_total,
                cancel_requested, error, created_at, started_at, finished_at
         from job where job_id = $1",
    )
    .bind(job_id)
    .fetch_optional(pool)
    .await
}

/// Payloads of the training jobs, newest first (a deleted model's id may have trained
/// again: its newest training is the current model's).
pub async fn training_payloads(pool: &super::Pool) -> sqlx::Result<Vec<String>> {
    sqlx::query_scalar("select payload from job where kind = 'training' order by job_id desc")
        .fetch_all(pool)
        .await
}

/// Jobs waiting or running: the queue length that bounds new submissions.
pub async fn count_pending<'e>(
    ex: impl sqlx::Executor<'e, Database = sqlx::Any>,
) -> sqlx::Result<i64> {
    sqlx::query_scalar("select count(*) from job where status in ('queued', 'running')")
        .fetch_one(ex)
        .await
}

/// Number of jobs in each state (for /metrics).
pub async fn count_by_status(pool: &super::Pool) -> sqlx::Result<Vec<(JobStatus, i64)>> {
    sqlx::query_as("select status, count(*) from job group by status order by status")
        .fetch_all(pool)
        .await
}

/// Deletes a job row (after its cohort was deleted).
pub async fn delete(conn: &mut super::Conn, job_id: i64) -> sqlx::Result<()> {
    sqlx::query("delete from job where job_id = $1")
        .bind(job_id)
        .execute(conn)
        .await?;
    Ok(())
}
