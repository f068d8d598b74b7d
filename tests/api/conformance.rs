//! Every answer is documented: requests that once got a status or content type missing
//! from the OpenAPI document (found by schema-driven fuzzing) are checked against the
//! served document, operation by operation.

use axum::http::{Method, StatusCode};
use serde_json::Value;

use crate::helpers::{TestApp, TestResponse, cohort_body, spawn_app};

/// Asserts that `r` is one of the answers `doc` documents for `method template`: its status
/// is listed and, when the answer has a body, its media type is one of that status's.
fn assert_documented(doc: &Value, method: &str, template: &str, r: &TestResponse) {
    let op = &doc["paths"][template][method];
    assert!(op.is_object(), "{method} {template} is not in the document");
    let status = r.status.as_str();
    let documented = &op["responses"][status];
    assert!(
        documented.is_object(),
        "{method} {template}: status {status} is not documented ({})",
        String::from_utf8_lossy(&r.body)
    );
    if r.body.is_empty() {
        return;
    }
    let media = r
        .header("content-type")
        .unwrap_or_default()
        .split(';')
        .next()
        .unwrap()
        .trim();
    let content = documented["content"].as_object();
    assert!(
        content.is_some_and(|c| c.contains_key(media)),
        "{method} {template}: {status} with {media} is not documented (documented: {:?})",
        content.map(|c| c.keys().collect::<Vec<_>>())
    );
}

async fn finished_cohort(app: &TestApp) -> (i64, i64) {
    let id = app.create_cohort_ok(&cohort_body(2, 2)).await;
    app.run_pending_jobs().await;
    let page = app.get(&format!("/v1/cohorts/{id}/shapes")).await.json();
    (id, page["items"][0]["id"].as_i64().unwrap())
}

#[tokio::test]
async fn an_offset_beyond_i64_is_a_documented_400_naming_offset() {
    let app = spawn_app().await;
    let doc = app.get("/openapi.json").await.json();
    let (cohort, _) = finished_cohort(&app).await;
    let r = app
        .get(&format!(
            "/v1/cohorts/{cohort}/shapes?offset=9223372036854775808"
        ))
        .await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST);
    assert!(r.detail().contains("offset"));
    assert_documented(&doc, "get", "/v1/cohorts/{id}/shapes", &r);
    let r = app
        .get(&format!("/v1/cohorts/{cohort}/shapes?limit=0"))
        .await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST);
    assert_documented(&doc, "get", "/v1/cohorts/{id}/shapes", &r);
}

#[tokio::test]
async fn a_malformed_multipart_upload_is_a_documented_400() {
    let app = spawn_app().await;
    let doc = app.get("/openapi.json").await.json();
    // A part whose header block never ends.
    let body = "--b\r\nContent-Disposition: form-data; name=\"files\"; filename=\"a.stl\"\r\n";
    let r = app
        .request(
            Method::POST,
            "/v1/models",
            &[("content-type", "multipart/form-data; boundary=b")],
            body,
        )
        .await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST, "{:?}", r.body);
    assert_eq!(r.header("content-type"), Some("application/problem+json"));
    assert_documented(&doc, "post", "/v1/models", &r);
    assert_eq!(app.count("job").await, 0);
}

#[tokio::test]
async fn every_mesh_format_is_a_documented_media_type() {
    let app = spawn_app().await;
    let doc = app.get("/openapi.json").await.json();
    let (_, shape) = finished_cohort(&app).await;
    for format in ["glb", "gltf", "stl", "obj", "ply"] {
        let r = app
            .get(&format!("/v1/shapes/{shape}/mesh?format={format}"))
            .await;
        assert_eq!(r.status, StatusCode::OK, "{format}");
        assert_documented(&doc, "get", "/v1/shapes/{id}/mesh", &r);
    }
}

#[tokio::test]
async fn csv_metrics_are_a_documented_media_type() {
    let app = spawn_app().await;
    let doc = app.get("/openapi.json").await.json();
    let (cohort, _) = finished_cohort(&app).await;
    app.run_pending_jobs().await;
    for query in ["", "?format=csv"] {
        let r = app
            .get(&format!("/v1/cohorts/{cohort}/metrics{query}"))
            .await;
        assert_eq!(r.status, StatusCode::OK, "{query}: {:?}", r.body);
        assert_documented(&doc, "get", "/v1/cohorts/{id}/metrics", &r);
    }
}
