//! `aortagen migrate`: brings the database's schema to this version and exits (the step a
//! deployment runs once before starting new API and worker processes); with `--remeasure`,
//! also the stored shapes' measurements to today's method.

use crate::config::StorageConfig;
use crate::db;
use crate::jobs::remeasure::remeasure_stored_shapes;
use crate::objects::Objects;

/// Arguments of `aortagen migrate`.
#[derive(Debug, clap::Args)]
pub struct MigrateArgs {
    /// The database (the models directory is not used).
    #[command(flatten)]
    pub storage: StorageConfig,
    /// Also measure again every stored shape an earlier measurement method measured (or
    /// could not measure), from its stored mesh, so shape responses and cohort summaries
    /// show today's values. Safe while the service runs.
    #[arg(long)]
    pub remeasure: bool,
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
        if args.remeasure {
            let objects = Objects::open(&args.storage.blob_store, &pool)?;
            let counts = remeasure_stored_shapes(&pool, &objects, &mut |c| {
                tracing::info!(
                    examined = c.examined,
                    measured = c.measured,
                    failed = c.failed,
                    "measuring stored shapes again"
                );
            })
            .await?;
            tracing::info!(
                examined = counts.examined,
                already_current = counts.current,
                measured = counts.measured,
                failed = counts.failed,
                unreadable = counts.unreadable,
                "stored measurements are current"
            );
            anyhow::ensure!(
                counts.unreadable == 0,
                "stored shapes without a readable mesh: {}; their measurements were left as stored",
                counts.unreadable
            );
        }
        pool.close().await;
        anyhow::Ok(())
    })
}
