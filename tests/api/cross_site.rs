//! Cross-site request forgery: a state-changing request a browser sends for another site is
//! refused with a 403 problem document, keys or not, while clients that are not browsers and
//! the service's own page are unaffected.

use axum::http::{Method, StatusCode};
use serde_json::json;

use crate::helpers::{
    TestApp, TestResponse, cohort_body, multipart, spawn_app, spawn_app_configured,
};

const EVIL: &str = "http://evil.example";

fn host_of(app: &TestApp) -> String {
    app.address.trim_start_matches("http://").to_owned()
}

async fn post(app: &TestApp, path: &str, headers: &[(&str, &str)], body: &str) -> TestResponse {
    app.request(Method::POST, path, headers, body.to_owned())
        .await
}

fn assert_refused(r: &TestResponse, header: &str) {
    assert_eq!(
        r.status,
        StatusCode::FORBIDDEN,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    assert_eq!(r.header("content-type"), Some("application/problem+json"));
    let p = r.json();
    assert_eq!(p["type"], "/problems/cross-site-request");
    assert_eq!(p["field"], header);
    assert_eq!(p["rule"], "same-origin");
    assert!(p["detail"].as_str().unwrap().contains("refused"), "{p}");
}

async fn queued_cohort(app: &TestApp) -> i64 {
    app.create_cohort_ok(&cohort_body(2, 2)).await
}

async fn status_of(app: &TestApp, cohort: i64) -> String {
    let view = app.get(&format!("/v1/cohorts/{cohort}")).await.json();
    view["status"].as_str().unwrap().to_owned()
}

#[tokio::test]
async fn a_form_post_from_another_site_cancels_nothing() {
    let app = spawn_app().await;
    let cohort = queued_cohort(&app).await;
    let path = format!("/v1/cohorts/{cohort}/cancel");
    let form = ("content-type", "application/x-www-form-urlencoded");

    let foreign = post(&app, &path, &[form, ("origin", EVIL)], "a=1").await;
    assert_refused(&foreign, "Origin");
    let opaque = post(&app, &path, &[form, ("origin", "null")], "a=1").await;
    assert_refused(&opaque, "Origin");
    let fetched = post(&app, &path, &[("sec-fetch-site", "cross-site")], "").await;
    assert_refused(&fetched, "Sec-Fetch-Site");
    // A browser that sends no Origin still sends a form type, which this endpoint never takes.
    let bare_form = post(&app, &path, &[form], "a=1").await;
    assert_refused(&bare_form, "Content-Type");
    let text = post(&app, &path, &[("content-type", "text/plain")], "x").await;
    assert_refused(&text, "Content-Type");
    assert_eq!(status_of(&app, cohort).await, "queued");

    // curl-style and same-origin requests go through.
    let ours = post(
        &app,
        &path,
        &[("origin", &app.address), ("sec-fetch-site", "same-origin")],
        "",
    )
    .await;
    assert_eq!(ours.status, StatusCode::ACCEPTED);
    assert_eq!(status_of(&app, cohort).await, "cancelled");
}

#[tokio::test]
async fn json_endpoints_refuse_form_bodies_and_foreign_origins() {
    let app = spawn_app().await;
    let body = cohort_body(1, 2).to_string();
    let json_type = ("content-type", "application/json");
    for (headers, header) in [
        (vec![("content-type", "text/plain")], "Content-Type"),
        (
            vec![("content-type", "application/x-www-form-urlencoded")],
            "Content-Type",
        ),
        (
            vec![("content-type", "multipart/form-data; boundary=x")],
            "Content-Type",
        ),
        (vec![json_type, ("origin", EVIL)], "Origin"),
        (
            vec![json_type, ("sec-fetch-site", "same-site")],
            "Sec-Fetch-Site",
        ),
    ] {
        let r = post(&app, "/v1/cohorts", &headers, &body).await;
        assert_refused(&r, header);
    }
    assert_eq!(app.count("cohort").await, 0, "nothing refused is stored");

    let host = host_of(&app);
    let origin = format!("http://{host}");
    let page = post(
        &app,
        "/v1/cohorts",
        &[json_type, ("origin", &origin)],
        &body,
    )
    .await;
    assert_eq!(page.status, StatusCode::ACCEPTED);
    let curl = post(&app, "/v1/cohorts", &[json_type], &body).await;
    assert_eq!(curl.status, StatusCode::ACCEPTED);
    // Another port of the same host is another origin.
    let port = host.rsplit(':').next().unwrap().parse::<u32>().unwrap();
    let other = format!("http://127.0.0.1:{}", port + 1);
    let r = post(&app, "/v1/cohorts", &[json_type, ("origin", &other)], &body).await;
    assert_refused(&r, "Origin");
}

#[tokio::test]
async fn uploads_from_another_site_are_refused_but_reads_are_not() {
    let app = spawn_app().await;
    let (content_type, body) = multipart(&[("id", None, b"planted".to_vec())]);
    let r = app
        .request(
            Method::POST,
            "/v1/models",
            &[("content-type", &content_type), ("origin", EVIL)],
            body,
        )
        .await;
    assert_refused(&r, "Origin");
    assert_eq!(
        app.count("model").await,
        1,
        "only the test model is registered"
    );

    let read = app
        .request(
            Method::GET,
            "/v1/cohorts",
            &[("origin", EVIL), ("sec-fetch-site", "cross-site")],
            "",
        )
        .await;
    assert_eq!(read.status, StatusCode::OK);
    let delete = app
        .request(
            Method::DELETE,
            "/v1/models/ellipsoids",
            &[("sec-fetch-site", "cross-site")],
            "",
        )
        .await;
    assert_refused(&delete, "Sec-Fetch-Site");
}

#[tokio::test]
async fn a_valid_key_does_not_let_another_site_write() {
    let app = spawn_app_configured(|c| c.api_keys = vec!["k-1".parse().unwrap()]).await;
    let body = json!({"model_id": "ellipsoids", "count": 1, "arity": 2}).to_string();
    let auth = ("authorization", "Bearer k-1");
    let json_type = ("content-type", "application/json");
    let r = post(
        &app,
        "/v1/cohorts",
        &[json_type, auth, ("origin", EVIL)],
        &body,
    )
    .await;
    assert_refused(&r, "Origin");
    let ok = post(&app, "/v1/cohorts", &[json_type, auth], &body).await;
    assert_eq!(ok.status, StatusCode::ACCEPTED);
}

/// A concrete path for a route template, naming resources that exist where there are any.
fn concrete(template: &str, cohort: i64, job: i64) -> String {
    let id = if template.starts_with("/v1/models/") {
        crate::helpers::MODEL.to_owned()
    } else if template.starts_with("/v1/cohorts/") {
        cohort.to_string()
    } else if template.starts_with("/v1/jobs/") {
        job.to_string()
    } else {
        "1".to_owned()
    };
    template.replace("{id}", &id)
}

#[tokio::test]
async fn form_posts_from_another_site_reach_no_state_changing_route_without_keys() {
    let app = spawn_app().await;
    assert!(!app.state.access.is_enabled(), "no key configured");
    let cohort = queued_cohort(&app).await;
    let job = app.get(&format!("/v1/cohorts/{cohort}")).await.json()["job_id"]
        .as_i64()
        .unwrap();
    let counts = async || {
        let mut counts = Vec::new();
        for table in [
            "model",
            "job",
            "cohort",
            "shape",
            "anchor",
            "reference_population",
            "validation",
            "model_refit",
        ] {
            counts.push(app.count(table).await);
        }
        counts
    };
    let before = counts().await;
    // Every state-changing operation the service documents, so a new route is covered too.
    let doc = app.get("/openapi.json").await.json();
    let (multipart_type, multipart_body) = multipart(&[("id", None, b"planted".to_vec())]);
    let mut checked = 0;
    let mut takes_forms = Vec::new();
    for (template, item) in doc["paths"].as_object().unwrap() {
        for method in ["post", "put", "patch", "delete"] {
            let Some(op) = item.get(method) else { continue };
            let path = concrete(template, cohort, job);
            let verb = Method::from_bytes(method.to_uppercase().as_bytes()).unwrap();
            let send = async |headers: &[(&str, &str)], body: Vec<u8>| {
                app.request(verb.clone(), &path, headers, body).await
            };
            // What a current browser sends with a cross-site form or no-cors fetch.
            let r = send(
                &[
                    ("content-type", "application/x-www-form-urlencoded"),
                    ("origin", EVIL),
                    ("sec-fetch-site", "cross-site"),
                ],
                b"a=1".to_vec(),
            )
            .await;
            assert_refused(&r, "Sec-Fetch-Site");
            let r = send(
                &[("content-type", &multipart_type), ("origin", EVIL)],
                multipart_body.clone(),
            )
            .await;
            assert_refused(&r, "Origin");
            // A browser that sends neither: only a type the endpoint takes gets through.
            let accepted = op["requestBody"]["content"]
                .as_object()
                .map(|c| c.keys().cloned().collect::<Vec<_>>())
                .unwrap_or_default();
            for form in ["application/x-www-form-urlencoded", "text/plain"] {
                assert!(!accepted.iter().any(|t| t == form), "{method} {template}");
                let r = send(&[("content-type", form)], b"a=1".to_vec()).await;
                assert_refused(&r, "Content-Type");
            }
            if accepted.iter().any(|t| t == "multipart/form-data") {
                takes_forms.push(format!("{method} {template}"));
            } else {
                let r = send(&[("content-type", &multipart_type)], multipart_body.clone()).await;
                assert_refused(&r, "Content-Type");
            }
            checked += 1;
        }
    }
    assert_eq!(checked, 14, "the documented state-changing operations");
    // Uploads take multipart bodies from clients that are not browsers (curl -F): a form
    // with neither Origin nor Sec-Fetch-Site is theirs, which no current browser sends.
    takes_forms.sort();
    assert_eq!(
        takes_forms,
        [
            "post /v1/models",
            "post /v1/models/{id}/fit",
            "post /v1/models/{id}/references"
        ]
    );
    assert_eq!(counts().await, before, "nothing was created or deleted");
    assert_eq!(status_of(&app, cohort).await, "queued");
}
