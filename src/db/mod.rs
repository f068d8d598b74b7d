//! SQLite storage: the connection pool, embedded migrations, and one module per table.
//! Only this module writes SQL; every query is a short function taking a pool or a
//! connection and returning a typed row.

pub mod anchors;
pub mod blobs;
pub mod cohort_metrics;
pub mod cohorts;
pub mod ids;
pub mod job_changes;
pub mod jobs;
pub mod models;
pub mod novelty_surfaces;
pub mod references;
pub mod refits;
pub mod shapes;
pub mod simulations;
pub mod states;
pub mod tasks;
pub mod thumbnails;
pub mod validations;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use sqlx::Connection;
use sqlx::any::{AnyConnectOptions, AnyPoolOptions};

pub use values::{Flag, Json, NullableDouble, latent_blob, latent_values};

mod values;

/// The connection pool of either backend. SQL is written once, in the dialect both share
/// (`$n` parameters, `on conflict`, `returning`); what differs is confined to this module
/// and the per-backend migrations.
pub type Pool = sqlx::AnyPool;
/// One connection of [`Pool`] (the inside of a transaction).
pub type Conn = sqlx::AnyConnection;
/// A write transaction opened by [`begin_write`].
pub type Tx = sqlx::Transaction<'static, sqlx::Any>;

/// Anything a query runs on: the pool, or a connection inside a transaction.
pub trait Executor<'e>: sqlx::Executor<'e, Database = sqlx::Any> {}

impl<'e, T: sqlx::Executor<'e, Database = sqlx::Any>> Executor<'e> for T {}

/// The storage engine behind a [`Pool`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// One SQLite file: the embedded default.
    Sqlite,
    /// A PostgreSQL server: several processes and machines share one database.
    Postgres,
}

impl Backend {
    /// The backend a database URL names (`sqlite:` or `postgres:`/`postgresql:`).
    pub fn of_url(url: &str) -> anyhow::Result<Self> {
        match url.split_once(':').map(|(scheme, _)| scheme) {
            Some("sqlite") => Ok(Self::Sqlite),
            Some("postgres" | "postgresql") => Ok(Self::Postgres),
            _ => anyhow::bail!(
                "AORTAGEN_DATABASE_URL must start with sqlite: or postgres: (got {url:?})"
            ),
        }
    }

    /// The backend of an open pool.
    pub fn of(pool: &Pool) -> Self {
        match pool.connect_options().database_url.scheme() {
            "sqlite" => Self::Sqlite,
            _ => Self::Postgres,
        }
    }

    /// A name for logs and `/metrics`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Sqlite => "sqlite",
            Self::Postgres => "postgres",
        }
    }
}

/// How long a connection waits for another writer before giving up.
const BUSY_TIMEOUT: Duration = Duration::from_secs(10);

/// Opens the database at `url` and runs the embedded migrations of its backend. A SQLite
/// file and its directory are created when missing.
pub async fn connect(url: &str, max_connections: u32) -> anyhow::Result<Pool> {
    connect_with_switch(url, max_connections, &ReadOnlySwitch::default()).await
}

/// [`connect`] with a [`ReadOnlySwitch`] consulted whenever a connection leaves the pool.
pub async fn connect_with_switch(
    url: &str,
    max_connections: u32,
    switch: &ReadOnlySwitch,
) -> anyhow::Result<Pool> {
    let pool = open(url, max_connections, switch).await?;
    migrate(&pool).await?;
    Ok(pool)
}

