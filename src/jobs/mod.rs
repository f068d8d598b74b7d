//! Background work: a durable queue in the `job` table ([`queue`] is the one way in),
//! workers that claim and run jobs, and the job kinds ([`Job`]: cohort generation, model
//! training, fitting a new shape). Heavy work goes to background threads
//! ([`priority::spawn_background`]); a panic there fails the job, never the worker.

pub mod cohort;
pub mod fit;
pub mod priority;
pub mod queue;
pub mod setup;
pub mod simulation;
pub mod stats;
pub mod training;
pub mod worker;

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::anyhow;
use sqlx::SqlitePool;
use tracing::Instrument;

use crate::cohort::CohortError;
use crate::db::{self, states::JobKind};
use crate::engine::Engine;
use crate::telemetry::ServiceMetrics;
pub use queue::{JobQueue, Submission, SubmitError};

/// A job with its typed payload: what a submission stores and a worker runs.
#[derive(Debug, Clone, PartialEq)]
pub enum Job {
    /// Generate a cohort's missing shapes and its metrics.
    Cohort(cohort::CohortPayload),
    /// Train a model.
    Training(training::TrainingPayload),
    /// Fit a latent to a new mesh.
    Fit(fit::FitPayload),
}

impl Job {
    /// Its kind (the `kind` column).
    pub fn kind(&self) -> JobKind {
        match self {
            Self::Cohort(_) => JobKind::Cohort,
            Self::Training(_) => JobKind::Training,
            Self::Fit(_) => JobKind::Fit,
        }
    }

    /// The payload as stored.
    pub fn payload_json(&self) -> String {
        let json = match self {
            Self::Cohort(p) => serde_json::to_string(p),
            Self::Training(p) => serde_json::to_string(p),
            Self::Fit(p) => serde_json::to_string(p),
        };
        json.expect("payloads serialise")
    }

    /// Reads a stored job back.
    pub fn parse(kind: JobKind, payload: &str) -> serde_json::Result<Self> {
        Ok(match kind {
            JobKind::Cohort => Self::Cohort(serde_json::from_str(payload)?),
            JobKind::Training => Self::Training(serde_json::from_str(payload)?),
            JobKind::Fit => Self::Fit(serde_json::from_str(payload)?),
        })
    }
}

/// Why a job run did not succeed: the one error channel of every job kind.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// Interrupted by its cancel flag (a cancel request or shutdown); finished work is kept.
    #[error("interrupted")]
    Stopped,
    /// Gave up; a storage fault anywhere in the chain sends the job back to the queue
    /// instead.
    #[error("{0:#}")]
    Failed(anyhow::Error),
}

impl From<anyhow::Error> for JobError {
    fn from(e: anyhow::Error) -> Self {
        Self::Failed(e)
    }
}

impl From<sqlx::Error> for JobError {
    fn from(e: sqlx::Error) -> Self {
        Self::Failed(e.into())
    }
}

impl From<CohortError> for JobError {
    fn from(e: CohortError) -> Self {
        match e {
            CohortError::Cancelled => Self::Stopped,
            other => Self::Failed(other.into()),
        }
    }
}

/// What a worker needs to run jobs.
#[derive(Clone)]
pub struct JobContext {
    /// The database.
    pub pool: SqlitePool,
    /// The science engine.
    pub engine: Arc<dyn Engine>,
    /// Interrupt flags of the jobs running in this process.
    pub controls: JobControls,
    /// Counters for /metrics.
    pub metrics: Arc<ServiceMetrics>,
    /// Where trained models are written.
    pub models_dir: PathBuf,
}

/// Interrupt flags of running jobs, shared by the workers (which pass them to the engine)
/// and the API (cancel) and the shutdown path.
#[derive(Clone, Default)]
pub struct JobControls {
    running: Arc<Mutex<HashMap<i64, Arc<AtomicBool>>>>,
    shutting_down: Arc<AtomicBool>,
}

impl JobControls {
    fn register(&self, job_id: i64) -> Arc<AtomicBool> {
        let flag = Arc::new(AtomicBool::new(self.is_shutting_down()));
        self.lock().insert(job_id, flag.clone());
        flag
    }

    fn unregister(&self, job_id: i64) {
        self.lock().remove(&job_id);
    }

    /// Raises the interrupt flag of a job running in this process; false if it is not.
    pub fn interrupt(&self, job_id: i64) -> bool {
        self.lock()
            .get(&job_id)
            .map(|f| f.store(true, Ordering::SeqCst))
            .is_some()
    }

    /// Interrupts every running job and makes new claims stop at once; interrupted jobs go
    /// back to the queue with their finished work kept.
    pub fn shut_down(&self) {
        self.shutting_down.store(true, Ordering::SeqCst);
        for flag in self.lock().values() {
            flag.store(true, Ordering::SeqCst);
        }
    }

    /// Ids of the jobs running in this process.
    pub fn running_jobs(&self) -> Vec<i64> {
        self.lock().keys().copied().collect()
    }

