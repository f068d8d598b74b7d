//! Bad input: each case gets a problem document with the right status, field and rule, and
//! nothing is stored.

use axum::http::{Method, StatusCode};

use crate::helpers::{MAX_UPLOAD, TestApp, spawn_app};

struct Case {
    what: &'static str,
    method: Method,
    path: &'static str,
    content_type: &'static str,
    body: String,
    status: u16,
    field: Option<&'static str>,
    rule: Option<&'static str>,
}

fn post(
    what: &'static str,
    body: &str,
    status: u16,
    field: Option<&'static str>,
    rule: Option<&'static str>,
) -> Case {
    Case {
        what,
        method: Method::POST,
        path: "/v1/cohorts",
        content_type: "application/json",
        body: body.into(),
        status,
        field,
        rule,
    }
}

fn get(what: &'static str, path: &'static str, status: u16, field: Option<&'static str>) -> Case {
    Case {
        what,
        method: Method::GET,
        path,
        content_type: "",
        body: String::new(),
        status,
        field,
        rule: None,
    }
}

fn cases() -> Vec<Case> {
    const M: &str = r#""model_id": "ellipsoids""#;
    vec![
        post(
            "unknown model",
            r#"{"model_id": "nope", "count": 1, "arity": 2}"#,
            404,
            None,
            None,
        ),
        post(
            "count 0",
            &format!(r#"{{{M}, "count": 0, "arity": 2}}"#),
            422,
            Some("count"),
            Some("range"),
        ),
        post(
            "count above the limit",
            &format!(r#"{{{M}, "count": 51, "arity": 2}}"#),
            422,
            Some("count"),
            Some("range"),
        ),
        post(
            "arity 1",
            &format!(r#"{{{M}, "count": 1, "arity": 1}}"#),
            422,
            Some("arity"),
            Some("range"),
        ),
        post(
            "arity above training shapes",
            &format!(r#"{{{M}, "count": 1, "arity": 6}}"#),
            422,
            Some("arity"),
            Some("range"),
        ),
        post(
            "weights of the wrong length",
            &format!(r#"{{{M}, "count": 1, "arity": 3, "weights": [0.5, 0.5]}}"#),
            422,
            Some("weights"),
            Some("length"),
        ),
        post(
            "negative weight",
            &format!(r#"{{{M}, "count": 1, "arity": 2, "weights": [-0.5, 1.5]}}"#),
            422,
            Some("weights"),
            Some("non-negative"),
        ),
        post(
            "NaN weight (not JSON)",
            &format!(r#"{{{M}, "count": 1, "arity": 2, "weights": [NaN, 1]}}"#),
            400,
            None,
            None,
        ),
        post(
            "weights not summing to 1",
            &format!(r#"{{{M}, "count": 1, "arity": 2, "weights": [0.5, 0.51]}}"#),
            422,
            Some("weights"),
            Some("sum"),
        ),
        post(
            "weights off by 2e-6",
            &format!(r#"{{{M}, "count": 1, "arity": 2, "weights": [0.5, 0.500002]}}"#),
            422,
            Some("weights"),
            Some("sum"),
        ),
        post(
            "unknown weighting",
            &format!(r#"{{{M}, "count": 1, "arity": 2, "weighting": "uniform"}}"#),
            422,
            Some("weighting"),
            Some("enum"),
        ),
        post(
            "resolution 31",
            &format!(r#"{{{M}, "count": 1, "arity": 2, "resolution": 31}}"#),
            422,
            Some("resolution"),
            Some("range"),
        ),
        post(
            "resolution 1025",
            &format!(r#"{{{M}, "count": 1, "arity": 2, "resolution": 1025}}"#),
            422,
            Some("resolution"),
            Some("range"),
        ),
        post(
            "unknown field",
            &format!(r#"{{{M}, "count": 1, "arity": 2, "colour": "red"}}"#),
            422,
            Some("colour"),
            Some("unknown-field"),
        ),
        post(
            "missing field",
            &format!(r#"{{{M}, "arity": 2}}"#),
            422,
            Some("count"),
            Some("required"),
        ),
        post(
            "count of the wrong type",
            &format!(r#"{{{M}, "count": "two", "arity": 2}}"#),
            422,
            Some("count"),
            Some("type"),
        ),
        post("malformed JSON", "{\n  \"count\": 1,,\n}", 400, None, None),
        Case {
            content_type: "application/xml",
            ..post("wrong content type", "{}", 415, None, None)
        },
        Case {
            content_type: "text/plain",
            ..post(
                "form content type",
                "{}",
                403,
                Some("Content-Type"),
                Some("same-origin"),
            )
        },
        Case {
            content_type: "",
            ..post("no content type", "{}", 415, None, None)
        },
        post(
            "oversized body",
            &format!(r#"{{{M}, "pad": "{}"}}"#, "x".repeat(MAX_UPLOAD + 1)),
            413,
            None,
            None,
        ),
        get("unknown cohort", "/v1/cohorts/999", 404, None),
        get("non-numeric cohort id", "/v1/cohorts/abc", 404, None),
        get(
            "unknown cohort's shapes",
            "/v1/cohorts/999/shapes",
            404,
            None,
        ),
        get(
            "unknown cohort's metrics",
            "/v1/cohorts/999/metrics",
            404,
            None,
        ),
        get("unknown shape", "/v1/shapes/999", 404, None),
        get("unknown shape's mesh", "/v1/shapes/999/mesh", 404, None),
        get("unknown job", "/v1/jobs/999", 404, None),
        get("unknown model", "/v1/models/nope", 404, None),
        get("unknown route", "/v2/everything", 404, None),
        get("bad page size", "/v1/cohorts?limit=0", 400, Some("limit")),
        get(
            "bad status filter",
            "/v1/cohorts?status=done",
            400,
            Some("status"),
        ),
        get(
            "bad metrics format",
            "/v1/cohorts/1/metrics?format=xml",
            400,
            Some("format"),
        ),
    ]
}

async fn check(app: &TestApp, case: &Case) -> serde_json::Value {
    let headers: Vec<(&str, &str)> = if case.content_type.is_empty() {
        vec![]
    } else {
        vec![("content-type", case.content_type)]
    };
    let r = app
        .request(case.method.clone(), case.path, &headers, case.body.clone())
        .await;
    assert_eq!(
        r.status.as_u16(),
        case.status,
        "{}: {}",
        case.what,
        String::from_utf8_lossy(&r.body)
    );
    assert_eq!(
        r.header("content-type"),
        Some("application/problem+json"),
        "{}",
        case.what
    );
    let p = r.json();
    assert_eq!(
        p["status"].as_u64(),
        Some(case.status as u64),
        "{}",
        case.what
    );
    assert!(
        p["type"].as_str().unwrap().starts_with("/problems/"),
        "{}",
        case.what
    );
    assert!(!p["detail"].as_str().unwrap().is_empty(), "{}", case.what);
    assert_eq!(p["field"].as_str(), case.field, "{}: {p}", case.what);
    if case.rule.is_some() {
        assert_eq!(p["rule"].as_str(), case.rule, "{}: {p}", case.what);
    }
    p
}

#[tokio::test]
async fn bad_requests_get_problem_documents_naming_the_field_and_rule() {
    let app = spawn_app().await;
    for case in cases() {
        check(&app, &case).await;
    }
    for table in ["cohort", "job", "shape"] {
        assert_eq!(
            app.count(table).await,
            0,
            "{table}: a bad request stored something"
        );
    }
}

#[tokio::test]
async fn malformed_json_reports_line_and_column() {
    let app = spawn_app().await;
    let p = check(
        &app,
        &post("malformed JSON", "{\n  \"count\": 1,,\n}", 400, None, None),
    )
    .await;
    assert_eq!(
        (p["line"].as_u64(), p["column"].as_u64()),
        (Some(2), Some(14))
    );
    let nan = check(&app, &post("NaN", r#"{"weights": [NaN]}"#, 400, None, None)).await;
    assert_eq!(
        (nan["line"].as_u64(), nan["column"].as_u64()),
        (Some(1), Some(14))
    );
}

#[tokio::test]
async fn an_unknown_mesh_format_or_unit_is_a_400_naming_the_parameter() {
    let app = spawn_app().await;
    let id = app
        .create_cohort_ok(&crate::helpers::cohort_body(1, 2))
        .await;
    app.run_pending_jobs().await;
    let shapes = app.get(&format!("/v1/cohorts/{id}/shapes")).await.json();
    let shape = shapes["items"][0]["id"].as_i64().unwrap();
    for (query, field) in [("format=step", "format"), ("units=inch", "units")] {
        let r = app.get(&format!("/v1/shapes/{shape}/mesh?{query}")).await;
        assert_eq!(r.status, StatusCode::BAD_REQUEST, "{query}");
        assert_eq!(r.json()["field"], field);
    }
}
