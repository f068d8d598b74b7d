//! `aortagen serve`: the cohort service (REST API + job workers) on SQLite or PostgreSQL;
//! with `--workers 0` the API alone, while `aortagen worker` processes take the work.

use std::sync::Arc;
use std::time::Duration;

use crate::config::Config;
use crate::engine::Engine;
use crate::sdf::backend::Backend;
use crate::startup::{Application, shutdown_signal};

/// Arguments of `aortagen serve`.
#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    /// Service settings.
    #[command(flatten)]
    pub config: Config,
}

/// Runs the service until Ctrl-C or SIGTERM.
pub fn run(args: ServeArgs) -> anyhow::Result<()> {
    crate::telemetry::init_subscriber("aortagen=info,tower_http=info", args.config.log_json);
    let workers = args.config.work.worker_count();
    crate::jobs::priority::init_background_pool(args.config.work.worker_nice);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("aortagen")
        .build()?;
    let result = runtime.block_on(async move {
        let app = Application::build(args.config, engine()).await?;
        app.run_until_stopped(workers, shutdown_signal()).await
    });
    // Dropping the runtime would wait for engine work still running on blocking threads
    // (its job is already back in the queue); the process exits without it.
    runtime.shutdown_timeout(Duration::from_millis(500));
    result
}

/// The science engine the service runs on: the trained SDF models.
pub(super) fn engine() -> Arc<dyn Engine> {
    Arc::new(crate::engine::SdfEngine::new(Backend::default()))
}
