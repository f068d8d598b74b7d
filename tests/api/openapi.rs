//! The committed OpenAPI document matches the code, and the docs page is self-contained.
//! Regenerate with `AORTAGEN_UPDATE_OPENAPI=1 cargo test --test api openapi`.

use crate::helpers::spawn_app;

const COMMITTED: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/openapi/openapi.json");

#[test]
fn the_committed_openapi_document_matches_the_generated_one() {
    let generated = aortagen::http::openapi::document_json();
    if std::env::var_os("AORTAGEN_UPDATE_OPENAPI").is_some() {
        std::fs::write(COMMITTED, &generated).unwrap();
    }
    let committed = std::fs::read_to_string(COMMITTED).unwrap_or_default();
    assert!(
        committed == generated,
        "openapi/openapi.json is stale; regenerate it with AORTAGEN_UPDATE_OPENAPI=1 cargo test --test api openapi"
    );
}

#[tokio::test]
async fn the_served_document_lists_every_contract_path() {
    let app = spawn_app().await;
    let doc = app.get("/openapi.json").await.json();
    assert_eq!(doc["openapi"], "3.1.0");
    let paths = doc["paths"].as_object().unwrap();
    let contract = [
        ("/healthz", "get"),
        ("/readyz", "get"),
        ("/metrics", "get"),
        ("/openapi.json", "get"),
        ("/docs", "get"),
        ("/v1/models", "get"),
        ("/v1/models", "post"),
        ("/v1/models/{id}", "get"),
        ("/v1/models/{id}", "delete"),
        ("/v1/models/{id}/shapes", "get"),
        ("/v1/cohorts", "post"),
        ("/v1/cohorts", "get"),
        ("/v1/cohorts/{id}", "get"),
        ("/v1/cohorts/{id}", "delete"),
        ("/v1/cohorts/{id}/cancel", "post"),
        ("/v1/cohorts/{id}/shapes", "get"),
        ("/v1/cohorts/{id}/metrics", "get"),
        ("/v1/shapes/{id}", "get"),
        ("/v1/shapes/{id}/mesh", "get"),
        ("/v1/jobs/{id}", "get"),
        ("/v1/jobs/{id}/cancel", "post"),
    ];
    for (path, method) in contract {
        assert!(
            paths.get(path).and_then(|p| p.get(method)).is_some(),
            "{method} {path} is not documented"
        );
    }
}

#[tokio::test]
async fn the_docs_page_loads_nothing_from_elsewhere() {
    let app = spawn_app().await;
    let r = app.get("/docs").await;
    assert_eq!(r.header("content-type"), Some("text/html; charset=utf-8"));
    let html = String::from_utf8(r.body.to_vec()).unwrap();
    assert!(html.contains("/openapi.json"));
    for external in ["src=\"http", "href=\"http", "@import"] {
        assert!(!html.contains(external), "{external}");
    }
}

#[tokio::test]
async fn health_readiness_and_metrics_answer() {
    let app = spawn_app().await;
    assert_eq!(app.get("/healthz").await.json()["status"], "ok");
    assert_eq!(app.get("/readyz").await.json()["status"], "ok");
    app.create_cohort_ok(&crate::helpers::cohort_body(2, 2))
        .await;
    app.run_pending_jobs().await;
    let text = String::from_utf8(app.get("/metrics").await.body.to_vec()).unwrap();
    assert!(
        text.contains("aortagen_jobs{state=\"succeeded\"} 1"),
        "{text}"
    );
    assert!(text.contains("aortagen_shapes_generated_total 2"));
    assert!(
        text.contains(
            "aortagen_task_duration_seconds_count{kind=\"shape\",outcome=\"succeeded\"} 2"
        ),
        "{text}"
    );
    assert!(
        text.contains(
            "aortagen_task_duration_seconds_count{kind=\"metrics\",outcome=\"succeeded\"} 1"
        ),
        "{text}"
    );
    assert!(text.contains("route=\"/v1/cohorts\",status=\"202\""));
    app.state.jobs.controls.shut_down();
    assert_eq!(app.get("/readyz").await.status.as_u16(), 503);
}

/// Reads a counter's value from the Prometheus text.
fn counter(text: &str, name: &str) -> u64 {
    text.lines()
        .find_map(|l| l.strip_prefix(&format!("{name} ")))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("{name} missing in {text}"))
}

#[tokio::test]
async fn concurrent_readiness_checks_share_their_database_writes() {
    let app = spawn_app().await;
    let calls = 64;
    let answers = futures_util::future::join_all((0..calls).map(|_| app.get("/readyz"))).await;
    assert!(answers.iter().all(|r| r.status.as_u16() == 200));
    let text = String::from_utf8(app.get("/metrics").await.body.to_vec()).unwrap();
    let writes = counter(&text, "aortagen_readiness_probes_total");
    assert!(
        writes >= 1 && writes < calls,
        "{writes} writes for {calls} checks"
    );
    // Sequential checks each make their own write, so a fault shows at the next call.
    app.get("/readyz").await;
    let text = String::from_utf8(app.get("/metrics").await.body.to_vec()).unwrap();
    assert_eq!(
        counter(&text, "aortagen_readiness_probes_total"),
        writes + 1
    );
}

#[tokio::test]
async fn made_up_request_methods_do_not_create_metric_series() {
    let app = spawn_app().await;
    for i in 0..20 {
        let method = axum::http::Method::from_bytes(format!("BREW{i}").as_bytes()).unwrap();
        app.request(method, "/v1/cohorts", &[], "").await;
    }
    let text = String::from_utf8(app.get("/metrics").await.body.to_vec()).unwrap();
    assert!(!text.contains("BREW"), "{text}");
    assert!(text.contains("method=\"other\""), "{text}");
}
