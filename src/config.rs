//! Service configuration: every setting is a flag with an `AORTAGEN_*` environment variable
//! and a default, so `aortagen serve` runs with none and containers configure by env.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

/// An API key as configured. Its `Debug` is redacted so a logged or printed configuration
/// never shows it.
#[derive(Clone, PartialEq, Eq)]
pub struct ApiKey(String);

impl ApiKey {
    /// The key text.
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for ApiKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("ApiKey(<redacted>)")
    }
}

impl FromStr for ApiKey {
    type Err = std::convert::Infallible;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(Self(s.trim().to_owned()))
    }
}

/// Where the service keeps its state: shared by `serve`, `worker` and `migrate`, so every
/// process of a deployment is configured the same way.
#[derive(Debug, Clone, clap::Args)]
pub struct StorageConfig {
    /// Database URL: `sqlite://FILE` (the embedded default; the file and its directory are
    /// created when missing) or `postgres://USER:PASSWORD@HOST/DB` (several processes and
    /// machines share it).
    #[arg(
        long = "database",
        env = "AORTAGEN_DATABASE_URL",
        default_value = "sqlite://data/aortagen.db"
    )]
    pub database_url: String,

    /// Directory of models: the bundled model lives in `<dir>/default`, trained ones next to
    /// it, and models fetched from the object store in `<dir>/.fetched`.
    #[arg(long, env = "AORTAGEN_MODELS_DIR", default_value = "models")]
    pub models_dir: PathBuf,

    /// Where meshes and model bundles are kept: `db` (the database's `blob` table),
    /// `file:///DIR` (a local or shared directory) or `s3://BUCKET/PREFIX` (an
    /// S3-compatible store, configured by `AWS_ENDPOINT_URL`, `AWS_ACCESS_KEY_ID`,
    /// `AWS_SECRET_ACCESS_KEY`, `AWS_REGION` and `AWS_ALLOW_HTTP`). Every process of a
    /// deployment names the same store.
    #[arg(long = "blob-store", env = "AORTAGEN_BLOB_STORE", default_value = "db")]
    pub blob_store: crate::objects::BlobStoreUrl,
}

impl StorageConfig {
    /// Where models fetched by digest are unpacked.
    pub fn fetched_models_dir(&self) -> PathBuf {
        self.models_dir.join(".fetched")
    }
}

/// How a process runs tasks: shared by `serve` and `worker`.
#[derive(Debug, Clone, clap::Args)]
pub struct WorkerConfig {
    /// Worker tasks running jobs concurrently [default: number of CPU cores]; 0 with `serve`
    /// runs the API alone (workers elsewhere take the work).
    #[arg(long, env = "AORTAGEN_WORKERS")]
    pub workers: Option<usize>,

    /// Seconds a worker holds a task without renewing its lease; a worker silent for longer
    /// (dead, paused, cut off) loses the task to another. Renewed every tenth of it.
    #[arg(long, env = "AORTAGEN_LEASE_SECS", default_value_t = 30,
          value_parser = clap::value_parser!(u64).range(1..=3600))]
    pub lease_secs: u64,

    /// Leases of one task that may expire in a row (its workers died or hung) before the
    /// task and its job are failed.
    #[arg(long, env = "AORTAGEN_MAX_ATTEMPTS", default_value_t = 5,
          value_parser = clap::value_parser!(i64).range(1..))]
    pub max_attempts: i64,

    /// Nice value (0–19) of the threads that train and generate: above 0 the API answers
    /// first when it competes with them for a core.
    #[arg(long, env = "AORTAGEN_WORKER_NICE", default_value_t = 10,
          value_parser = clap::value_parser!(i32).range(0..=19))]
    pub worker_nice: i32,
}

impl WorkerConfig {
    /// The worker count actually used (0: none).
    pub fn worker_count(&self) -> usize {
        self.workers
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
    }

