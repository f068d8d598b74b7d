//! The `task` table: the units of work of jobs, claimed by workers of any process on any
//! machine under leases. A lease is a random token and an expiry on the database's clock
//! (never a machine's), extended by heartbeats. An expired lease is taken over by the next
//! claim, and a result is committed only with the token it was claimed under, so a worker
//! paused past its lease cannot commit late ([`complete`] refuses it). Every statement that
//! claims or changes a lease is a single statement: on PostgreSQL the claim skips rows
//! another transaction has locked (`FOR UPDATE SKIP LOCKED`), on SQLite the one writer makes
//! it atomic.

use super::states::{JobStatus, TaskKind, TaskStatus};
use super::{Backend, Conn, Flag, Pool};

/// The database clock in milliseconds since the Unix epoch, as SQL (both backends: SQLite's
/// `unixepoch`, and its twin the PostgreSQL migrations define).
macro_rules! now_ms {
    () => {
        "cast(unixepoch('now', 'subsec') * 1000 as bigint)"
    };
}

/// The claim: the oldest job's first claimable task, queued or with an expired lease. A
/// cohort's shapes wait for its setup tasks; tasks of a cancelled or finished job are not
/// claimed.
macro_rules! claim_sql {
    ($lock:literal) => {
        concat!(
            "update task set status = 'running', attempts = attempts + 1,
                 stalled_attempts = case when status = 'running' then stalled_attempts + 1
                                         else stalled_attempts end,
                 lease_token = $1, lease_owner = $2,
                 lease_expires_ms = ",
            now_ms!(),
            " + $3,
                 updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
             where task_id = (
                 select t.task_id from task t join job j on j.job_id = t.job_id
                 where j.status in ('queued', 'running') and j.cancel_requested = 0
                   and (t.status = 'queued'
                        or (t.status = 'running' and t.lease_expires_ms < ",
            now_ms!(),
            "))
                   and (t.kind <> 'shape' or not exists (
                        select 1 from task s where s.job_id = t.job_id
                            and s.kind in ('surface', 'anatomy') and s.status <> 'done'))
                 order by t.job_id, t.task_id
                 limit 1",
            $lock,
            ")
             returning task_id, job_id, kind, item, attempts, stalled_attempts, lease_token"
        )
    };
}

/// A task a worker holds: what to do and the token its result must be committed with.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct Lease {
    /// The task.
    pub task_id: i64,
    /// Its job.
    pub job_id: i64,
    /// What it makes.
    pub kind: TaskKind,
    /// The shape or training-shape index it makes, or -1.
    pub item: i64,
    /// Claims of this task so far, this one included.
    pub attempts: i64,
    /// Leases of it that expired in a row before this claim (0: a first or clean claim).
    pub stalled_attempts: i64,
    /// The claim's token.
    #[sqlx(rename = "lease_token")]
    pub token: String,
}

/// A task of a job, as planning creates it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NewTask {
    /// What it makes.
    pub kind: TaskKind,
    /// The shape or training-shape index, or -1 for a job-wide step.
    pub item: i64,
}

impl NewTask {
    /// A task without an index (a metrics step, a training, a fit, the anatomy step).
    pub fn whole(kind: TaskKind) -> Self {
        Self { kind, item: -1 }
    }
}

/// Why a lease no longer allows a commit.
#[derive(Debug, thiserror::Error)]
pub enum LeaseError {
    /// The lease expired and another worker took the task over (or it was released).
    #[error("the lease on task {0} was lost: another worker has taken the task over")]
    Lost(i64),
    /// The database refused.
    #[error(transparent)]
    Storage(#[from] sqlx::Error),
}

/// Adds `tasks` to a job inside the caller's transaction; tasks it has already are kept.
/// Returns how many were added.
pub async fn insert_missing(conn: &mut Conn, job_id: i64, tasks: &[NewTask]) -> sqlx::Result<u64> {
    let mut added = 0;
    for task in tasks {
        added += sqlx::query(
            "insert into task (job_id, kind, item) values ($1, $2, $3)
             on conflict (job_id, kind, item) do nothing",
        )
        .bind(job_id)
        .bind(task.kind)
        .bind(task.item)
        .execute(&mut *conn)
        .await?
        .rows_affected();
    }
    Ok(added)
}

/// Claims the next task for `owner` with a lease of `lease_ms` and the fresh `token`.
pub async fn claim(
    pool: &Pool,
    owner: &str,
    token: &str,
    lease_ms: i64,
) -> sqlx::Result<Option<Lease>> {
    let sql = match Backend::of(pool) {
        Backend::Sqlite => claim_sql!(""),
        Backend::Postgres => claim_sql!(" for update of t skip locked"),
    };
    sqlx::query_as(sql)
        .bind(token)
        .bind(owner)
        .bind(lease_ms)
        .fetch_optional(pool)
        .await
}

/// What a heartbeat learnt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Heartbeat {
    /// The lease is extended; `stop` when the job was cancelled or has ended meanwhile.
    Held {
        /// The worker should stop and leave the task.
        stop: bool,
    },
    /// The lease was lost (expired and taken over, or released).
    Lost,
}

/// Extends a lease by `lease_ms` from now; `progressed` clears the task's stall count (a
/// long task that keeps saving progress is not given up however often it is interrupted).
pub async fn heartbeat(
    pool: &Pool,
    lease: &Lease,
    lease_ms: i64,
    progressed: bool,
) -> sqlx::Result<Heartbeat> {
    let extended = sqlx::query(concat!(
        "update task set lease_expires_ms = ",
        now_ms!(),
        " + $1,
             stalled_attempts = case when $2 = 1 then 0 else stalled_attempts end,
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where task_id = $3 and lease_token = $4 and status = 'running'"
    ))
    .bind(lease_ms)
    .bind(Flag(progressed))
    .bind(lease.task_id)
    .bind(&lease.token)
    .execute(pool)
    .await?
    .rows_affected();
    if extended == 0 {
        return Ok(Heartbeat::Lost);
    }
    let job: Option<(JobStatus, Flag)> =
        sqlx::query_as("select status, cancel_requested from job where job_id = $1")
            .bind(lease.job_id)
            .fetch_optional(pool)
            .await?;
    let stop = job.is_none_or(|(status, cancel)| cancel.0 || !status.is_pending());
    Ok(Heartbeat::Held { stop })
}

/// Ends a lease with the task's result, inside the caller's transaction that stores that
/// result: refused (and the transaction is to be dropped) unless the lease still holds.
pub async fn complete(conn: &mut Conn, lease: &Lease) -> Result<(), LeaseError> {
    end(conn, lease, TaskStatus::Done, None).await
}

/// Ends a lease with the task given up (the caller fails its job in the same transaction).
pub async fn fail(conn: &mut Conn, lease: &Lease, error: &str) -> Result<(), LeaseError> {
    end(conn, lease, TaskStatus::Failed, Some(error)).await
}

/// Ends a lease with the task stopped because its job was cancelled or ended.
pub async fn cancel(conn: &mut Conn, lease: &Lease) -> Result<(), LeaseError> {
    end(conn, lease, TaskStatus::Cancelled, None).await
}

/// Gives a task back to the queue (shutdown, a storage fault): the next claim takes it
/// without counting a stall.
pub async fn release(conn: &mut Conn, lease: &Lease) -> Result<(), LeaseError> {
    end(conn, lease, TaskStatus::Queued, None).await
}

async fn end(
    conn: &mut Conn,
    lease: &Lease,
    status: TaskStatus,
    error: Option<&str>,
) -> Result<(), LeaseError> {
    let ended = sqlx::query(
        "update task set status = $1, error = $2, lease_token = null, lease_owner = null,
             lease_expires_ms = null,
             stalled_attempts = case when $1 = 'queued' then 0 else stalled_attempts end,
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where task_id = $3 and lease_token = $4 and status = 'running'",
    )
    .bind(status)
    .bind(error)
    .bind(lease.task_id)
    .bind(&lease.token)
    .execute(conn)
    .await?
    .rows_affected();
    match ended {
        1 => Ok(()),
        _ => Err(LeaseError::Lost(lease.task_id)),
    }
}

/// Tasks whose lease expired `max_stalls` times in a row: each is failed here (not claimed
/// again), and its job id returned so the caller fails the job. A task that kills every
/// worker that runs it must not loop forever.
pub async fn fail_stalled(pool: &Pool, max_stalls: i64) -> sqlx::Result<Vec<(i64, String)>> {
    sqlx::query_as(concat!(
        "update task set status = 'failed', lease_token = null, lease_owner = null,
             lease_expires_ms = null,
             error = 'its worker stopped ' || cast(stalled_attempts + 1 as text) ||
                     ' times in a row before finishing it; not retried again',
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where status = 'running' and lease_expires_ms < ",
        now_ms!(),
        " and stalled_attempts + 1 >= $1
         returning job_id, error"
    ))
    .bind(max_stalls)
    .fetch_all(pool)
    .await
}

/// Expires at once the leases `owner` holds (a process that found its predecessor on this
/// host dead: its tasks need not wait for their leases to run out). Returns how many.
pub async fn expire_owner(pool: &Pool, owner: &str) -> sqlx::Result<u64> {
    Ok(sqlx::query(
        "update task set lease_expires_ms = 0 where lease_owner = $1 and status = 'running'",
    )
    .bind(owner)
    .execute(pool)
    .await?
    .rows_affected())
}

/// Gives back to the queue every task whose owner's name starts with `prefix` (a process
/// that stops without waiting for its tasks), without counting a stall; jobs left with no
/// running task show as queued again.
pub async fn release_owned(pool: &Pool, prefix: &str) -> sqlx::Result<u64> {
    let mut tx = super::begin_write(pool).await?;
    let jobs: Vec<i64> = sqlx::query_scalar(
        "update task set status = 'queued', lease_token = null, lease_owner = null,
             lease_expires_ms = null, updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where status = 'running' and substr(lease_owner, 1, length($1)) = $1
         returning job_id",
    )
    .bind(prefix)
    .fetch_all(&mut *tx)
    .await?;
    for job_id in &jobs {
        super::jobs::queue_if_idle(&mut tx, *job_id).await?;
    }
    tx.commit().await?;
    Ok(jobs.len() as u64)
}

/// Owners of running tasks whose name starts with `prefix` (this host's processes).
pub async fn owners_with_prefix(pool: &Pool, prefix: &str) -> sqlx::Result<Vec<String>> {
    sqlx::query_scalar(
        "select distinct lease_owner from task
         where status = 'running' and substr(lease_owner, 1, length($1)) = $1",
    )
    .bind(prefix)
    .fetch_all(pool)
    .await
}

/// Running tasks of a job whose leases have not expired.
pub async fn live_count(conn: &mut Conn, job_id: i64) -> sqlx::Result<i64> {
    sqlx::query_scalar(concat!(
        "select count(*) from task where job_id = $1 and status = 'running'
             and lease_expires_ms >= ",
        now_ms!()
    ))
    .bind(job_id)
    .fetch_one(conn)
    .await
}

/// Ends every unfinished task of a job (its job reached a final state): queued and expired
/// ones become `cancelled`; live leases are left to their workers, who learn of it at their
/// next heartbeat.
pub async fn cancel_unfinished(conn: &mut Conn, job_id: i64) -> sqlx::Result<u64> {
    Ok(sqlx::query(concat!(
        "update task set status = 'cancelled', lease_token = null, lease_owner = null,
             lease_expires_ms = null, updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = $1 and (status = 'queued'
             or (status = 'running' and lease_expires_ms < ",
        now_ms!(),
        "))"
    ))
    .bind(job_id)
    .execute(conn)
    .await?
    .rows_affected())
}

/// Puts a job's failed and cancelled tasks back in the queue (a retried job), their
/// counts cleared.
pub async fn requeue_ended(conn: &mut Conn, job_id: i64) -> sqlx::Result<u64> {
    Ok(sqlx::query(
        "update task set status = 'queued', error = null, attempts = 0, stalled_attempts = 0,
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where job_id = $1 and status in ('failed', 'cancelled')",
    )
    .bind(job_id)
    .execute(conn)
    .await?
    .rows_affected())
}

/// Tasks of a job that are not done, of one kind.
pub async fn unfinished_count(conn: &mut Conn, job_id: i64, kind: TaskKind) -> sqlx::Result<i64> {
    sqlx::query_scalar(
        "select count(*) from task where job_id = $1 and kind = $2 and status <> 'done'",
    )
    .bind(job_id)
    .bind(kind)
    .fetch_one(conn)
    .await
}

/// Whether a job has any task at all (a job queued by an older version has none until a
/// worker plans it).
pub async fn has_tasks(conn: &mut Conn, job_id: i64) -> sqlx::Result<bool> {
    let n: i64 = sqlx::query_scalar("select count(*) from task where job_id = $1")
        .bind(job_id)
        .fetch_one(conn)
        .await?;
    Ok(n > 0)
}

/// Queued jobs without tasks (submitted, retried, or queued by an older version), oldest
/// first: what planning turns into tasks.
pub async fn unplanned_jobs(pool: &Pool, limit: i64) -> sqlx::Result<Vec<i64>> {
    sqlx::query_scalar(
        "select j.job_id from job j
         where j.status = 'queued' and j.cancel_requested = 0
           and not exists (select 1 from task t where t.job_id = j.job_id)
         order by j.job_id limit $1",
    )
    .bind(limit)
    .fetch_all(pool)
    .await
}

/// Counts of tasks by status over live jobs (for /metrics), and the live leases.
pub async fn count_by_status(pool: &Pool) -> sqlx::Result<Vec<(TaskStatus, i64)>> {
    sqlx::query_as("select status, count(*) from task group by status order by status")
        .fetch_all(pool)
        .await
}

/// Leases not yet expired (a finished job must have none).
pub async fn live_leases(pool: &Pool) -> sqlx::Result<i64> {
    sqlx::query_scalar(concat!(
        "select count(*) from task where status = 'running' and lease_expires_ms >= ",
        now_ms!()
    ))
    .fetch_one(pool)
    .await
}
