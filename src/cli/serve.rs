//! `aortagen serve`: the cohort service (REST API + job workers) on a SQLite database.

use std::sync::Arc;

use crate::config::Config;
use crate::jobs::engine::CohortEngine;
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
    let workers = args.config.worker_count();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("aortagen")
        .build()?;
    runtime.block_on(async move {
        let app = Application::build(args.config, engine()).await?;
        app.run_until_stopped(workers, shutdown_signal()).await
    })
}

/// The science engine the service runs on: the trained SDF models.
fn engine() -> Arc<dyn CohortEngine> {
    Arc::new(crate::engine::SdfEngine::new(Backend::default()))
}
