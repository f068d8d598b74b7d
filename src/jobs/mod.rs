//! Background work: a durable queue in the `job` table ([`queue`] is the one way in), jobs
//! planned into tasks ([`lifecycle`]: a cohort's setup steps, one task per shape and its
//! metrics step; a training; a fit; a refit, one task per training shape), and workers in
//! any process on any machine that claim tasks under leases and run them ([`worker`]). Heavy work goes to background threads
//! ([`priority::spawn_background`]); a panic there fails the task and its job, never the
//! worker.

pub mod cohort;
pub mod fit;
pub mod lifecycle;
pub mod priority;
pub mod queue;
pub mod refit;
pub mod remeasure;
pub mod setup;
pub mod simulation;
pub mod stats;
pub mod training;
pub mod validation;
pub mod worker;

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::anyhow;
use tracing::Instrument;

use crate::cohort::CohortError;
use crate::db::tasks::{Heartbeat, Lease, LeaseError};
use crate::db::{
    self,
    jobs::FinalStatus,
    states::{JobKind, TaskKind},
};
use crate::engine::Engine;
use crate::telemetry::ServiceMetrics;
pub use lifecycle::CancelOutcome;
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
    /// Validate a cohort against a reference population.
    Validation(validation::ValidationPayload),
    /// Fit a model's training shapes again with the network frozen.
    Refit(refit::RefitPayload),
}

impl Job {
    /// Its kind (the `kind` column).
    pub fn kind(&self) -> JobKind {
        match self {
            Self::Cohort(_) => JobKind::Cohort,
            Self::Training(_) => JobKind::Training,
            Self::Fit(_) => JobKind::Fit,
            Self::Validation(_) => JobKind::Validation,
            Self::Refit(_) => JobKind::Refit,
        }
    }

    /// The payload as stored.
    pub fn payload_json(&self) -> String {
        let json = match self {
            Self::Cohort(p) => serde_json::to_string(p),
            Self::Training(p) => serde_json::to_string(p),
            Self::Fit(p) => serde_json::to_string(p),
            Self::Validation(p) => serde_json::to_string(p),
            Self::Refit(p) => serde_json::to_string(p),
        };
        json.expect("payloads serialise")
    }

    /// Reads a stored job back.
    pub fn parse(kind: JobKind, payload: &str) -> serde_json::Result<Self> {
        Ok(match kind {
            JobKind::Cohort => Self::Cohort(serde_json::from_str(payload)?),
            JobKind::Training => Self::Training(serde_json::from_str(payload)?),
            JobKind::Fit => Self::Fit(serde_json::from_str(payload)?),
            JobKind::Validation => Self::Validation(serde_json::from_str(payload)?),
            JobKind::Refit => Self::Refit(serde_json::from_str(payload)?),
        })
    }
}

/// Why a job run did not succeed: the one error channel of every job kind.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// Interrupted by its cancel flag (a cancel request or shutdown); finished work is kept.
    #[error("interrupted")]
    Stopped,
    /// Gave up; a storage fault anywhere in the chain sends the task back to the queue
    /// instead.
    #[error("{0:#}")]
    Failed(anyhow::Error),
    /// The task's lease was taken over by another worker: its result was not committed.
    #[error("the task's lease was lost")]
    LeaseLost,
}

