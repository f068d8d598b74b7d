//! Request limits: JSON body size (413), request deadline (408), requests in flight (503 +
//! Retry-After) and the per-cohort work budget (422), each as a problem document.

use std::time::Duration;

use axum::http::StatusCode;
use serde_json::json;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::helpers::{MODEL, TestApp, TestResponse, cohort_body, spawn_app, spawn_app_configured};

/// Opens a connection and sends a POST whose body stops short of its Content-Length, so
/// the handler waits for the rest while the connection stays open.
async fn send_incomplete_post(app: &TestApp) -> TcpStream {
    let host = app.address.trim_start_matches("http://");
    let mut stream = TcpStream::connect(host).await.unwrap();
    let head = format!(
        "POST /v1/cohorts HTTP/1.1\r\nhost: {host}\r\ncontent-type: application/json\r\n\
         content-length: 200\r\n\r\n{{\"model_id\": "
    );
    stream.write_all(head.as_bytes()).await.unwrap();
    stream.flush().await.unwrap();
    stream
}

#[tokio::test]
async fn a_json_body_over_the_limit_is_413() {
    let app = spawn_app_configured(|c| c.max_json_bytes = 300).await;
    let mut body = cohort_body(1, 2);
    body["model_id"] = json!("m".repeat(400));
    let r = app.create_cohort(&body).await;
    assert_eq!(r.status, StatusCode::PAYLOAD_TOO_LARGE);
    assert_eq!(r.header("content-type"), Some("application/problem+json"));
    assert!(r.detail().contains("300 bytes"));
    // Under the limit the same endpoint accepts.
    assert_eq!(
        app.create_cohort(&cohort_body(1, 2)).await.status,
        StatusCode::ACCEPTED
    );
}

#[tokio::test]
async fn a_request_over_the_deadline_is_408() {
    let app = spawn_app_configured(|c| c.request_timeout_secs = 1).await;
    let mut stream = send_incomplete_post(&app).await;
    let mut response = Vec::new();
    tokio::time::timeout(Duration::from_secs(10), stream.read_to_end(&mut response))
        .await
        .expect("the server answers and closes within the deadline")
        .unwrap();
    let text = String::from_utf8_lossy(&response);
    assert!(text.starts_with("HTTP/1.1 408"), "{text}");
    assert!(text.contains("application/problem+json"), "{text}");
    assert!(text.contains("did not complete within 1 s"), "{text}");
    assert_eq!(app.count("cohort").await, 0);
}

#[tokio::test]
async fn requests_beyond_the_in_flight_bound_get_503_with_retry_after() {
    let app = spawn_app_configured(|c| {
        c.max_in_flight = 1;
        c.retry_after_secs = 7;
    })
    .await;
    let held = send_incomplete_post(&app).await;
    // The held request takes the only slot once the server has read its head.
    let mut refused = None;
    for _ in 0..200 {
        let r = app.get("/v1/cohorts").await;
        if r.status == StatusCode::SERVICE_UNAVAILABLE {
            refused = Some(r);
            break;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let refused = refused.expect("a second request is refused while one is held");
    assert_eq!(refused.header("retry-after"), Some("7"));
    assert_eq!(
        refused.header("content-type"),
        Some("application/problem+json")
    );
    assert_eq!(refused.json()["status"], 503);
    assert_eq!(
        app.get("/healthz").await.status,
        StatusCode::OK,
        "probes pass"
    );

    drop(held);
    let mut freed = false;
    for _ in 0..200 {
        if app.get("/v1/cohorts").await.status == StatusCode::OK {
            freed = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    assert!(freed, "the slot is freed when the held request ends");
}

#[tokio::test]
async fn a_cohort_over_the_work_budget_is_422_naming_count() {
    let app = spawn_app().await;
    // The default budget of 4e9 voxels holds 29 fields at 512³; the model's 5 training
    // shapes take 5 of them the first time: 40 shapes do not fit, 24 do.
    let body = json!({ "model_id": MODEL, "count": 40, "arity": 2, "resolution": 512 });
    let r = app.create_cohort(&body).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
    let p = r.json();
    assert_eq!(
        (p["field"].as_str(), p["rule"].as_str()),
        (Some("count"), Some("budget"))
    );
    let detail = p["detail"].as_str().unwrap();
    assert!(detail.contains("512³"), "{p}");
    assert!(detail.contains("at most 24 shapes"), "{p}");
    assert_eq!(app.count("cohort").await, 0);
    let fits = json!({ "model_id": MODEL, "count": 24, "arity": 2, "resolution": 512 });
    assert_eq!(app.create_cohort(&fits).await.status, StatusCode::ACCEPTED);
}

#[tokio::test]
async fn the_work_budget_counts_every_draw_and_the_models_first_reconstructions() {
    let app = spawn_app().await;
    let problem = |r: TestResponse, field: &str| {
        assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
        let p = r.json();
        assert_eq!(
            (p["field"].as_str(), p["rule"].as_str()),
            (Some(field), Some("budget"))
        );
        p["detail"].as_str().unwrap().to_owned()
    };
    // One shape at 1024³ is one field of 1.07e9 voxels, but the model's 5 training shapes
    // are first reconstructed at that resolution for novelty: 6 fields, 6.4e9 voxels. The
    // setup alone fills the budget, so no count fits and the resolution is named.
    let one = json!({ "model_id": MODEL, "count": 1, "arity": 2, "resolution": 1024 });
    let detail = problem(app.create_cohort(&one).await, "resolution");
    assert!(detail.contains("5 training shapes"), "{detail}");
    // 100 shapes at 256³ pass; with a novelty minimum each may take 11 draws: refused,
    // naming the draws and the most shapes that fit.
    let plain = json!({ "model_id": MODEL, "count": 100, "arity": 2, "resolution": 256 });
    let app = spawn_app_configured(|c| c.max_count = 1000).await;
    assert_eq!(app.create_cohort(&plain).await.status, StatusCode::ACCEPTED);
    let mut novel = plain.clone();
    novel["min_novelty"] = json!(0.001);
    let detail = problem(app.create_cohort(&novel).await, "count");
    assert!(detail.contains("11 draws a shape"), "{detail}");
    // 4e9 / 256³ = 238 fields, 5 of them setup: (238 − 5) / 11 = 21 shapes.
    assert!(detail.contains("at most 21 shapes"), "{detail}");
    novel["count"] = json!(21);
    assert_eq!(app.create_cohort(&novel).await.status, StatusCode::ACCEPTED);
    // A target search counts its candidates.
    let mut targeted = plain.clone();
    targeted["targets"] = json!({ "length_mm": { "min": 1.0 } });
    targeted["max_candidates"] = json!(50);
    let detail = problem(app.create_cohort(&targeted).await, "count");
    assert!(detail.contains("50 draws a shape"), "{detail}");
    assert_eq!(app.count("cohort").await, 2);
}

#[tokio::test]
async fn the_default_budget_allows_100_shapes_at_256() {
    let app = spawn_app_configured(|c| c.max_count = 1000).await;
    let body = json!({ "model_id": MODEL, "count": 100, "arity": 2, "resolution": 256 });
    assert_eq!(app.create_cohort(&body).await.status, StatusCode::ACCEPTED);
    // 238 fields at 256³, 5 of them the model's first reconstructions.
    let over = json!({ "model_id": MODEL, "count": 234, "arity": 2, "resolution": 256 });
    assert_eq!(
        app.create_cohort(&over).await.status,
        StatusCode::UNPROCESSABLE_ENTITY
    );
}
