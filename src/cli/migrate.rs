//! `aortagen migrate`: brings the database's schema to this version and exits (the step a
//! deployment runs once before starting new API and worker processes).

use crate::config::StorageConfig;
use crate::db;

/// Arguments of `aortagen migrate`.
#[derive(Debug, clap::Args)]
pub struct MigrateArgs {
    /// The database (the models directory is not used).
    #[command(flatten)]
    pub storage: StorageConfig,
}

/// Applies the embedded migrations of the database's backend.
pub fn run(args: MigrateArgs) -> anyhow::Result<()> {
    crate::telemetry::init_subscriber("aortagen=info", false);
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let url = &args.storage.database_url;
        let pool = db::open(url, 1, &db::ReadOnlySwitch::default()).await?;
        db::migrate(&pool).await?;
        db::require_current_schema(&pool).await?;
        tracing::info!(
            database = db::redact(url),
            backend = db::Backend::of(&pool).name(),
            "schema is current"
        );
        pool.close().await;
        anyhow::Ok(())
    })
}
