//! `spawn_app`: the service on port 0 with a temporary database, a registered analytic
//! model and no background workers; tests run queued jobs themselves.

use std::path::Path;
use std::sync::{Arc, Once};

use aortagen::config::Config;
use aortagen::engine::{Engine, SdfEngine};
use aortagen::http::AppState;
use aortagen::jobs::{ExecutionOutcome, try_execute_job};
use aortagen::sdf::backend::Backend;
use aortagen::startup::{Application, register_model};
use axum::body::Bytes;
use axum::http::{HeaderMap, Method, Request, StatusCode};
use http_body_util::{BodyExt, Full};
use hyper_util::client::legacy::{Client, connect::HttpConnector};
use hyper_util::rt::TokioExecutor;
use serde_json::Value;

use crate::engine::AnalyticEngine;

/// Id of the analytic model every test app has.
pub const MODEL: &str = "ellipsoids";
/// Largest cohort in tests.
pub const MAX_COUNT: u32 = 50;
/// Queue bound in tests.
pub const MAX_QUEUE: i64 = 3;
/// Body limit in tests.
pub const MAX_UPLOAD: usize = 64 * 1024;
/// JSON body limit in tests.
pub const MAX_JSON: usize = 16 * 1024;
/// Most entries of an uploaded zip archive in tests.
pub const MAX_ARCHIVE_ENTRIES: usize = 8;
/// Most bytes an uploaded zip archive may expand to in tests.
pub const MAX_ARCHIVE_BYTES: usize = 256 * 1024;

/// A running test service.
pub struct TestApp<E = AnalyticEngine> {
    /// `http://127.0.0.1:<port>`.
    pub address: String,
    /// Shared state (pool, job context).
    pub state: AppState,
    /// The engine behind the jobs.
    pub engine: Arc<E>,
    /// The database URL (to reopen it).
    pub database_url: String,
    client: Client<HttpConnector, Full<Bytes>>,
    _server: tokio::task::JoinHandle<anyhow::Result<()>>,
    /// Keeps the database directory alive.
    pub dir: Arc<tempfile::TempDir>,
}

/// A collected response.
#[derive(Debug)]
pub struct TestResponse {
    /// Status.
    pub status: StatusCode,
    /// Headers.
    pub headers: HeaderMap,
    /// Body bytes.
    pub body: Bytes,
}

impl TestResponse {
    /// The body as JSON.
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&self.body)))
    }

    /// The `detail` of a problem+json body (panics, showing the body, when there is none).
    pub fn detail(&self) -> String {
        let body = self.json();
        match body["detail"].as_str() {
            Some(detail) => detail.to_owned(),
            None => panic!("no problem detail in {body}"),
        }
    }

    /// A header as text.
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.get(name).and_then(|v| v.to_str().ok())
    }
}

fn init_tracing() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("TEST_LOG").is_some() {
            aortagen::telemetry::init_subscriber("aortagen=debug", false);
        }
    });
}

/// Starts a service with the default analytic engine.
pub async fn spawn_app() -> TestApp {
    spawn_app_with(AnalyticEngine::default()).await
}

/// The server the API tests also run against: `AORTAGEN_TEST_POSTGRES_URL`, a PostgreSQL
/// URL whose user may create databases (`scripts/test` starts one). Unset: SQLite only.
pub fn postgres_server() -> Option<String> {
    std::env::var("AORTAGEN_TEST_POSTGRES_URL")
        .ok()
        .filter(|u| !u.is_empty())
}

/// A new, empty database for one test: a file in `dir` on SQLite, or a database of its own
/// on the PostgreSQL test server when one is configured.
pub async fn fresh_database_url(dir: &Path) -> String {
    match postgres_server() {
        None => format!("sqlite://{}", dir.join("aortagen.db").display()),
        Some(server) => create_postgres_database(&server).await,
    }
}

/// A SQLite database for a test about SQLite itself (its file, its locks, its pragmas).
pub fn sqlite_database_url(dir: &Path) -> String {
    format!("sqlite://{}", dir.join("aortagen.db").display())
}

/// Creates a uniquely named database on the PostgreSQL server and returns its URL.
pub async fn create_postgres_database(server: &str) -> String {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
    let name = format!(
        "test_{}_{n}_{:08x}",
        std::process::id(),
        rand::random::<u32>()
    );
    let admin = aortagen::db::open(server, 1, &Default::default())
        .await
        .expect("the PostgreSQL test server answers");
    sqlx::query(sqlx::AssertSqlSafe(format!("create database {name}")))
        .execute(&admin)
        .await
        .expect("a test database is created");
    admin.close().await;
    let (base, _) = server
        .rsplit_once('/')
        .expect("a server URL ends in /DATABASE");
    format!("{base}/{name}")
}

/// Starts a service on a fresh temporary database with `engine`.
pub async fn spawn_app_with(engine: AnalyticEngine) -> TestApp {
    let dir = Arc::new(tempfile::tempdir().expect("temp dir"));
    let url = fresh_database_url(dir.path()).await;
    spawn_on(engine, dir, url).await
}

