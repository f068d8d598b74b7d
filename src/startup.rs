//! The service lifecycle: open and migrate the database, free the leases of this host's
//! dead processes, register the bundled model, bind, then serve and run workers until a
//! shutdown signal. [`run_workers`] is the same without the API (`aortagen worker`).

use std::future::Future;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use tokio::net::TcpListener;
use tokio::sync::watch;

use crate::config::{Config, StorageConfig, WorkerConfig};
use crate::db;
use crate::db::states::ModelStatus;
use crate::engine::Engine;
use crate::http::access::AccessPolicy;
use crate::http::mesh_cache::MeshCache;
use crate::http::{self, AppState};
use crate::jobs::simulation::{self, SimulationWork};
use crate::jobs::{self, JobContext, JobControls, JobQueue, worker};
use crate::objects::Objects;
use crate::telemetry::ServiceMetrics;

/// Longest a shutdown waits for running jobs and open requests before abandoning them.
/// Container runtimes usually allow 10 s between SIGTERM and SIGKILL.
pub const SHUTDOWN_GRACE: Duration = Duration::from_secs(7);

/// Id under which the bundled model is registered.
pub const DEFAULT_MODEL_ID: &str = "default";

/// A built, bound, not yet running service.
pub struct Application {
    listener: TcpListener,
    state: AppState,
    port: u16,
}

impl Application {
    /// Prepares everything that can fail before serving: database, recovery, model
    /// registration, listener.
    pub async fn build(config: Config, engine: Arc<dyn Engine>) -> anyhow::Result<Self> {
        let access = AccessPolicy::from_config(&config)?;
        if access.is_enabled() {
            tracing::info!(
                protect_reads = config.protect_reads,
                "API keys required for state-changing requests"
            );
        }
        let workers = config.work.worker_count();
        // Workers hold a connection while committing and renewing leases; requests need a
        // few more.
        let connections = (3 * workers + 8) as u32;
        let read_only_switch = db::ReadOnlySwitch::default();
        let pool =
            db::connect_with_switch(&config.storage.database_url, connections, &read_only_switch)
                .await?;
        tracing::info!(database = db::Backend::of(&pool).name(), "database ready");
        free_dead_leases(&pool).await?;
        let bundled = config.storage.models_dir.join(DEFAULT_MODEL_ID);
        if bundled.is_dir() {
            if let Err(e) = register_model(&pool, engine.clone(), DEFAULT_MODEL_ID, &bundled).await
            {
                tracing::warn!(
                    error = format!("{e:#}"),
                    "cannot register the bundled model"
                );
            }
        } else if db::models::get(&pool, DEFAULT_MODEL_ID).await?.is_none() {
            tracing::warn!(dir = %bundled.display(), "no bundled model found; cohorts need a model registered or trained");
        }
        let listener = TcpListener::bind(&config.bind)
            .await
            .with_context(|| format!("cannot listen on {}", config.bind))?;
        let port = listener.local_addr()?.port();
        let jobs = job_context(pool.clone(), engine, &config.storage, &config.work)?;
        if config.storage.blob_store != crate::objects::BlobStoreUrl::Database {
            tracing::info!(store = %config.storage.blob_store, "objects kept outside the database");
        }
        publish_models(&jobs).await;
        let mesh_cache = Arc::new(MeshCache::new(config.mesh_cache_bytes));
        let queue = JobQueue::new(pool.clone(), config.max_queue, config.retry_after_secs);
        let state = AppState {
            pool,
            mesh_cache,
            simulations: Arc::new(SimulationWork::new(
                simulation::DEFAULT_SLOTS,
                simulation::DEFAULT_BACKLOG,
                jobs.objects.clone(),
                config.max_remesh_triangles,
            )),
            config: Arc::new(config),
            jobs,
            queue,
            access: Arc::new(access),
            read_only_switch,
            readiness: Default::default(),
        };
        Ok(Self {
            listener,
            state,
            port,
        })
    }

    /// The bound port (useful with port 0).
    pub fn port(&self) -> u16 {
        self.port
    }

    /// Shared state (tests drive jobs through it).
    pub fn state(&self) -> &AppState {
        &self.state
    }

