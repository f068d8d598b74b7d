//! Reads of the `job` table by modification time, for the server-sent event stream: every
//! change of a job (claimed, progress, cancel requested, finished) sets its `updated_at`,
//! so the jobs touched since a moment are the rows at or after it.

use super::jobs::JobRow;

/// A job row with the time it last changed.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct ChangedJob {
    /// The job as the API reports it.
    #[sqlx(flatten)]
    pub job: JobRow,
    /// Last change (UTC, RFC 3339 with milliseconds; sorts as text).
    pub updated_at: String,
}

const COLUMNS: &str = "job_id, kind, payload, status, attempts, progress_done, progress_total,
    cancel_requested, error, created_at, started_at, finished_at, updated_at";

/// Jobs changed at or after `since`, oldest change first (at most `limit`).
pub async fn changed_since(
    pool: &super::Pool,
    since: &str,
    limit: i64,
) -> sqlx::Result<Vec<ChangedJob>> {
    let sql = format!(
        "select {COLUMNS} from job where updated_at >= $1 order by updated_at, job_id limit $2"
    );
    sqlx::query_as(sqlx::AssertSqlSafe(sql))
        .bind(since)
        .bind(limit)
        .fetch_all(pool)
        .await
}

/// Jobs still queued or running, in id order (what a new subscriber starts from).
pub async fn active(pool: &super::Pool) -> sqlx::Result<Vec<ChangedJob>> {
    let sql =
        format!("select {COLUMNS} from job where status in ('queued', 'running') order by job_id");
    sqlx::query_as(sqlx::AssertSqlSafe(sql))
        .fetch_all(pool)
        .await
}

/// The latest change of any job (None for an empty table).
pub async fn latest_change(pool: &super::Pool) -> sqlx::Result<Option<String>> {
    sqlx::query_scalar("select max(updated_at) from job")
        .fetch_one(pool)
        .await
}