impl From<LeaseError> for JobError {
    fn from(e: LeaseError) -> Self {
        match e {
            LeaseError::Lost(_) => Self::LeaseLost,
            LeaseError::Storage(e) => Self::Failed(e.into()),
        }
    }
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

/// How workers hold tasks: the lease a claim takes, how often it is renewed, and how many
/// expired leases in a row give a task up.
#[derive(Debug, Clone, Copy)]
pub struct LeaseSettings {
    /// How long a claim or heartbeat holds a task; a worker silent for longer loses it.
    pub lease: Duration,
    /// How often a running task's lease is renewed (and its job's cancel flag read).
    pub heartbeat: Duration,
    /// Leases of one task that may expire in a row (its worker died or hung) before the task
    /// and its job are failed.
    pub max_stalls: i64,
}

impl Default for LeaseSettings {
    fn default() -> Self {
        Self {
            lease: Duration::from_secs(30),
            heartbeat: Duration::from_secs(3),
            max_stalls: 5,
        }
    }
}

impl LeaseSettings {
    fn lease_ms(&self) -> i64 {
        self.lease.as_millis() as i64
    }
}

/// What a worker needs to run tasks.
#[derive(Clone)]
pub struct JobContext {
    /// The database.
    pub pool: db::Pool,
    /// The science engine.
    pub engine: Arc<dyn Engine>,
    /// Interrupt flags of the tasks running in this process.
    pub controls: JobControls,
    /// Counters for /metrics.
    pub metrics: Arc<ServiceMetrics>,
    /// Where trained models are written.
    pub models_dir: PathBuf,
    /// Where models fetched from the object store are unpacked.
    pub fetched_models_dir: PathBuf,
    /// Where meshes are stored.
    pub objects: crate::objects::Objects,
    /// Lease length, heartbeat and stall bound.
    pub leases: LeaseSettings,
    /// Who holds the leases this context takes (`host/pid/start/worker`).
    pub owner: String,
    /// When this process last did the queue's housekeeping.
    pub housekeeping: Housekeeping,
}

/// When a process last did the queue's housekeeping ([`lifecycle::maintain`]): once per
/// interval is enough, so a busy worker's claims stay one statement each.
#[derive(Clone, Default)]
pub struct Housekeeping(Arc<Mutex<Option<Instant>>>);

impl Housekeeping {
    /// How often housekeeping runs at most.
    const INTERVAL: Duration = Duration::from_millis(500);

    /// Whether it is due now (and, if so, marks it done).
    fn due(&self) -> bool {
        let mut last = self.0.lock().unwrap_or_else(|e| e.into_inner());
        match *last {
            Some(at) if at.elapsed() < Self::INTERVAL => false,
            _ => {
                *last = Some(Instant::now());
                true
            }
        }
    }
}

impl JobContext {
    /// The directory on this machine holding `model`'s files, fetched from the object
    /// store by digest when this machine does not have them.
    pub async fn model_dir(&self, model: &crate::db::models::ModelRow) -> anyhow::Result<PathBuf> {
        crate::objects::bundle::local_model_dir(&self.objects, &self.fetched_models_dir, model)
            .await
    }

    /// The same context for worker `index` of this process (its own lease owner name).
    pub fn for_worker(&self, index: usize) -> Self {
        Self {
            owner: format!("{}/{index}", process_identity()),
            ..self.clone()
        }
    }
}

/// This process as lease owners name it: host, process id and the process's start time
/// (so a later process that reuses the id is told apart).
pub fn process_identity() -> String {
    static IDENTITY: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    IDENTITY
        .get_or_init(|| {
            let pid = std::process::id();
            format!("{}/{pid}/{}", host_name(), process_start(pid).unwrap_or(0))
        })
        .clone()
}

/// The host's name (`HOSTNAME`, else the kernel's), as lease owners carry it.
pub fn host_name() -> String {
    std::env::var("HOSTNAME")
        .ok()
        .filter(|h| !h.is_empty())
        .or_else(|| {
            std::fs::read_to_string("/proc/sys/kernel/hostname")
                .ok()
                .map(|h| h.trim().to_owned())
        })
        .unwrap_or_else(|| "localhost".to_owned())
}

/// When process `pid` started, in clock ticks since boot (Linux), or None when there is no
/// such process.
fn process_start(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may hold spaces: count from its end.
    let after_name = &stat[stat.rfind(')')? + 2..];
    after_name.split(' ').nth(19)?.parse().ok()
}

/// Whether the process an owner name describes is gone (same host only: the name carries
/// the host, and a process elsewhere cannot be checked).
fn owner_is_dead(owner: &str) -> bool {
    let mut parts = owner.split('/');
    let (Some(_host), Some(pid), Some(start)) = (parts.next(), parts.next(), parts.next()) else {
        return false;
    };
    let (Ok(pid), Ok(start)) = (pid.parse::<u32>(), start.parse::<u64>()) else {
        return false;
    };
    process_start(pid) != Some(start)
}

/// At start-up: the leases that earlier processes on this host still hold, when those
/// processes are gone, are expired at once so their tasks run again without waiting for the
/// leases to run out. Leases of live processes, and of other hosts, are left alone.
pub async fn expire_dead_local_leases(pool: &db::Pool) -> anyhow::Result<u64> {
    let prefix = format!("{}/", host_name());
    let mut expired = 0;
    for owner in db::tasks::owners_with_prefix(pool, &prefix).await? {
        if owner_is_dead(&owner) {
            expired += db::tasks::expire_owner(pool, &owner).await?;
        }
    }
    Ok(expired)
}

/// Stop flags of the tasks this process runs, by job: (task id, flag).
type RunningTasks = HashMap<i64, Vec<(i64, Arc<AtomicBool>)>>;

/// Interrupt flags of running tasks, shared by the workers (which pass them to the engine),
/// the API (cancel) and the shutdown path.
#[derive(Clone, Default)]
pub struct JobControls {
    running: Arc<Mutex<RunningTasks>>,
    shutting_down: Arc<AtomicBool>,
}

impl JobControls {
    fn register(&self, job_id: i64, task_id: i64) -> Arc<AtomicBool> {
        let flag = Arc::new(AtomicBool::new(self.is_shutting_down()));
        self.lock()
            .entry(job_id)
            .or_default()
            .push((task_id, flag.clone()));
        flag
    }

