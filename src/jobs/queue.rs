//! The one way into the job queue: a [`Submission`] opens the write transaction in which a
//! job and the row it works on are created together, refuses the job when the queue is full,
//! stores its typed payload, and once it commits plans the job into tasks and wakes a
//! worker.

use std::sync::Arc;

use tokio::sync::Notify;

use super::Job;
use crate::db;

/// The queue's bound and the workers' wake-up signal.
#[derive(Clone)]
pub struct JobQueue {
    pool: db::Pool,
    wake: Arc<Notify>,
    max_pending: i64,
    retry_after_secs: u64,
}

/// Why a job was not queued.
#[derive(Debug, thiserror::Error)]
pub enum SubmitError {
    /// As many jobs as the bound allows are queued or running.
    #[error("the job queue is full ({pending} jobs waiting or running); retry in {retry_after} s")]
    QueueFull {
        /// Jobs queued or running.
        pending: i64,
        /// Seconds to wait before retrying.
        retry_after: u64,
    },
    /// The database refused.
    #[error(transparent)]
    Storage(#[from] sqlx::Error),
}

impl JobQueue {
    /// A queue on `pool` holding at most `max_pending` queued or running jobs; a refusal
    /// advises retrying after `retry_after_secs`.
    pub fn new(pool: db::Pool, max_pending: i64, retry_after_secs: u64) -> Self {
        Self {
            pool,
            wake: Arc::new(Notify::new()),
            max_pending,
            retry_after_secs,
        }
    }

    /// What workers wait on between jobs.
    pub fn waker(&self) -> Arc<Notify> {
        self.wake.clone()
    }

    /// Opens the write transaction of a submission.
    pub async fn begin(&self) -> sqlx::Result<Submission> {
        Ok(Submission {
            tx: db::begin_write(&self.pool).await?,
            queue: self.clone(),
            jobs: Vec::new(),
        })
    }
}

/// A write transaction that may enqueue jobs; they reach the workers when it commits.
pub struct Submission {
    tx: db::Tx,
    queue: JobQueue,
    jobs: Vec<i64>,
}

impl Submission {
    /// The transaction, for the rows the job works on.
    pub fn conn(&mut self) -> &mut db::Conn {
        &mut self.tx
    }

    /// Enqueues `job` with `progress_total` units of work, unless the queue is full.
    pub async fn enqueue(&mut self, job: &Job, progress_total: i64) -> Result<i64, SubmitError> {
        let pending = db::jobs::count_pending(&mut *self.tx).await?;
        if pending >= self.queue.max_pending {
            let retry_after = self.queue.retry_after_secs;
            return Err(SubmitError::QueueFull {
                pending,
                retry_after,
            });
        }
        let payload = job.payload_json();
        let id = db::jobs::enqueue(&mut self.tx, job.kind(), &payload, progress_total).await?;
        self.jobs.push(id);
        Ok(id)
    }

    /// Puts a failed or cancelled job back in the queue, unless the queue is full; returns
    /// whether the job was in such a state (otherwise nothing changes). A refused requeue
    /// leaves the transaction to be dropped, which undoes it.
    pub async fn requeue(&mut self, job_id: i64) -> Result<bool, SubmitError> {
        if !db::jobs::requeue_finished(&mut self.tx, job_id).await? {
            return Ok(false);
        }
        db::tasks::requeue_ended(&mut self.tx, job_id).await?;
        self.jobs.push(job_id);
        // The job counts itself now.
        let pending = db::jobs::count_pending(&mut *self.tx).await? - 1;
        if pending >= self.queue.max_pending {
            let retry_after = self.queue.retry_after_secs;
            return Err(SubmitError::QueueFull {
                pending,
                retry_after,
            });
        }
        Ok(true)
    }

    /// Commits the transaction, plans its jobs into tasks and wakes an idle worker. A job
    /// whose planning fails here is planned by the next worker that looks.
    pub async fn commit(self) -> sqlx::Result<()> {
        self.tx.commit().await?;
        for job_id in self.jobs {
            if let Err(e) = super::lifecycle::plan(&self.queue.pool, job_id).await {
                tracing::warn!(job_id, error = format!("{e:#}"), "cannot plan the job yet");
            }
        }
        self.queue.wake.notify_one();
        Ok(())
    }
}
