//! SQLite storage: the connection pool, embedded migrations, and one module per table.
//! Only this module writes SQL; every query is a short function taking a pool or a
//! connection and returning a typed row.

pub mod anchors;
pub mod cohort_metrics;
pub mod cohorts;
pub mod ids;
pub mod job_changes;
pub mod jobs;
pub mod models;
pub mod novelty_surfaces;
pub mod shapes;
pub mod simulations;
pub mod states;
pub mod thumbnails;

use std::str::FromStr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
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
    connect_with_switch(url, max_connections, &ReadOnlySwitch::default()).await
}

/// [`connect`] with a [`ReadOnlySwitch`] consulted whenever a connection leaves the pool.
pub async fn connect_with_switch(
    url: &str,
    max_connections: u32,
    switch: &ReadOnlySwitch,
) -> anyhow::Result<SqlitePool> {
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
    let switch = switch.clone();
    let pool = SqlitePoolOptions::new()
        .before_acquire(move |conn, _| {
            let switch = switch.clone();
            Box::pin(async move {
                switch.apply(conn).await?;
                Ok(true)
            })
        })
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

/// Why storage cannot take writes; the condition may clear without a restart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StorageFault {
    /// The database file (or its directory or file system) is read-only.
    ReadOnly,
    /// The disk or quota is full.
    Full,
    /// The storage device reported an I/O error.
    Io,
}

impl std::fmt::Display for StorageFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::ReadOnly => "database is read-only",
            Self::Full => "disk is full",
            Self::Io => "storage I/O error",
        })
    }
}

/// Classifies a database error as a storage fault by SQLite's primary result code
/// (SQLITE_READONLY, SQLITE_FULL, SQLITE_IOERR, SQLITE_CANTOPEN) or the I/O error kind.
pub fn storage_fault(err: &sqlx::Error) -> Option<StorageFault> {
    match err {
        sqlx::Error::Database(db) => {
            let code: i32 = db.code()?.parse().ok()?;
            match code & 0xff {
                8 => Some(StorageFault::ReadOnly),
                13 => Some(StorageFault::Full),
                10 | 14 => Some(StorageFault::Io),
                _ => None,
            }
        }
        sqlx::Error::Io(io) => io_fault(io),
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
pub async fn probe_write(pool: &SqlitePool) -> sqlx::Result<()> {
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

    async fn apply(&self, conn: &mut sqlx::SqliteConnection) -> sqlx::Result<()> {
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