    /// Serves HTTP and runs `workers` job workers until `shutdown` resolves. On shutdown
    /// the server stops accepting, running jobs are interrupted and re-queued with their
    /// finished shapes kept, and the call returns once workers and connections are done,
    /// or after [`SHUTDOWN_GRACE`] at the latest: work that has not stopped by then (a shape
    /// at a very high resolution, a slow client) is abandoned and its job re-queued.
    pub async fn run_until_stopped(
        self,
        workers: usize,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> anyhow::Result<()> {
        let (stop_tx, mut stop_rx) = watch::channel(false);
        let mut handles: Vec<_> = (0..workers)
            .map(|i| {
                let (ctx, wake, stop) = (
                    self.state.jobs.clone(),
                    self.state.queue.waker(),
                    stop_rx.clone(),
                );
                tokio::spawn(worker::run_worker_until_stopped(i, ctx, wake, stop))
            })
            .collect();
        let sweeper = tokio::spawn(sweep_orphans_periodically(self.state.jobs.clone()));
        let controls = self.state.jobs.controls.clone();
        let app = http::router(self.state.clone());
        tracing::info!(port = self.port, workers, "listening");
        let limits = http::server::ConnectionLimits::from_config(&self.state.config);
        let serve = http::server::serve(self.listener, app, limits, async move {
            shutdown.await;
            tracing::info!("shutting down: interrupting running jobs");
            controls.shut_down();
            let _ = stop_tx.send(true);
        });
        let mut served = tokio::spawn(serve);
        // Runs until the signal (or until the server fails, which also ends the service).
        let early = tokio::select! {
            joined = &mut served => Some(joined),
            _ = stop_rx.wait_for(|stopped| *stopped) => None,
        };
        sweeper.abort();
        let deadline = tokio::time::Instant::now() + SHUTDOWN_GRACE;
        if early.is_some() {
            self.state.jobs.controls.shut_down();
        }
        let workers_done = tokio::time::timeout_at(deadline, async {
            for h in &mut handles {
                if let Err(e) = h.await {
                    tracing::error!(error = %e, "worker ended abnormally");
                }
            }
        })
        .await;
        if workers_done.is_err() {
            abandon_running_tasks(&self.state.jobs).await;
            handles.iter().for_each(|h| h.abort());
        }
        let served = match early {
            Some(joined) => joined,
            None => match tokio::time::timeout_at(deadline, &mut served).await {
                Ok(joined) => joined,
                Err(_) => {
                    tracing::warn!("connections still open after the grace period; closing");
                    served.abort();
                    Ok(Ok(()))
                }
            },
        };
        if tokio::time::timeout(Duration::from_secs(1), self.state.pool.close())
            .await
            .is_err()
        {
            tracing::warn!("database connections still busy at exit");
        }
        served
            .context("the HTTP server task failed")?
            .context("the HTTP server failed")
    }
}

/// The context workers of this process run tasks with.
pub fn job_context(
    pool: db::Pool,
    engine: Arc<dyn Engine>,
    storage: &StorageConfig,
    work: &WorkerConfig,
) -> anyhow::Result<JobContext> {
    Ok(JobContext {
        objects: Objects::open(&storage.blob_store, &pool)?,
        pool,
        engine,
        controls: JobControls::default(),
        metrics: Arc::new(ServiceMetrics::default()),
        models_dir: storage.models_dir.clone(),
        fetched_models_dir: storage.fetched_models_dir(),
        leases: work.leases(),
        owner: format!("{}/api", jobs::process_identity()),
        housekeeping: Default::default(),
    })
}

/// How long an object no row names is kept: longer than any writer takes between writing an
/// object and committing the row that names it.
pub const ORPHAN_GRACE: Duration = Duration::from_secs(3600);

/// Sweeps the object store for orphans every ten minutes (API processes do; the sweep is
/// idempotent, so several APIs sweeping is harmless).
async fn sweep_orphans_periodically(ctx: JobContext) {
    let mut every = tokio::time::interval(Duration::from_secs(600));
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        every.tick().await;
        match ctx.objects.sweep(&ctx.pool, ORPHAN_GRACE).await {
            Ok(0) => {}
            Ok(n) => tracing::info!(objects = n, "orphaned objects swept"),
            Err(e) => tracing::warn!(error = format!("{e:#}"), "cannot sweep the object store"),
        }
    }
}

/// Publishes the bundle of every ready model that has none yet (the bundled model at its
/// first start, models of a database from before bundles), so workers elsewhere can fetch
/// them. A model whose files are not on this machine is left for a process that has them.
async fn publish_models(ctx: &JobContext) {
    let models = match db::models::list(&ctx.pool).await {
        Ok(models) => models,
        Err(e) => {
            tracing::warn!(error = %e, "cannot list the models to publish");
            return;
        }
    };
    for model in models {
        let ready = model.status == ModelStatus::Ready;
        if !ready || model.digest.is_some() || !Path::new(&model.dir_path).is_dir() {
            continue;
        }
        let published = async {
            let digest =
                crate::objects::bundle::publish(&ctx.objects, Path::new(&model.dir_path)).await?;
            if let Some(digest) = &digest {
                db::models::set_digest(&ctx.pool, &model.model_id, digest).await?;
            }
            anyhow::Ok(digest)
        };
        match published.await {
            Ok(Some(digest)) => {
                tracing::info!(model_id = %model.model_id, %digest, "model published")
            }
            Ok(None) => {}
            Err(e) => {
                tracing::warn!(model_id = %model.model_id, error = format!("{e:#}"), "cannot publish the model")
            }
        }
    }
}