    /// Whether [`Self::shut_down`] was called.
    pub fn is_shutting_down(&self) -> bool {
        self.shutting_down.load(Ordering::SeqCst)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<i64, Arc<AtomicBool>>> {
        self.running.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// How a job run ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RunOutcome {
    /// Everything done.
    Succeeded,
    /// Stopped by a cancel request; finished work kept.
    Cancelled,
    /// Stopped by shutdown; back in the queue to resume later.
    Released,
    /// Gave up; the message is the error chain.
    Failed(String),
    /// Storage could not take a write (read-only database, full disk); back in the queue
    /// with finished work kept, to run again once storage recovers.
    StorageFault(String),
}

impl RunOutcome {
    fn label(&self) -> &'static str {
        match self {
            Self::Succeeded => "succeeded",
            Self::Cancelled => "cancelled",
            Self::Released => "released",
            Self::Failed(_) => "failed",
            Self::StorageFault(_) => "storage-fault",
        }
    }
}

/// Result of one attempt to take work from the queue.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ExecutionOutcome {
    /// A job was claimed and run to one of its outcomes.
    TaskCompleted {
        /// The job.
        job_id: i64,
        /// How it ended.
        outcome: RunOutcome,
    },
    /// Nothing was queued.
    EmptyQueue,
}

/// Claims the oldest queued job, runs it and records its final state.
pub async fn try_execute_job(ctx: &JobContext) -> anyhow::Result<ExecutionOutcome> {
    let Some(job) = db::jobs::claim_next(&ctx.pool).await? else {
        return Ok(ExecutionOutcome::EmptyQueue);
    };
    let span = tracing::info_span!(
        "job",
        job_id = job.job_id,
        kind = %job.kind,
        attempt = job.attempts,
        cohort_id = tracing::field::Empty,
        model_id = tracing::field::Empty,
    );
    execute(ctx, job).instrument(span).await
}

/// Ends what a job cancelled while still queued was to produce, as its own run ends it on a
/// cancel: no worker ever claims such a job, so its kind's final step runs here.
pub async fn finish_cancelled_while_queued(ctx: &JobContext, job: &Job) -> anyhow::Result<()> {
    finish_subject(ctx, job, &RunOutcome::Cancelled).await
}

/// Brings what a job works on into the state its final outcome implies: a model whose
/// training or an anchor whose fit did not succeed becomes `failed`. A cohort's state is its
/// job's, and a released job runs again, so neither needs anything.
async fn finish_subject(ctx: &JobContext, job: &Job, outcome: &RunOutcome) -> anyhow::Result<()> {
    if matches!(outcome, RunOutcome::Released | RunOutcome::StorageFault(_)) {
        return Ok(());
    }
    match job {
        Job::Cohort(_) => Ok(()),
        Job::Training(p) => training::finish(ctx, p, outcome).await,
        Job::Fit(p) => fit::finish(ctx, p, outcome).await,
    }
}

async fn execute(
    ctx: &JobContext,
    claimed: db::jobs::ClaimedJob,
) -> anyhow::Result<ExecutionOutcome> {
    tracing::info!("job started");
    let job_id = claimed.job_id;
    let flag = ctx.controls.register(job_id);
    let started = Instant::now();
    let job = Job::parse(claimed.kind, &claimed.payload);
    let result = match &job {
        Ok(Job::Cohort(p)) => cohort::run(ctx, job_id, p, &flag).await,
        Ok(Job::Training(p)) => training::run(ctx, job_id, p, &flag).await,
        Ok(Job::Fit(p)) => fit::run(ctx, job_id, p, &flag).await,
        Err(e) => Err(JobError::Failed(anyhow!("bad job payload: {e}"))),
    };
    ctx.controls.unregister(job_id);
    let outcome = match result {
        Ok(()) => RunOutcome::Succeeded,
        Err(JobError::Stopped) => stop_outcome(ctx, job_id, &flag).await?,
        Err(JobError::Failed(e)) => match db::storage_fault_in(&e) {
            Some(fault) => RunOutcome::StorageFault(format!("{e:#} ({fault})")),
            None => RunOutcome::Failed(format!("{e:#}")),
        },
    };
    if let Ok(job) = &job {
        finish_subject(ctx, job, &outcome).await?;
    }
    record_outcome(ctx, job_id, &outcome).await?;
    let seconds = started.elapsed().as_secs_f64();
    ctx.metrics
        .observe_job(claimed.kind, outcome.label(), seconds);
    tracing::info!(outcome = outcome.label(), seconds, "job ended");
    Ok(ExecutionOutcome::TaskCompleted { job_id, outcome })
}

