//! API keys: state-changing requests need a configured bearer key once any is set, reads
//! only when protected, and the probes never.

use aortagen::config::{ApiKey, Config};
use axum::http::{Method, StatusCode};

use crate::helpers::{TestApp, cohort_body, spawn_app, spawn_app_configured};

const FIRST: &str = "k1-3f9a0c";
const SECOND: &str = "k2-77be41";

fn keys(config: &mut Config) {
    config.api_keys = [FIRST, SECOND].iter().map(|k| k.parse().unwrap()).collect();
}

async fn post_cohort(app: &TestApp, authorization: Option<&str>) -> crate::helpers::TestResponse {
    let mut headers = vec![("content-type", "application/json")];
    if let Some(a) = authorization {
        headers.push(("authorization", a));
    }
    let body = cohort_body(1, 2).to_string();
    app.request(Method::POST, "/v1/cohorts", &headers, body)
        .await
}

#[tokio::test]
async fn without_keys_writes_are_open() {
    let app = spawn_app().await;
    assert_eq!(post_cohort(&app, None).await.status, StatusCode::ACCEPTED);
}

#[tokio::test]
async fn with_keys_writes_need_a_configured_bearer_key() {
    let app = spawn_app_configured(keys).await;

    let missing = post_cohort(&app, None).await;
    assert_eq!(missing.status, StatusCode::UNAUTHORIZED);
    assert_eq!(missing.header("www-authenticate"), Some("Bearer"));
    assert_eq!(
        missing.header("content-type"),
        Some("application/problem+json")
    );
    assert_eq!(missing.json()["status"], 401);

    let malformed = post_cohort(&app, Some(&format!("Basic {FIRST}"))).await;
    assert_eq!(malformed.status, StatusCode::UNAUTHORIZED);

    let wrong = post_cohort(&app, Some("Bearer not-a-key")).await;
    assert_eq!(wrong.status, StatusCode::FORBIDDEN);
    assert_eq!(wrong.json()["status"], 403);
    assert_eq!(
        app.count("cohort").await,
        0,
        "refused requests store nothing"
    );

    let first = post_cohort(&app, Some(&format!("Bearer {FIRST}"))).await;
    assert_eq!(first.status, StatusCode::ACCEPTED);
    let second = post_cohort(&app, Some(&format!("Bearer {SECOND}"))).await;
    assert_eq!(second.status, StatusCode::ACCEPTED);

    let delete = app.request(Method::DELETE, "/v1/cohorts/1", &[], "").await;
    assert_eq!(delete.status, StatusCode::UNAUTHORIZED);
}

#[tokio::test]
async fn keys_can_come_from_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("keys");
    std::fs::write(&file, format!("# service keys\n\n{SECOND}\n")).unwrap();
    let app = spawn_app_configured(|c| c.api_keys_file = Some(file.clone())).await;
    assert_eq!(
        post_cohort(&app, None).await.status,
        StatusCode::UNAUTHORIZED
    );
    let ok = post_cohort(&app, Some(&format!("Bearer {SECOND}"))).await;
    assert_eq!(ok.status, StatusCode::ACCEPTED);
}

#[tokio::test]
async fn reads_are_public_by_default() {
    let app = spawn_app_configured(keys).await;
    assert_eq!(app.get("/v1/cohorts").await.status, StatusCode::OK);
    assert_eq!(app.get("/v1/models").await.status, StatusCode::OK);
}

#[tokio::test]
async fn protected_reads_need_a_key_but_probes_do_not() {
    let app = spawn_app_configured(|c| {
        keys(c);
        c.protect_reads = true;
    })
    .await;
    assert_eq!(
        app.get("/v1/cohorts").await.status,
        StatusCode::UNAUTHORIZED
    );
    let bearer = format!("Bearer {FIRST}");
    let authorised = app
        .request(
            Method::GET,
            "/v1/cohorts",
            &[("authorization", &bearer)],
            "",
        )
        .await;
    assert_eq!(authorised.status, StatusCode::OK);
    let wrong = app
        .request(
            Method::GET,
            "/v1/cohorts",
            &[("authorization", "Bearer nope")],
            "",
        )
        .await;
    assert_eq!(wrong.status, StatusCode::FORBIDDEN);
    for path in ["/healthz", "/readyz", "/metrics"] {
        assert_eq!(app.get(path).await.status, StatusCode::OK, "{path}");
    }
}

#[test]
fn the_configuration_never_shows_a_key() {
    let mut config = Config::with_database("sqlite::memory:", "127.0.0.1:0");
    config.api_keys = vec![FIRST.parse::<ApiKey>().unwrap()];
    let shown = format!("{config:?}");
    assert!(!shown.contains(FIRST), "{shown}");
    assert!(shown.contains("redacted"));
}

/// `aortagen serve` with `AORTAGEN_API_KEYS` set to `value`: its exit status and output,
/// or `None` if it was still running (serving open) when given up on.
fn serve_with_keys(value: &str) -> Option<(std::process::ExitStatus, String)> {
    use std::process::{Command, Stdio};
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("serve.log");
    let file = std::fs::File::create(&log).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_aortagen"))
        .arg("serve")
        .env("AORTAGEN_API_KEYS", value)
        .env_remove("AORTAGEN_API_KEYS_FILE")
        .env("AORTAGEN_BIND", "127.0.0.1:0")
        .env(
            "AORTAGEN_DATABASE_URL",
            format!("sqlite://{}", dir.path().join("a.db").display()),
        )
        .env("AORTAGEN_MODELS_DIR", dir.path().join("models"))
        .stdin(Stdio::null())
        .stdout(file.try_clone().unwrap())
        .stderr(file)
        .spawn()
        .unwrap();
    // A guard against a server that starts and never exits, not a timing assertion.
    for _ in 0..600 {
        if let Some(status) = child.try_wait().unwrap() {
            return Some((status, std::fs::read_to_string(&log).unwrap()));
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    None
}

#[test]
fn a_blank_key_variable_stops_the_service_from_starting_open() {
    for value in ["", " ", ",", " , ,"] {
        let (status, log) = serve_with_keys(value)
            .unwrap_or_else(|| panic!("AORTAGEN_API_KEYS={value:?}: the service ran open"));
        assert!(!status.success(), "{value:?}: {status}");
        assert!(
            log.contains("AORTAGEN_API_KEYS") && log.contains("holds no key"),
            "{value:?}: {log}"
        );
    }
}