/// Starts a service on SQLite whatever the test server, for tests of SQLite's own faults.
pub async fn spawn_sqlite_app_with(engine: AnalyticEngine) -> TestApp {
    let dir = Arc::new(tempfile::tempdir().expect("temp dir"));
    let url = sqlite_database_url(dir.path());
    spawn_on(engine, dir, url).await
}

/// Starts a service with the default analytic engine and settings changed by `configure`.
pub async fn spawn_app_configured(configure: impl FnOnce(&mut Config)) -> TestApp {
    let dir = Arc::new(tempfile::tempdir().expect("temp dir"));
    let url = fresh_database_url(dir.path()).await;
    spawn_on_configured(AnalyticEngine::default(), dir, url, configure).await
}

/// Starts a service on an existing database (a restart).
pub async fn spawn_on(engine: AnalyticEngine, dir: Arc<tempfile::TempDir>, url: String) -> TestApp {
    spawn_on_configured(engine, dir, url, |_| {}).await
}

/// Starts a service on an existing database with the test settings, then `configure`'s.
pub async fn spawn_on_configured(
    engine: AnalyticEngine,
    dir: Arc<tempfile::TempDir>,
    url: String,
    configure: impl FnOnce(&mut Config),
) -> TestApp {
    init_tracing();
    let mut config = Config::with_database(url.clone(), "127.0.0.1:0");
    config.max_count = MAX_COUNT;
    config.max_queue = MAX_QUEUE;
    config.max_upload_bytes = MAX_UPLOAD;
    config.max_json_bytes = MAX_JSON;
    config.max_archive_entries = MAX_ARCHIVE_ENTRIES;
    config.max_archive_bytes = MAX_ARCHIVE_BYTES;
    config.storage.models_dir = dir.path().join("models");
    configure(&mut config);
    let app = start(Arc::new(engine), dir, url, config).await;
    let model_dir = app.dir.path().join("models").join(MODEL);
    register_model(&app.state.pool, app.engine.clone(), MODEL, &model_dir)
        .await
        .expect("model registers");
    app
}

/// Starts a service on the neural engine with copies of `models` (directory names under
/// the repository's `models/`) in its models directory; the bundled `default` registers
/// itself at start. Novelty and pairwise Chamfer use `chamfer_points` samples.
pub async fn spawn_neural(models: &[&str], chamfer_points: usize) -> TestApp<SdfEngine> {
    init_tracing();
    let dir = Arc::new(tempfile::tempdir().expect("temp dir"));
    for name in models {
        let from = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("models")
            .join(name);
        copy_dir(&from, &dir.path().join("models").join(name));
    }
    let url = fresh_database_url(dir.path()).await;
    let mut config = Config::with_database(url.clone(), "127.0.0.1:0");
    config.storage.models_dir = dir.path().join("models");
    let engine = SdfEngine::new(Backend::default()).with_chamfer_points(chamfer_points);
    start(Arc::new(engine), dir, url, config).await
}

/// Copies the files of a directory (one level: model directories are flat).
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        if entry.file_type().unwrap().is_file() {
            std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
        }
    }
}

/// Builds and serves the application (no workers; tests run jobs themselves).
async fn start<E: Engine>(
    engine: Arc<E>,
    dir: Arc<tempfile::TempDir>,
    url: String,
    config: Config,
) -> TestApp<E> {
    let app = Application::build(config, engine.clone())
        .await
        .expect("app builds");
    let state = app.state().clone();
    let address = format!("http://127.0.0.1:{}", app.port());
    let server = tokio::spawn(app.run_until_stopped(0, std::future::pending()));
    let client = Client::builder(TokioExecutor::new()).build_http();
    TestApp {
        address,
        state,
        engine,
        database_url: url,
        client,
        _server: server,
        dir,
    }
}

impl<E> TestApp<E> {
    /// Sends a request.
    pub async fn request(
        &self,
        method: Method,
        path: &str,
        headers: &[(&str, &str)],
        body: impl Into<Bytes>,
    ) -> TestResponse {
        let mut req = Request::builder()
            .method(method)
            .uri(format!("{}{path}", self.address));
        for (k, v) in headers {
            req = req.header(*k, *v);
        }
        let response = self
            .client
            .request(req.body(Full::new(body.into())).unwrap())
            .await
            .expect("request is sent");
        let (parts, body) = response.into_parts();
        let body = body.collect().await.expect("body is read").to_bytes();
        TestResponse {
            status: parts.status,
            headers: parts.headers,
            body,
        }
    }

    /// GET.
    pub async fn get(&self, path: &str) -> TestResponse {
        self.request(Method::GET, path, &[], Bytes::new()).await
    }