/// At start-up: leases still held by processes of this host that are gone (a crash, a
/// kill) are expired, so their tasks run again at once instead of when the leases run out.
/// Other processes' work, here or on other machines, is left alone.
async fn free_dead_leases(pool: &db::Pool) -> anyhow::Result<()> {
    let expired = jobs::expire_dead_local_leases(pool).await?;
    if expired > 0 {
        tracing::warn!(
            tasks = expired,
            "tasks held by a stopped process on this host run again"
        );
    }
    Ok(())
}

/// Gives back the tasks this process still runs after the shutdown grace period, so other
/// workers take them at once (their finished shapes are kept).
async fn abandon_running_tasks(ctx: &JobContext) {
    let jobs = ctx.controls.running_jobs();
    tracing::warn!(
        jobs = ?jobs,
        "tasks did not stop within the shutdown grace period; giving them back"
    );
    let prefix = format!("{}/", jobs::process_identity());
    if let Err(e) = db::tasks::release_owned(&ctx.pool, &prefix).await {
        tracing::error!(error = %e, "cannot give the tasks back; their leases will expire");
    }
}

/// Runs `workers` task workers without the API until `shutdown` resolves (`aortagen
/// worker`): on shutdown running tasks are interrupted and given back, as by the service.
pub async fn run_workers(
    storage: StorageConfig,
    work: WorkerConfig,
    engine: Arc<dyn Engine>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let workers = work.worker_count().max(1);
    let pool = db::open(
        &storage.database_url,
        (3 * workers + 2) as u32,
        &db::ReadOnlySwitch::default(),
    )
    .await?;
    db::require_current_schema(&pool).await?;
    free_dead_leases(&pool).await?;
    let ctx = job_context(pool.clone(), engine, &storage, &work)?;
    let (stop_tx, stop_rx) = watch::channel(false);
    let wake = Arc::new(tokio::sync::Notify::new());
    let mut handles: Vec<_> = (0..workers)
        .map(|i| {
            tokio::spawn(worker::run_worker_until_stopped(
                i,
                ctx.clone(),
                wake.clone(),
                stop_rx.clone(),
            ))
        })
        .collect();
    tracing::info!(
        workers,
        database = db::Backend::of(&pool).name(),
        "workers running"
    );
    shutdown.await;
    tracing::info!("shutting down: interrupting running tasks");
    ctx.controls.shut_down();
    let _ = stop_tx.send(true);
    let done = tokio::time::timeout(SHUTDOWN_GRACE, async {
        for h in &mut handles {
            if let Err(e) = h.await {
                tracing::error!(error = %e, "worker ended abnormally");
            }
        }
    })
    .await;
    if done.is_err() {
        abandon_running_tasks(&ctx).await;
        handles.iter().for_each(|h| h.abort());
    }
    pool.close().await;
    Ok(())
}

/// Registers the model in `dir` under `id` unless that id exists; the engine reads its
/// facts (off the executor). Returns whether it was newly registered.
pub async fn register_model(
    pool: &db::Pool,
    engine: Arc<dyn Engine>,
    id: &str,
    dir: &Path,
) -> anyhow::Result<bool> {
    if db::models::get(pool, id).await?.is_some() {
        return Ok(false);
    }
    let owned = dir.to_path_buf();
    let info = tokio::task::spawn_blocking(move || engine.model_info(&owned))
        .await?
        .with_context(|| format!("cannot read the model in {}", dir.display()))?;
    let mut conn = pool.acquire().await?;
    let dir_path = dir.to_string_lossy();
    let inserted =
        db::models::insert_if_absent(&mut conn, id, &dir_path, Some(&info), ModelStatus::Ready)
            .await?;
    if inserted {
        tracing::info!(
            model_id = id,
            shapes = info.training_shape_count(),
            "model registered"
        );
    }
    Ok(inserted)
}

/// Resolves on Ctrl-C or SIGTERM (what container runtimes send).
pub async fn shutdown_signal() {
    let ctrl_c = async {
        if let Err(e) = tokio::signal::ctrl_c().await {
            tracing::error!(error = %e, "cannot listen for Ctrl-C");
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(e) => {
                tracing::error!(error = %e, "cannot listen for SIGTERM");
                std::future::pending::<()>().await;
            }
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {}
        _ = terminate => {}
    }
}
