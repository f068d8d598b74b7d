//! Service configuration: every setting is a flag with an `AORTAGEN_*` environment variable
//! and a default, so `aortagen serve` runs with none and containers configure by env.

use std::path::PathBuf;

/// Settings of `aortagen serve`.
#[derive(Debug, Clone, clap::Args)]
pub struct Config {
    /// Address to listen on (port 0 picks a free port).
    #[arg(long, env = "AORTAGEN_BIND", default_value = "127.0.0.1:8080")]
    pub bind: String,

    /// SQLite database URL; the file and its directory are created when missing.
    #[arg(
        long = "database",
        env = "AORTAGEN_DATABASE_URL",
        default_value = "sqlite://data/aortagen.db"
    )]
    pub database_url: String,

    /// Worker tasks running jobs concurrently [default: number of CPU cores].
    #[arg(long, env = "AORTAGEN_WORKERS")]
    pub workers: Option<usize>,

    /// Jobs allowed to wait or run at once; further submissions get 429.
    #[arg(long, env = "AORTAGEN_MAX_QUEUE", default_value_t = 64)]
    pub max_queue: i64,

    /// Largest cohort a request may ask for.
    #[arg(long, env = "AORTAGEN_MAX_COUNT", default_value_t = 1000)]
    pub max_count: u32,

    /// Largest accepted request body in bytes (model uploads).
    #[arg(long, env = "AORTAGEN_MAX_UPLOAD_BYTES", default_value_t = 256 * 1024 * 1024)]
    pub max_upload_bytes: usize,

    /// Most entries in an uploaded zip archive of training meshes.
    #[arg(long, env = "AORTAGEN_MAX_ARCHIVE_ENTRIES", default_value_t = 1000)]
    pub max_archive_entries: usize,

    /// Most bytes an uploaded zip archive may expand to (guards against zip bombs).
    #[arg(long, env = "AORTAGEN_MAX_ARCHIVE_BYTES", default_value_t = 1024 * 1024 * 1024)]
    pub max_archive_bytes: usize,

    /// Directory of models: the bundled model lives in `<dir>/default`, trained ones next to it.
    #[arg(long, env = "AORTAGEN_MODELS_DIR", default_value = "models")]
    pub models_dir: PathBuf,

    /// Seconds a request may take before it is answered 408.
    #[arg(long, env = "AORTAGEN_REQUEST_TIMEOUT_SECS", default_value_t = 30)]
    pub request_timeout_secs: u64,

    /// Seconds clients are told to wait when the queue is full (Retry-After).
    #[arg(long, env = "AORTAGEN_RETRY_AFTER_SECS", default_value_t = 30)]
    pub retry_after_secs: u64,

    /// Times in a row a job may be interrupted by a dying process without committing any
    /// progress before it is failed.
    #[arg(long, env = "AORTAGEN_MAX_ATTEMPTS", default_value_t = 5)]
    pub max_attempts: i64,

    /// Log as JSON lines instead of human-readable text.
    #[arg(long, env = "AORTAGEN_LOG_JSON", default_value_t = false)]
    pub log_json: bool,
}

impl Config {
    /// Defaults with a different database and bind address (tests, embedding).
    pub fn with_database(database_url: impl Into<String>, bind: impl Into<String>) -> Self {
        #[derive(clap::Parser)]
        struct Wrapper {
            #[command(flatten)]
            config: Config,
        }
        let mut config = <Wrapper as clap::Parser>::parse_from(["aortagen"]).config;
        config.database_url = database_url.into();
        config.bind = bind.into();
        config
    }

    /// The worker count actually used.
    pub fn worker_count(&self) -> usize {
        self.workers
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
            .max(1)
    }
}