/// Opens the database at `url` without touching its schema (what a worker does: only
/// `aortagen migrate` and `aortagen serve` change the schema).
pub async fn open(
    url: &str,
    max_connections: u32,
    switch: &ReadOnlySwitch,
) -> anyhow::Result<Pool> {
    sqlx::any::install_default_drivers();
    let backend = Backend::of_url(url)?;
    let url = match backend {
        Backend::Sqlite => prepare_sqlite_file(url).await?,
        Backend::Postgres => url.to_owned(),
    };
    let options: AnyConnectOptions = url
        .parse()
        .with_context(|| format!("invalid database URL {}", redact(&url)))?;
    let switch = switch.clone();
    let pool = AnyPoolOptions::new()
        .after_connect(move |conn, _| {
            Box::pin(async move {
                if backend == Backend::Sqlite {
                    sqlx::Executor::execute(&mut *conn, SQLITE_CONNECTION_PRAGMAS).await?;
                }
                Ok(())
            })
        })
        .before_acquire(move |conn, _| {
            let switch = switch.clone();
            Box::pin(async move {
                if backend == Backend::Sqlite {
                    switch.apply(conn).await?;
                }
                Ok(true)
            })
        })
        .max_connections(max_connections)
        .acquire_timeout(Duration::from_secs(30))
        .connect_with(options)
        .await
        .with_context(|| format!("cannot open the database {}", redact(&url)))?;
    Ok(pool)
}

/// Per-connection SQLite settings: a busy timeout so writers queue instead of failing,
/// foreign keys (off by default in SQLite; the schema relies on them for cascades), and
/// `synchronous = normal`, which is durable in WAL mode.
const SQLITE_CONNECTION_PRAGMAS: &str = concat!(
    "pragma busy_timeout = 10000; ",
    "pragma foreign_keys = on; ",
    "pragma synchronous = normal;"
);

/// Creates a SQLite file's directory and the file itself in WAL mode (readers proceed while
/// a worker commits shapes; the mode is stored in the file), once, before the pool opens
/// connections to it; returns the URL to open.
async fn prepare_sqlite_file(url: &str) -> anyhow::Result<String> {
    use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode};
    use std::str::FromStr;
    let options = SqliteConnectOptions::from_str(url)
        .with_context(|| format!("invalid database URL {url:?}"))?
        .create_if_missing(true)
        .journal_mode(SqliteJournalMode::Wal)
        .busy_timeout(BUSY_TIMEOUT);
    let file = options.get_filename().to_path_buf();
    if let Some(dir) = file.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the database directory {}", dir.display()))?;
    }
    let conn = sqlx::SqliteConnection::connect_with(&options)
        .await
        .with_context(|| format!("cannot open the database {}", file.display()))?;
    conn.close().await?;
    Ok(url.to_owned())
}

/// A database URL with its password replaced, for messages.
pub fn redact(url: &str) -> String {
    match url::Url::parse(url) {
        Ok(mut parsed) if parsed.password().is_some() => {
            let _ = parsed.set_password(Some("***"));
            parsed.to_string()
        }
        _ => url.to_owned(),
    }
}

/// Applies the migrations of the pool's backend, embedded from `migrations/<backend>/` at
/// compile time. Both sets carry the same version numbers and describe the same schema
/// (a test compares them).
pub async fn migrate(pool: &Pool) -> anyhow::Result<()> {
    migrator(pool)
        .run(pool)
        .await
        .context("cannot apply database migrations")
}

/// The migrations embedded for the pool's backend.
fn migrator(pool: &Pool) -> sqlx::migrate::Migrator {
    match Backend::of(pool) {
        Backend::Sqlite => sqlx::migrate!("migrations/sqlite"),
        Backend::Postgres => sqlx::migrate!("migrations/postgres"),
    }
}

/// Checks that the database has every migration this version embeds, and no other (what a
/// worker does instead of migrating: only `aortagen migrate` and `aortagen serve` change
/// the schema, so a worker of another version never touches it).
pub async fn require_current_schema(pool: &Pool) -> anyhow::Result<()> {
    let expected: Vec<i64> = migrator(pool).iter().map(|m| m.version).collect();
    let applied: Vec<i64> =
        sqlx::query_scalar("select version from _sqlx_migrations where success order by version")
            .fetch_all(pool)
            .await
            .context("cannot read the database's migrations (run `aortagen migrate` first)")?;
    let missing: Vec<i64> = expected
        .iter()
        .filter(|v| !applied.contains(v))
        .copied()
        .collect();
    let unknown: Vec<i64> = applied
        .iter()
        .filter(|v| !expected.contains(v))
        .copied()
        .collect();
    anyhow::ensure!(
        missing.is_empty(),
        "the database lacks migrations {missing:?}: run `aortagen migrate` with this version first"
    );
    anyhow::ensure!(
        unknown.is_empty(),
        "the database has migrations {unknown:?} this version does not know: it was migrated by a newer version"
    );
    Ok(())
}