    fn unregister(&self, job_id: i64, task_id: i64) {
        let mut running = self.lock();
        if let Some(tasks) = running.get_mut(&job_id) {
            tasks.retain(|(id, _)| *id != task_id);
            if tasks.is_empty() {
                running.remove(&job_id);
            }
        }
    }

    /// Raises the interrupt flags of a job's tasks running in this process; false if none
    /// runs here.
    pub fn interrupt(&self, job_id: i64) -> bool {
        self.lock()
            .get(&job_id)
            .map(|tasks| {
                tasks
                    .iter()
                    .for_each(|(_, f)| f.store(true, Ordering::SeqCst))
            })
            .is_some()
    }

    /// Interrupts every running task and makes new claims stop at once; interrupted tasks
    /// go back to the queue with their jobs' finished work kept.
    pub fn shut_down(&self) {
        self.shutting_down.store(true, Ordering::SeqCst);
        for tasks in self.lock().values() {
            tasks
                .iter()
                .for_each(|(_, f)| f.store(true, Ordering::SeqCst));
        }
    }

    /// Ids of the jobs with tasks running in this process.
    pub fn running_jobs(&self) -> Vec<i64> {
        self.lock().keys().copied().collect()
    }

    /// Whether [`Self::shut_down`] was called.
    pub fn is_shutting_down(&self) -> bool {
        self.shutting_down.load(Ordering::SeqCst)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, RunningTasks> {
        self.running.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A task being run: its lease, its interrupt flag (raised by a cancel, shutdown, or a lost
/// lease) and its progress counter (saved epochs or steps; renewals report it so a long task
/// that progresses is never given up).
#[derive(Clone)]
pub struct TaskRun {
    /// The claim.
    pub lease: Lease,
    /// Raised to stop the task.
    pub flag: Arc<AtomicBool>,
    /// Units of work the task has saved.
    pub progress: Arc<AtomicU64>,
}

/// How a task run ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RunOutcome {
    /// Its result is committed.
    Succeeded,
    /// Stopped because its job was cancelled (or ended meanwhile); finished work kept.
    Cancelled,
    /// Stopped by shutdown; back in the queue to run again.
    Released,
    /// Gave up, failing its job; the message is the error chain.
    Failed(String),
    /// Storage could not take a write (read-only database, full disk, server unreachable);
    /// back in the queue to run again once storage recovers.
    StorageFault(String),
    /// Another worker took the task over after this one's lease expired; nothing of this run
    /// was committed.
    LeaseLost,
}

impl RunOutcome {
    fn label(&self) -> &'static str {
        match self {
            Self::Succeeded => "succeeded",
            Self::Cancelled => "cancelled",
            Self::Released => "released",
            Self::Failed(_) => "failed",
            Self::StorageFault(_) => "storage-fault",
            Self::LeaseLost => "lease-lost",
        }
    }
}

/// Result of one attempt to take work from the queue.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ExecutionOutcome {
    /// A task was claimed and run to one of its outcomes.
    TaskCompleted {
        /// Its job.
        job_id: i64,
        /// The task.
        task_id: i64,
        /// What it made.
        kind: TaskKind,
        /// How it ended.
        outcome: RunOutcome,
    },
    /// Nothing was claimable.
    EmptyQueue,
}

/// Does the queue's housekeeping, then claims the next task, runs it and records how it
/// ended.
pub async fn try_execute_job(ctx: &JobContext) -> anyhow::Result<ExecutionOutcome> {
    if ctx.controls.is_shutting_down() {
        return Ok(ExecutionOutcome::EmptyQueue);
    }
    if ctx.housekeeping.due() {
        lifecycle::maintain(ctx, ctx.leases.max_stalls).await?;
    }
    let token = format!("{:032x}", rand::random::<u128>());
    let Some(lease) =
        db::tasks::claim(&ctx.pool, &ctx.owner, &token, ctx.leases.lease_ms()).await?
    else {
        return Ok(ExecutionOutcome::EmptyQueue);
    };
    let mut conn = ctx.pool.acquire().await?;
    db::jobs::start(&mut conn, lease.job_id).await?;
    drop(conn);
    let span = tracing::info_span!(
        "task",
        job_id = lease.job_id,
        task_id = lease.task_id,
        kind = %lease.kind,
        item = lease.item,
        attempt = lease.attempts,
        cohort_id = tracing::field::Empty,
        model_id = tracing::field::Empty,
    );
    execute(ctx, lease).instrument(span).await
}

async fn execute(ctx: &JobContext, lease: Lease) -> anyhow::Result<ExecutionOutcome> {
    if lease.stalled_attempts > 0 {
        tracing::warn!(
            stalls = lease.stalled_attempts,
            "task taken over from a worker whose lease expired"
        );
    }
    tracing::debug!("task started");
    let (job_id, task_id, kind) = (lease.job_id, lease.task_id, lease.kind);
    let run = TaskRun {
        flag: ctx.controls.register(job_id, task_id),
        progress: Arc::new(AtomicU64::new(0)),
        lease,
    };
    let started = Instant::now();
    let lost = Arc::new(AtomicBool::new(false));
    let heartbeat = AbortOnDrop(tokio::spawn(keep_lease(
        ctx.clone(),
        run.clone(),
        lost.clone(),
    )));
    // Its own task: a panic outside the engine ends this task's run, not the worker.
    let result = AbortOnDrop(tokio::spawn({
        let (ctx, run) = (ctx.clone(), run.clone());
        async move { run_task(&ctx, &run).await }.in_current_span()
    }))
    .await
    .unwrap_or_else(|e| Err(JobError::Failed(task_panic(e))));
    drop(heartbeat);
    ctx.controls.unregister(job_id, task_id);
    let outcome = match result {
        Ok(()) => RunOutcome::Succeeded,
        Err(JobError::LeaseLost) => RunOutcome::LeaseLost,
        Err(JobError::Stopped) if lost.load(Ordering::SeqCst) => RunOutcome::LeaseLost,
        Err(JobError::Stopped) if ctx.controls.is_shutting_down() => RunOutcome::Released,
        Err(JobError::Stopped) => RunOutcome::Cancelled,
        Err(JobError::Failed(e)) => match db::storage_fault_in(&e) {
            Some(fault) => RunOutcome::StorageFault(format!("{e:#} ({fault})")),
            None => RunOutcome::Failed(format!("{e:#}")),
        },
    };
    record_outcome(ctx, &run.lease, &outcome).await?;
    let seconds = started.elapsed().as_secs_f64();
    ctx.metrics.observe_task(kind, outcome.label(), seconds);
    tracing::debug!(outcome = outcome.label(), seconds, "task ended");
    Ok(ExecutionOutcome::TaskCompleted {
        job_id,
        task_id,
        kind,
        outcome,
    })
}

async fn run_task(ctx: &JobContext, run: &TaskRun) -> Result<(), JobError> {
    let row = db::jobs::get(&ctx.pool, run.lease.job_id)
        .await?
        .ok_or_else(|| anyhow!("job {} no longer exists", run.lease.job_id))?;
    let job = Job::parse(row.kind, &row.payload)
        .map_err(|e| JobError::Failed(anyhow!("bad job payload: {e}")))?;
    match (&job, run.lease.kind) {
        (Job::Cohort(p), TaskKind::Surface) => cohort::surface(ctx, run, p).await,
        (Job::Cohort(p), TaskKind::Anatomy) => cohort::anatomy(ctx, run, p).await,
        (Job::Cohort(p), TaskKind::Shape) => cohort::shape(ctx, run, p).await,
        (Job::Cohort(p), TaskKind::Metrics) => cohort::metrics(ctx, run, p).await,
        (Job::Training(p), TaskKind::Training) => training::run(ctx, run, p).await,
        (Job::Fit(p), TaskKind::Fit) => fit::run(ctx, run, p).await,
        (Job::Validation(p), TaskKind::Validation) => validation::run(ctx, run, p).await,
        (Job::Refit(p), TaskKind::Refit) => refit::shape(ctx, run, p).await,
        (_, kind) => Err(JobError::Failed(anyhow!(
            "a {} job has no {kind} task",
            row.kind
        ))),
    }
}

/// A spawned task that is aborted when its handle is dropped: a run given up by its caller
/// (a worker stopped at the end of the shutdown grace) stops renewing its lease and never
/// commits, exactly as if its process had died.
pub struct AbortOnDrop<T>(pub tokio::task::JoinHandle<T>);

impl<T> Drop for AbortOnDrop<T> {
    fn drop(&mut self) {
        self.0.abort();
    }
}

impl<T> std::future::Future for AbortOnDrop<T> {
    type Output = Result<T, tokio::task::JoinError>;