    /// Lease length, renewal interval and stall bound.
    pub fn leases(&self) -> crate::jobs::LeaseSettings {
        let lease = std::time::Duration::from_secs(self.lease_secs);
        crate::jobs::LeaseSettings {
            lease,
            heartbeat: (lease / 10).max(std::time::Duration::from_millis(100)),
            max_stalls: self.max_attempts,
        }
    }
}

/// Settings of `aortagen serve`.
#[derive(Debug, Clone, clap::Args)]
pub struct Config {
    /// Address to listen on (port 0 picks a free port).
    #[arg(long, env = "AORTAGEN_BIND", default_value = "127.0.0.1:8080")]
    pub bind: String,

    /// Database and models.
    #[command(flatten)]
    pub storage: StorageConfig,

    /// Workers in this process.
    #[command(flatten)]
    pub work: WorkerConfig,

    /// Jobs allowed to wait or run at once; further submissions get 429.
    #[arg(long, env = "AORTAGEN_MAX_QUEUE", default_value_t = 64)]
    pub max_queue: i64,

    /// Largest cohort a request may ask for.
    #[arg(long, env = "AORTAGEN_MAX_COUNT", default_value_t = 1000)]
    pub max_count: u32,

    /// Largest accepted request body in bytes (model uploads).
    #[arg(long, env = "AORTAGEN_MAX_UPLOAD_BYTES", default_value_t = 256 * 1024 * 1024)]
    pub max_upload_bytes: usize,

    /// Largest accepted JSON request body in bytes; larger ones get 413.
    #[arg(long, env = "AORTAGEN_MAX_JSON_BYTES", default_value_t = 1024 * 1024)]
    pub max_json_bytes: usize,

    /// Largest work of one cohort in field-evaluation voxels, `(count × draws per shape +
    /// training shapes first reconstructed at this resolution) × resolution³`; larger
    /// requests get 422. The default holds 100 shapes at 256³ on a model of 100 training
    /// shapes asked at that resolution for the first time.
    #[arg(
        long,
        env = "AORTAGEN_MAX_COHORT_VOXELS",
        default_value_t = 4_000_000_000
    )]
    pub max_cohort_voxels: u64,

    /// Largest shape-level work of one validation, Chamfer distances × surface points per
    /// shape; larger requests get 422 naming `points`. The default holds 10 times the
    /// 100-shape cohort against 20 held-out and 80 training shapes at 10 000 points.
    #[arg(
        long,
        env = "AORTAGEN_MAX_VALIDATION_WORK",
        default_value_t = 2_000_000_000
    )]
    pub max_validation_work: u64,

    /// Largest isotropic remesh of one simulation mesh, in triangles (surface area over an
    /// equilateral triangle of edge `remesh_mm`); finer requests get 422 naming
    /// `remesh_mm` and the finest edge within it. The default is about fifteen seconds of
    /// one core, e.g. `remesh_mm` 0.35 on a 25 000 mm² aorta.
    #[arg(long, env = "AORTAGEN_MAX_REMESH_TRIANGLES", default_value_t = 500_000)]
    pub max_remesh_triangles: u64,

    /// Requests handled at once; further ones get 503 with Retry-After (probes excepted).
    #[arg(long, env = "AORTAGEN_MAX_IN_FLIGHT", default_value_t = 512)]
    pub max_in_flight: usize,

    /// API keys (comma-separated). When any key is configured, state-changing requests
    /// need `Authorization: Bearer <key>`.
    #[arg(
        long = "api-keys",
        env = "AORTAGEN_API_KEYS",
        value_delimiter = ',',
        hide_env_values = true
    )]
    pub api_keys: Vec<ApiKey>,

    /// File of API keys, one per line; blank lines and `#` comments are ignored.
    #[arg(long, env = "AORTAGEN_API_KEYS_FILE")]
    pub api_keys_file: Option<PathBuf>,

    /// Require an API key for reads too (health, readiness and metrics stay public).
    #[arg(long, env = "AORTAGEN_PROTECT_READS", default_value_t = false)]
    pub protect_reads: bool,
    /// Most entries in an uploaded zip archive of training meshes.
    #[arg(long, env = "AORTAGEN_MAX_ARCHIVE_ENTRIES", default_value_t = 1000)]
    pub max_archive_entries: usize,

    /// Most bytes the zip archives of one upload may expand to together (guards against zip
    /// bombs).
    #[arg(long, env = "AORTAGEN_MAX_ARCHIVE_BYTES", default_value_t = 1024 * 1024 * 1024)]
    pub max_archive_bytes: usize,

    /// Memory for encoded mesh downloads kept for repeated requests, in bytes (0: none).
    #[arg(long, env = "AORTAGEN_MESH_CACHE_BYTES", default_value_t = 64 * 1024 * 1024)]
    pub mesh_cache_bytes: usize,

    /// Seconds a request may take before it is answered 408.
    #[arg(long, env = "AORTAGEN_REQUEST_TIMEOUT_SECS", default_value_t = 30)]
    pub request_timeout_secs: u64,

    /// Seconds a client may take to send a request's headers, and may keep a connection idle
    /// between requests, before the connection is closed (guards against slow-header clients).
    #[arg(long, env = "AORTAGEN_HEADER_TIMEOUT_SECS", default_value_t = 15,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub header_timeout_secs: u64,

    /// Most client connections open at once; further clients wait in the listen backlog.
    #[arg(long, env = "AORTAGEN_MAX_CONNECTIONS", default_value_t = 1024,
          value_parser = clap::value_parser!(u64).range(1..=65_536))]
    pub max_connections: u64,

    /// Seconds a model upload (`POST /v1/models`, multipart or a zip body) may take before it
    /// is answered 408; longer than the request timeout so a large upload on a slow link completes.
    #[arg(long, env = "AORTAGEN_UPLOAD_TIMEOUT_SECS", default_value_t = 600)]
    pub upload_timeout_secs: u64,

    /// Seconds clients are told to wait when the queue is full (Retry-After).
    #[arg(long, env = "AORTAGEN_RETRY_AFTER_SECS", default_value_t = 30)]
    pub retry_after_secs: u64,

    /// Log as JSON lines instead of human-readable text.
    #[arg(long, env = "AORTAGEN_LOG_JSON", default_value_t = false)]
    pub log_json: bool,
}

