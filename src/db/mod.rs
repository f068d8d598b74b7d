//! SQLite storage: the connection pool, embedded migrations, and one module per table.
//! Only this module writes SQL; every query is a short function taking a pool or a
//! connection and returning a typed row.

pub mod cohort_metrics;
pub mod cohorts;
pub mod jobs;
pub mod mesh_blob;
pub mod models;
pub mod shapes;

use std::str::FromStr;
use std::time::Duration;

use anyhow::Context;
use sqlx::SqlitePool;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};

/// The statement that opens every write transaction. A deferred transaction that reads
/// first and writes later can fail with SQLITE_BUSY at once instead of waiting, so writers
/// take the write lock up front and let the busy timeout do its job.
pub const BEGIN_WRITE: &str = "BEGIN IMMEDIATE";

/// How long a connection waits for another writer before giving up.
const BUSY_TIMEOUT: Duration = Duration::from_secs(10);

/// Opens (creating if needed) the SQLite database at `url` and runs the embedded migrations.
///
/// WAL lets readers proceed while a worker commits shapes; foreign keys are off by default
/// in SQLite and the schema relies on them for cascades.
pub async fn connect(url: &str, max_connections: u32) -> anyhow::Result<SqlitePool> {
    let options = SqliteConnectOptions::from_str(url)
        .with_context(|| format!("invalid database URL {url:?}"))?
        .create_if_missing(true)
        .journal_mode(SqliteJournalMode::Wal)
        .synchronous(SqliteSynchronous::Normal)
        .busy_timeout(BUSY_TIMEOUT)
        .foreign_keys(true);
    let file = options.get_filename().to_path_buf();
    if let Some(dir) = file.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the database directory {}", dir.display()))?;
    }
    let pool = SqlitePoolOptions::new()
        .max_connections(max_connections)
        .acquire_timeout(Duration::from_secs(30))
        .connect_with(options)
        .await
        .with_context(|| format!("cannot open the database {}", file.display()))?;
    migrate(&pool).await?;
    Ok(pool)
}

/// Applies the migrations embedded from `migrations/` at compile time.
pub async fn migrate(pool: &SqlitePool) -> anyhow::Result<()> {
    sqlx::migrate!()
        .run(pool)
        .await
        .context("cannot apply database migrations")
}

/// True when `err` is a violated UNIQUE constraint. SQLite reports no constraint names,
/// so callers branch on the kind and know from context which constraint it was.
pub fn is_unique_violation(err: &sqlx::Error) -> bool {
    matches!(err, sqlx::Error::Database(db) if db.is_unique_violation())
}
