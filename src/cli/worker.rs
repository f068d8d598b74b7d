//! `aortagen worker`: task workers without the API, for as many machines as the work needs.
//! Each claims tasks from the shared database (PostgreSQL for several machines) under
//! leases, runs them and commits their results; it never changes the schema.

use std::time::Duration;

use crate::config::{StorageConfig, WorkerConfig};
use crate::startup::{run_workers, shutdown_signal};

/// Arguments of `aortagen worker`.
#[derive(Debug, clap::Args)]
pub struct WorkerArgs {
    /// Database and models.
    #[command(flatten)]
    pub storage: StorageConfig,
    /// Workers in this process.
    #[command(flatten)]
    pub work: WorkerConfig,
    /// Log as JSON lines instead of human-readable text.
    #[arg(long, env = "AORTAGEN_LOG_JSON", default_value_t = false)]
    pub log_json: bool,
}

/// Runs workers until Ctrl-C or SIGTERM.
pub fn run(args: WorkerArgs) -> anyhow::Result<()> {
    crate::telemetry::init_subscriber("aortagen=info", args.log_json);
    crate::jobs::priority::init_background_pool(args.work.worker_nice);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("aortagen-worker")
        .build()?;
    let result = runtime.block_on(run_workers(
        args.storage,
        args.work,
        super::serve::engine(),
        shutdown_signal(),
    ));
    // Engine work still running on blocking threads has been given back to the queue.
    runtime.shutdown_timeout(Duration::from_millis(500));
    result
}