    /// GETs `path` until its JSON body satisfies `holds` and returns that body; panics
    /// with the last body after about 30 s (a guard against a hang, not a timing assertion).
    pub async fn poll_json(&self, path: &str, holds: impl Fn(&Value) -> bool) -> Value {
        let mut seen = Value::Null;
        for _ in 0..6000 {
            seen = self.get(path).await.json();
            if holds(&seen) {
                return seen;
            }
            tokio::time::sleep(std::time::Duration::from_millis(5)).await;
        }
        panic!("GET {path} never reached the expected state; last: {seen}");
    }

    /// POST a JSON body.
    pub async fn post_json(&self, path: &str, body: &Value) -> TestResponse {
        let headers = [("content-type", "application/json")];
        self.request(Method::POST, path, &headers, body.to_string())
            .await
    }

    /// POST /v1/cohorts.
    pub async fn create_cohort(&self, body: &Value) -> TestResponse {
        self.post_json("/v1/cohorts", body).await
    }

    /// Creates a cohort, asserting 202, and returns its id.
    pub async fn create_cohort_ok(&self, body: &Value) -> i64 {
        let r = self.create_cohort(body).await;
        assert_eq!(
            r.status,
            StatusCode::ACCEPTED,
            "{}",
            String::from_utf8_lossy(&r.body)
        );
        r.json()["id"].as_i64().unwrap()
    }

    /// `POST /v1/models` with a multipart body of `parts`.
    pub async fn upload_model(&self, parts: &[(&str, Option<&str>, Vec<u8>)]) -> TestResponse {
        let (content_type, body) = multipart(parts);
        self.request(
            Method::POST,
            "/v1/models",
            &[("content-type", &content_type)],
            body,
        )
        .await
    }

    /// Every shape of a cohort's first page, as `GET /v1/shapes/{id}` shows it.
    pub async fn shape_details(&self, cohort: i64) -> Vec<Value> {
        let page = self
            .get(&format!("/v1/cohorts/{cohort}/shapes"))
            .await
            .json();
        let mut out = Vec::new();
        for item in page["items"].as_array().unwrap() {
            let r = self.get(&format!("/v1/shapes/{}", item["id"])).await;
            assert_eq!(r.status, StatusCode::OK);
            out.push(r.json());
        }
        out
    }

    /// Runs queued jobs until the queue is empty; returns what each run did.
    pub async fn run_pending_jobs(&self) -> Vec<ExecutionOutcome> {
        let mut outcomes = Vec::new();
        loop {
            match try_execute_job(&self.state.jobs).await.expect("job runs") {
                ExecutionOutcome::EmptyQueue => return outcomes,
                done => outcomes.push(done),
            }
        }
    }

    /// Runs queued tasks in the background until none is claimable (what one worker does
    /// until it idles); aborting the handle is a process dying mid-task.
    pub fn spawn_pending_jobs(&self) -> tokio::task::JoinHandle<Vec<ExecutionOutcome>>
    where
        E: Send + Sync + 'static,
    {
        let ctx = self.state.jobs.clone();
        tokio::spawn(async move {
            let mut outcomes = Vec::new();
            loop {
                match try_execute_job(&ctx).await.expect("job runs") {
                    ExecutionOutcome::EmptyQueue => return outcomes,
                    done => outcomes.push(done),
                }
            }
        })
    }

    /// Counts rows of a table.
    pub async fn count(&self, table: &str) -> i64 {
        let sql = sqlx::AssertSqlSafe(format!("select count(*) from {table}"));
        sqlx::query_scalar(sql)
            .fetch_one(&self.state.pool)
            .await
            .unwrap()
    }
}

/// A cohort request on the analytic model.
pub fn cohort_body(count: i64, arity: i64) -> Value {
    serde_json::json!({ "model_id": MODEL, "count": count, "arity": arity, "seed": 7, "resolution": 64 })
}

/// `cohort_body(4, 2)` with the fields of `extra` set on it.
pub fn cohort_body_with(extra: Value) -> Value {
    let mut body = cohort_body(4, 2);
    for (k, v) in extra.as_object().unwrap() {
        body[k] = v.clone();
    }
    body
}

/// A multipart/form-data body of `(field, file name, bytes)` parts, with its content type.
pub fn multipart(parts: &[(&str, Option<&str>, Vec<u8>)]) -> (String, Vec<u8>) {
    let boundary = "aortagen-test-boundary";
    let mut body = Vec::new();
    for (name, file, bytes) in parts {
        body.extend_from_slice(
            format!("--{boundary}\r\nContent-Disposition: form-data; name=\"{name}\"").as_bytes(),
        );
        if let Some(f) = file {
            body.extend_from_slice(
                format!("; filename=\"{f}\"\r\nContent-Type: application/octet-stream").as_bytes(),
            );
        }
        body.extend_from_slice(b"\r\n\r\n");
        body.extend_from_slice(bytes);
        body.extend_from_slice(b"\r\n");
    }
    body.extend_from_slice(format!("--{boundary}--\r\n").as_bytes());
    (format!("multipart/form-data; boundary={boundary}"), body)
}