#[derive(clap::Parser)]
struct Wrapper {
    #[command(flatten)]
    config: Config,
}

impl Config {
    /// Defaults with a different database and bind address (tests, embedding).
    pub fn with_database(database_url: impl Into<String>, bind: impl Into<String>) -> Self {
        let mut config = <Wrapper as clap::Parser>::parse_from(["aortagen"]).config;
        config.storage.database_url = database_url.into();
        config.bind = bind.into();
        config
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn api_keys_are_a_comma_separated_list_and_debug_hides_them() {
        let args = ["aortagen", "--api-keys", "alpha, beta", "--protect-reads"];
        let config = <Wrapper as clap::Parser>::parse_from(args).config;
        let keys: Vec<&str> = config.api_keys.iter().map(ApiKey::expose).collect();
        assert_eq!(keys, ["alpha", "beta"]);
        assert!(config.protect_reads);
        let shown = format!("{config:?}");
        assert!(
            !shown.contains("alpha") && !shown.contains("beta"),
            "{shown}"
        );
    }

    #[test]
    fn default_limits_allow_100_shapes_at_256() {
        let config = Config::with_database("sqlite::memory:", "127.0.0.1:0");
        // 100 drawn shapes plus the first reconstruction of 100 training shapes.
        assert!((100 + 100) * 256u64.pow(3) <= config.max_cohort_voxels);
        assert_eq!(config.max_json_bytes, 1024 * 1024);
        assert_eq!(config.max_in_flight, 512);
        // The 100-shape experiment of docs/representative at the default 10 000 points.
        let pairs = crate::validation::shapes::chamfer_pairs(100, 20, 80, 0, false);
        assert_eq!(pairs, 19_920);
        assert!(pairs * 10_000 * 10 <= config.max_validation_work);
    }
}