/// Writes a run's outcome to the job row (retrying while storage refuses).
async fn record_outcome(ctx: &JobContext, job_id: i64, outcome: &RunOutcome) -> anyhow::Result<()> {
    use db::jobs::FinalStatus;
    let (status, error) = match outcome {
        RunOutcome::Succeeded => (Some(FinalStatus::Succeeded), None),
        RunOutcome::Cancelled => (Some(FinalStatus::Cancelled), None),
        RunOutcome::Failed(e) => {
            tracing::error!(error = %e, "job failed");
            (Some(FinalStatus::Failed), Some(e.as_str()))
        }
        RunOutcome::Released => (None, None),
        RunOutcome::StorageFault(e) => {
            tracing::warn!(error = %e, "storage fault; the job goes back to the queue");
            (None, None)
        }
    };
    let pool = &ctx.pool;
    match status {
        Some(status) => {
            write_when_storage_allows(ctx, || db::jobs::finish(pool, job_id, status, error)).await
        }
        None => write_when_storage_allows(ctx, || db::jobs::release(pool, job_id)).await,
    }
}

/// Longest pause between attempts to write while storage is faulty.
pub const MAX_STORAGE_BACKOFF: Duration = Duration::from_secs(30);

/// Runs a write, and while it fails with a storage fault retries it with exponential
/// backoff, so a job's state is recorded once storage recovers instead of being lost or
/// turned into a failure. Gives up on shutdown: jobs left running are re-queued at start-up.
async fn write_when_storage_allows<F, Fut>(ctx: &JobContext, mut write: F) -> anyhow::Result<()>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = sqlx::Result<()>>,
{
    let mut pause = Duration::from_millis(250);
    loop {
        match write().await {
            Ok(()) => return Ok(()),
            Err(e) => {
                let Some(fault) = db::storage_fault(&e) else {
                    return Err(e.into());
                };
                if ctx.controls.is_shutting_down() {
                    tracing::warn!(%fault, "storage fault at shutdown; the job is re-queued at the next start");
                    return Ok(());
                }
                tracing::warn!(%fault, retry_in = ?pause, "cannot record the job's state");
                tokio::time::sleep(pause).await;
                pause = (pause * 2).min(MAX_STORAGE_BACKOFF);
            }
        }
    }
}

/// Decides how an interrupted job ends: a cancel request wins over shutdown.
async fn stop_outcome(
    ctx: &JobContext,
    job_id: i64,
    flag: &AtomicBool,
) -> anyhow::Result<RunOutcome> {
    if db::jobs::is_cancel_requested(&ctx.pool, job_id).await? {
        return Ok(RunOutcome::Cancelled);
    }
    let shutdown = flag.load(Ordering::SeqCst) && ctx.controls.is_shutting_down();
    Ok(if shutdown {
        RunOutcome::Released
    } else {
        RunOutcome::Cancelled
    })
}

/// An engine error, or [`JobError::Stopped`] when it came from the raised cancel flag.
fn stopped_or_failed(flag: &AtomicBool, error: anyhow::Error) -> JobError {
    match flag.load(Ordering::SeqCst) {
        true => JobError::Stopped,
        false => JobError::Failed(error),
    }
}

/// Whether the job's cancel flag is up: a job checks it before starting work it cannot
/// interrupt.
fn stopped(flag: &AtomicBool) -> Result<(), JobError> {
    match flag.load(Ordering::SeqCst) {
        true => Err(JobError::Stopped),
        false => Ok(()),
    }
}

/// Runs `work` on a background engine thread with a progress counter, and copies the
/// counter to the job row every `interval` while it runs and once at the end. The outer
/// error is the job row's; the inner result is the engine's (a panic becomes an error).
async fn run_with_progress<T, F>(
    ctx: &JobContext,
    job_id: i64,
    interval: Duration,
    work: F,
) -> anyhow::Result<anyhow::Result<T>>
where
    F: FnOnce(&AtomicU64) -> anyhow::Result<T> + Send + 'static,
    T: Send + 'static,
{
    let progress = Arc::new(AtomicU64::new(0));
    let task_progress = progress.clone();
    let mut task = priority::spawn_background(move || work(&task_progress));
    let mut reported = 0;
    let mut tick = tokio::time::interval(interval);
    let joined = loop {
        tokio::select! {
            joined = &mut task => break joined,
            _ = tick.tick() => {
                reported = store_progress(ctx, job_id, &progress, reported).await?;
            }
        }
    };
    store_progress(ctx, job_id, &progress, reported).await?;
    Ok(joined.map_err(join_error).and_then(|r| r))
}

/// Stores the counter when it changed since `reported`; returns what is stored.
async fn store_progress(
    ctx: &JobContext,
    job_id: i64,
    counter: &AtomicU64,
    reported: i64,
) -> anyhow::Result<i64> {
    let now = counter.load(Ordering::SeqCst) as i64;
    if now != reported {
        let mut conn = ctx.pool.acquire().await?;
        db::jobs::set_progress(&mut conn, job_id, now).await?;
    }
    Ok(now)
}

/// Turns a failed `spawn_blocking` (a panic inside the engine) into an error.
fn join_error(e: tokio::task::JoinError) -> anyhow::Error {
    if e.is_panic() {
        let panic = e.into_panic();
        anyhow!("engine panicked: {}", crate::engine::panic_message(&*panic))
    } else {
        anyhow!("engine task was cancelled")
    }
}