/// Opens a write transaction. On SQLite it takes the write lock up front
/// (`BEGIN IMMEDIATE`): a deferred transaction that reads first and writes later can fail
/// with SQLITE_BUSY at once instead of waiting for the busy timeout. PostgreSQL's row locks
/// need nothing special.
pub async fn begin_write(pool: &Pool) -> sqlx::Result<Tx> {
    match Backend::of(pool) {
        Backend::Sqlite => pool.begin_with("BEGIN IMMEDIATE").await,
        Backend::Postgres => pool.begin().await,
    }
}

/// True when `err` is a violated UNIQUE constraint. SQLite reports no constraint names,
/// so callers branch on the kind and know from context which constraint it was.
pub fn is_unique_violation(err: &sqlx::Error) -> bool {
    matches!(err, sqlx::Error::Database(db) if db.is_unique_violation())
}

/// True when `err` is a violated foreign key: a row named a row another transaction just
/// deleted, or a delete met a row another transaction just made refer to it.
pub fn is_foreign_key_violation(err: &sqlx::Error) -> bool {
    matches!(err, sqlx::Error::Database(db) if db.is_foreign_key_violation())
}

/// [`is_foreign_key_violation`] anywhere in an error chain.
pub fn foreign_key_violation_in(err: &anyhow::Error) -> bool {
    err.chain().any(|cause| {
        cause
            .downcast_ref::<sqlx::Error>()
            .is_some_and(is_foreign_key_violation)
    })
}

/// Why storage cannot take writes; the condition may clear without a restart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StorageFault {
    /// The database file (or its directory or file system) is read-only.
    ReadOnly,
    /// The disk or quota is full.
    Full,
    /// The storage device reported an I/O error.
    Io,
    /// The database server cannot be reached (down, restarting, out of connections).
    Unreachable,
    /// The external object store failed (unreachable, refusing, full).
    ObjectStore,
}

impl std::fmt::Display for StorageFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::ReadOnly => "database is read-only",
            Self::Full => "disk is full",
            Self::Io => "storage I/O error",
            Self::Unreachable => "database unreachable",
            Self::ObjectStore => "object store unavailable",
        })
    }
}

/// A failure of the external object store itself (unreachable, refusing, out of space),
/// raised by `objects`: a storage fault, so work waits and retries instead of failing.
#[derive(Debug, thiserror::Error)]
#[error("object store {store}: {source}")]
pub struct ObjectStoreFault {
    /// The store's URL.
    pub store: String,
    /// What the store answered.
    #[source]
    pub source: Box<dyn std::error::Error + Send + Sync>,
}

/// Classifies a database error as a storage fault: SQLite's primary result codes
/// (SQLITE_READONLY, SQLITE_FULL, SQLITE_IOERR, SQLITE_CANTOPEN), PostgreSQL's SQLSTATEs
/// (read-only transaction, disk full, I/O error), a server that cannot be reached, or the
/// I/O error kind.
pub fn storage_fault(err: &sqlx::Error) -> Option<StorageFault> {
    match err {
        sqlx::Error::Database(db) => {
            let code = db.code()?;
            if db.try_downcast_ref::<sqlx::sqlite::SqliteError>().is_some() {
                let code: i32 = code.parse().ok()?;
                return match code & 0xff {
                    8 => Some(StorageFault::ReadOnly),
                    13 => Some(StorageFault::Full),
                    10 | 14 => Some(StorageFault::Io),
                    _ => None,
                };
            }
            match &*code {
                "25006" => Some(StorageFault::ReadOnly),
                "53100" => Some(StorageFault::Full),
                "58030" => Some(StorageFault::Io),
                // the server is shutting down or restarting, or refuses connections for now
                "57P01" | "57P02" | "57P03" | "53300" => Some(StorageFault::Unreachable),
                _ => None,
            }
        }
        sqlx::Error::Io(io) => io_fault(io).or(Some(StorageFault::Unreachable)),
        sqlx::Error::PoolTimedOut | sqlx::Error::PoolClosed => Some(StorageFault::Unreachable),
        _ => None,
    }
}