    fn poll(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<Self::Output> {
        std::pin::Pin::new(&mut self.0).poll(cx)
    }
}

/// Renews a running task's lease until the task ends. A renewal that finds the job
/// cancelled or ended raises the task's flag; one that finds the lease taken over, or no
/// renewal succeeding for a whole lease length (the database unreachable), raises it as
/// lost, so the task stops and commits nothing.
async fn keep_lease(ctx: JobContext, run: TaskRun, lost: Arc<AtomicBool>) {
    let mut renewed = Instant::now();
    let mut reported = 0;
    loop {
        tokio::time::sleep(ctx.leases.heartbeat).await;
        let progress = run.progress.load(Ordering::SeqCst);
        let beat = db::tasks::heartbeat(
            &ctx.pool,
            &run.lease,
            ctx.leases.lease_ms(),
            progress > reported,
        )
        .await;
        match beat {
            Ok(Heartbeat::Held { stop }) => {
                renewed = Instant::now();
                reported = progress;
                if stop {
                    run.flag.store(true, Ordering::SeqCst);
                }
            }
            Ok(Heartbeat::Lost) => {
                tracing::warn!("the task's lease was taken over; stopping it");
                lost.store(true, Ordering::SeqCst);
                run.flag.store(true, Ordering::SeqCst);
                return;
            }
            Err(e) if renewed.elapsed() >= ctx.leases.lease => {
                tracing::warn!(error = %e, "cannot renew the task's lease; stopping it");
                lost.store(true, Ordering::SeqCst);
                run.flag.store(true, Ordering::SeqCst);
                return;
            }
            Err(e) => tracing::warn!(error = %e, "cannot renew the task's lease; retrying"),
        }
    }
}

/// Writes how a task run ended (retrying while storage refuses): a cancelled task may be its
/// job's last and settle it; a failed one fails its job; a released one goes back to the
/// queue. Success was committed by the task itself, and a lost lease has nothing to write.
async fn record_outcome(
    ctx: &JobContext,
    lease: &Lease,
    outcome: &RunOutcome,
) -> anyhow::Result<()> {
    let pool = &ctx.pool;
    let job_id = lease.job_id;
    let written = match outcome {
        RunOutcome::Succeeded | RunOutcome::LeaseLost => return Ok(()),
        RunOutcome::Cancelled => {
            write_when_storage_allows(ctx, || async {
                let mut tx = db::begin_write(pool).await?;
                db::tasks::cancel(&mut tx, lease).await?;
                if lifecycle::settle_cancel(&mut tx, job_id).await? {
                    tracing::info!("job cancelled");
                }
                tx.commit().await?;
                Ok(())
            })
            .await
        }
        RunOutcome::Failed(e) => {
            tracing::error!(error = %e, "task failed; its job fails");
            write_when_storage_allows(ctx, || async {
                let mut tx = db::begin_write(pool).await?;
                db::tasks::fail(&mut tx, lease, e).await?;
                lifecycle::finish_job(&mut tx, job_id, FinalStatus::Failed, Some(e)).await?;
                tx.commit().await?;
                Ok(())
            })
            .await
        }
        RunOutcome::Released | RunOutcome::StorageFault(_) => {
            if let RunOutcome::StorageFault(e) = outcome {
                tracing::warn!(error = %e, "storage fault; the task goes back to the queue");
            }
            write_when_storage_allows(ctx, || async {
                let mut tx = db::begin_write(pool).await?;
                db::tasks::release(&mut tx, lease).await?;
                db::jobs::queue_if_idle(&mut tx, job_id).await?;
                tx.commit().await?;
                Ok(())
            })
            .await
        }
    };
    match written {
        Err(e) if e.downcast_ref::<LeaseError>().is_some() => {
            tracing::warn!("the task's lease was taken over before its end was recorded");
            Ok(())
        }
        other => other,
    }
}

/// Longest pause between attempts to write while storage is faulty.
pub const MAX_STORAGE_BACKOFF: Duration = Duration::from_secs(30);

/// Runs a write, and while it fails with a storage fault retries it with exponential
/// backoff, so a task's end is recorded once storage recovers instead of being lost. Gives
/// up on shutdown: the lease then expires and another worker runs the task again.
async fn write_when_storage_allows<F, Fut>(ctx: &JobContext, mut write: F) -> anyhow::Result<()>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = anyhow::Result<()>>,
{
    let mut pause = Duration::from_millis(250);
    loop {
        match write().await {
            Ok(()) => return Ok(()),
            Err(e) => {
                let Some(fault) = db::storage_fault_in(&e) else {
                    return Err(e);
                };
                if ctx.controls.is_shutting_down() {
                    tracing::warn!(%fault, "storage fault at shutdown; the task runs again once its lease expires");
                    return Ok(());
                }
                tracing::warn!(%fault, retry_in = ?pause, "cannot record the task's end");
                tokio::time::sleep(pause).await;
                pause = (pause * 2).min(MAX_STORAGE_BACKOFF);
            }
        }
    }
}

/// The model a job works on, or an error saying it was deleted meanwhile.
async fn existing_model(pool: &db::Pool, model_id: &str) -> anyhow::Result<db::models::ModelRow> {
    db::models::get(pool, model_id)
        .await?
        .ok_or_else(|| anyhow!("model {model_id:?} no longer exists"))
}

/// An engine error, or [`JobError::Stopped`] when it came from the raised cancel flag.
fn stopped_or_failed(flag: &AtomicBool, error: anyhow::Error) -> JobError {
    match flag.load(Ordering::SeqCst) {
        true => JobError::Stopped,
        false => JobError::Failed(error),
    }
}

/// Whether the task's flag is up: a task checks it before starting work it cannot
/// interrupt.
fn stopped(flag: &AtomicBool) -> Result<(), JobError> {
    match flag.load(Ordering::SeqCst) {
        true => Err(JobError::Stopped),
        false => Ok(()),
    }
}

/// Runs `work` on a background engine thread with the task's progress counter, and copies
/// the counter to the job row every `interval` while it runs and once at the end. The
/// outer error is the job row's; the inner result is the engine's (a panic becomes an
/// error).
async fn run_with_progress<T, F>(
    ctx: &JobContext,
    run: &TaskRun,
    interval: Duration,
    work: F,
) -> anyhow::Result<anyhow::Result<T>>
where
    F: FnOnce(&AtomicU64) -> anyhow::Result<T> + Send + 'static,
    T: Send + 'static,
{
    let progress = run.progress.clone();
    let task_progress = progress.clone();
    let mut task = priority::spawn_background(move || work(&task_progress));
    let mut reported = 0;
    let mut tick = tokio::time::interval(interval);
    let job_id = run.lease.job_id;
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

/// Turns a task run that panicked outside the engine into its error.
fn task_panic(e: tokio::task::JoinError) -> anyhow::Error {
    if e.is_panic() {
        let panic = e.into_panic();
        anyhow!(
            "the task panicked: {}",
            crate::engine::panic_message(&*panic)
        )
    } else {
        anyhow!("the task was aborted")
    }
}