/// The first storage fault in an error chain (database errors and file writes).
pub fn storage_fault_in(err: &anyhow::Error) -> Option<StorageFault> {
    err.chain().find_map(|cause| {
        if let Some(e) = cause.downcast_ref::<sqlx::Error>() {
            storage_fault(e)
        } else if let Some(e) = cause.downcast_ref::<std::io::Error>() {
            io_fault(e)
        } else if cause.is::<ObjectStoreFault>() {
            Some(StorageFault::ObjectStore)
        } else {
            None
        }
    })
}

fn io_fault(err: &std::io::Error) -> Option<StorageFault> {
    use std::io::ErrorKind;
    match err.kind() {
        ErrorKind::ReadOnlyFilesystem => Some(StorageFault::ReadOnly),
        ErrorKind::StorageFull | ErrorKind::QuotaExceeded => Some(StorageFault::Full),
        _ => None,
    }
}

/// Checks that the database takes a write: an upsert of the single probe row, committed.
/// It fails the way real writes fail when the file is read-only or the disk is full.
pub async fn probe_write(pool: &Pool) -> sqlx::Result<()> {
    sqlx::query(
        "insert into storage_probe (id, checked_at) values (1, strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
         on conflict (id) do update set checked_at = excluded.checked_at",
    )
    .execute(pool)
    .await?;
    Ok(())
}

/// Fault injection: while on, every connection taken from the pool is set to
/// `PRAGMA query_only`, so each write fails with SQLITE_READONLY exactly as on a read-only
/// database file, and reads keep working. It costs nothing until first switched on.
#[derive(Debug, Clone, Default)]
pub struct ReadOnlySwitch {
    on: Arc<AtomicBool>,
    used: Arc<AtomicBool>,
}

impl ReadOnlySwitch {
    /// Turns the fault on or off; connections pick it up when next acquired.
    pub fn set(&self, read_only: bool) {
        self.used.store(true, Ordering::SeqCst);
        self.on.store(read_only, Ordering::SeqCst);
    }

    async fn apply(&self, conn: &mut Conn) -> sqlx::Result<()> {
        if !self.used.load(Ordering::SeqCst) {
            return Ok(());
        }
        let sql = if self.on.load(Ordering::SeqCst) {
            "pragma query_only = 1"
        } else {
            "pragma query_only = 0"
        };
        sqlx::query(sql).execute(conn).await?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn storage_faults_are_found_anywhere_in_an_error_chain() {
        let full = std::io::Error::from(std::io::ErrorKind::StorageFull);
        let err = anyhow::Error::from(full).context("cannot write 0001.stl");
        assert_eq!(storage_fault_in(&err), Some(StorageFault::Full));
        let ro = sqlx::Error::Io(std::io::ErrorKind::ReadOnlyFilesystem.into());
        assert_eq!(storage_fault(&ro), Some(StorageFault::ReadOnly));
        let other = anyhow::anyhow!("engine diverged");
        assert_eq!(storage_fault_in(&other), None);
    }

    #[tokio::test]
    async fn the_switch_makes_writes_fail_as_on_a_read_only_file_and_reads_work() {
        let dir = tempfile::tempdir().unwrap();
        let url = format!("sqlite://{}", dir.path().join("t.db").display());
        let switch = ReadOnlySwitch::default();
        let pool = connect_with_switch(&url, 2, &switch).await.unwrap();
        probe_write(&pool).await.unwrap();
        switch.set(true);
        let err = probe_write(&pool).await.unwrap_err();
        assert_eq!(storage_fault(&err), Some(StorageFault::ReadOnly), "{err}");
        let n: i64 = sqlx::query_scalar("select count(*) from storage_probe")
            .fetch_one(&pool)
            .await
            .unwrap();
        assert_eq!(n, 1);
        switch.set(false);
        probe_write(&pool).await.unwrap();
    }
}
