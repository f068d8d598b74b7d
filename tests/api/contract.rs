//! The OpenAPI document states the rules the server enforces. The tests walk the served
//! document: every query or path parameter and every `POST /v1/cohorts` body field with a
//! bound or an enumeration gets a value just inside (the server must accept it) and values
//! just outside (the server must refuse them with a problem naming the parameter or field).
//! "Accepted" means the request passed every rule of that value: a success, or a 404 for
//! the resource the test names on purpose where the rules are checked before the lookup.

use std::collections::BTreeSet;

use axum::http::{Method, StatusCode};
use serde_json::{Value, json};

use crate::helpers::{MODEL, TestApp, TestResponse, cohort_body, spawn_app_configured};

/// A value to send and whether the server must take it.
#[derive(Debug, Clone)]
struct Probe {
    value: Value,
    accepted: bool,
}

/// A small step beside a bound, relative to its size.
fn step(bound: f64) -> f64 {
    1e-6 * bound.abs().max(1.0)
}

/// Follows a `$ref`, and a nullable `oneOf` to its non-null member.
fn resolve<'a>(doc: &'a Value, schema: &'a Value) -> &'a Value {
    if let Some(r) = schema["$ref"].as_str() {
        let name = r.trim_start_matches("#/components/schemas/");
        let target = &doc["components"]["schemas"][name];
        assert!(!target.is_null(), "{r} names no schema of the document");
        return resolve(doc, target);
    }
    for combinator in ["oneOf", "anyOf"] {
        if let Some(members) = schema[combinator].as_array() {
            let member = members
                .iter()
                .find(|m| m["type"] != "null")
                .expect("a non-null member");
            return resolve(doc, member);
        }
    }
    schema
}

/// Whether the schema states a rule the probes can test.
fn is_bounded(schema: &Value) -> bool {
    [
        "enum",
        "minimum",
        "maximum",
        "exclusiveMinimum",
        "exclusiveMaximum",
    ]
    .iter()
    .any(|k| schema.get(*k).is_some())
}

/// Values just inside and just outside every bound and enumeration of `schema`.
fn probes(schema: &Value) -> Vec<Probe> {
    let inside = |value: Value| Probe {
        value,
        accepted: true,
    };
    let outside = |value: Value| Probe {
        value,
        accepted: false,
    };
    let mut out = Vec::new();
    if let Some(values) = schema["enum"].as_array() {
        out.extend(values.iter().filter(|v| !v.is_null()).cloned().map(inside));
        out.push(outside(json!("")));
        out.push(outside(json!("no-such-value")));
        return out;
    }
    let integer = schema["type"] == "integer"
        || schema["type"]
            .as_array()
            .is_some_and(|t| t.contains(&json!("integer")));
    let number = |v: f64| match integer {
        true => json!(v as i64),
        false => json!(v),
    };
    let below = |b: f64| if integer { b - 1.0 } else { b - step(b) };
    let above = |b: f64| if integer { b + 1.0 } else { b + step(b) };
    if let Some(min) = schema["minimum"].as_f64() {
        out.push(inside(number(min)));
        out.push(outside(number(below(min))));
    }
    if let Some(min) = schema["exclusiveMinimum"].as_f64() {
        out.push(outside(number(min)));
        out.push(inside(number(above(min))));
    }
    if let Some(max) = schema["maximum"].as_f64() {
        out.push(inside(number(max)));
        out.push(outside(number(above(max))));
    }
    if let Some(max) = schema["exclusiveMaximum"].as_f64() {
        out.push(outside(number(max)));
        out.push(inside(number(below(max))));
    }
    out
}

/// A value as it goes into a query string or a path.
fn query_text(value: &Value) -> String {
    match value {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// Whether `r` refuses the request for `field`: a 4xx problem naming it (a path segment
/// that names nothing is a 404 whose detail starts with the parameter).
fn refuses(r: &TestResponse, field: &str) -> bool {
    if !r.status.is_client_error() || r.header("content-type") != Some("application/problem+json") {
        return false;
    }
    let problem = r.json();
    problem["field"] == field
        || (r.status == StatusCode::NOT_FOUND
            && problem["detail"]
                .as_str()
                .is_some_and(|d| d.starts_with(&format!("{field} "))))
}

/// Whether `r` passes the rules of `field`: a success, or a problem about something else
/// than a broken rule (the unknown resource the test asks for).
fn accepts(r: &TestResponse, field: &str) -> bool {
    r.status.is_success() || (r.status == StatusCode::NOT_FOUND && !refuses(r, field))
}

fn describe(r: &TestResponse) -> String {
    format!("{} {}", r.status, String::from_utf8_lossy(&r.body))
}

/// A service with one finished cohort and a queue that takes every accepted probe.
async fn app_with_a_cohort() -> (TestApp, i64, i64) {
    let app = spawn_app_configured(|c| c.max_queue = 10_000).await;
    let cohort = app.create_cohort_ok(&cohort_body(2, 2)).await;
    app.run_pending_jobs().await;
    let shapes = app
        .get(&format!("/v1/cohorts/{cohort}/shapes"))
        .await
        .json();
    let shape = shapes["items"][0]["id"].as_i64().unwrap();
    (app, cohort, shape)
}

/// A small closed mesh file.
fn stl() -> Vec<u8> {
    use aortagen::formats::{MeshFormat, MeshMetadata, write_mesh};
    let mesh = crate::engine::uv_sphere(6, 8);
    write_mesh(&mesh, MeshFormat::Stl, &MeshMetadata::new("mm")).unwrap()
}

fn zip_of_meshes(count: usize) -> Vec<u8> {
    use std::io::Write;
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default();
    for i in 0..count {
        zip.start_file(format!("m{i}.stl"), options).unwrap();
        zip.write_all(&stl()).unwrap();
    }
    zip.finish().unwrap().into_inner()
}

/// Sends one probe of parameter `name` of `method path`, the rest of the request valid.
async fn send_parameter(
    app: &TestApp,
    (method, path): (&str, &str),
    (name, location): (&str, &str),
    value: &Value,
    ids: (i64, i64),
    serial: usize,
) -> TestResponse {
    let (cohort, shape) = ids;
    // Simulation meshes are checked before the shape is looked up: an unknown shape keeps
    // accepted probes from running the pipeline.
    let simulation = ["/mesh", "/faces", "/meshes.zip"]
        .iter()
        .any(|s| path.ends_with(s));
    let mut url = path
        .replace("/v1/models/{id}", &format!("/v1/models/{MODEL}"))
        .replace(
            "/v1/cohorts/{id}",
            &format!("/v1/cohorts/{}", if simulation { 999_999 } else { cohort }),
        )
        .replace(
            "/v1/shapes/{id}",
            &format!("/v1/shapes/{}", if simulation { 999_999 } else { shape }),
        );
    let mut query = Vec::new();
    if location == "path" {
        url = url.replace(&format!("{{{name}}}"), &query_text(value));
    } else {
        query.push(format!("{name}={}", query_text(value)));
    }
    let simulation_option = !["format", "units", "openings"].contains(&name);
    if simulation && simulation_option && !path.ends_with("/faces") {
        query.push("openings=capped".into());
    }
    let (headers, body): (Vec<(&str, &str)>, Vec<u8>) = match (method, path) {
        ("post", "/v1/models") => {
            query.push(format!("id=probe-{serial}"));
            (vec![("content-type", "application/zip")], zip_of_meshes(3))
        }
        ("post", "/v1/models/{id}/fit") => {
            query.push("file_name=probe.stl".into());
            (vec![("content-type", "application/octet-stream")], stl())
        }
        _ => (Vec::new(), Vec::new()),
    };
    let url = format!("{url}?{}", query.join("&"));
    let method = Method::from_bytes(method.to_uppercase().as_bytes()).unwrap();
    app.request(method, &url, &headers, body).await
}

#[tokio::test]
async fn every_bounded_parameter_is_accepted_inside_and_refused_outside() {
    let (app, cohort, shape) = app_with_a_cohort().await;
    let doc = app.get("/openapi.json").await.json();
    let mut bounded = BTreeSet::new();
    let mut failures = Vec::new();
    let mut serial = 0;
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            for p in op["parameters"].as_array().into_iter().flatten() {
                let (name, location) = (p["name"].as_str().unwrap(), p["in"].as_str().unwrap());
                let schema = resolve(&doc, &p["schema"]);
                if !["query", "path"].contains(&location) || !is_bounded(schema) {
                    continue;
                }
                bounded.insert(format!("{path} {name}"));
                for probe in probes(schema) {
                    // An empty path segment is another route, not a value of the parameter.
                    if location == "path" && probe.value == "" {
                        continue;
                    }
                    serial += 1;
                    let r = send_parameter(
                        &app,
                        (method, path),
                        (name, location),
                        &probe.value,
                        (cohort, shape),
                        serial,
                    )
                    .await;
                    let agrees = match probe.accepted {
                        true => accepts(&r, name),
                        false => refuses(&r, name),
                    };
                    if !agrees {
                        failures.push(format!(
                            "{method} {path} {name}={} (schema: {}): {}",
                            probe.value,
                            if probe.accepted { "valid" } else { "invalid" },
                            describe(&r)
                        ));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    let expected = [
        "/v1/cohorts limit",
        "/v1/cohorts offset",
        "/v1/cohorts status",
        "/v1/cohorts/{id}/shapes limit",
        "/v1/cohorts/{id}/shapes offset",
        "/v1/cohorts/{id}/metrics format",
        "/v1/cohorts/{id}/plots/{plot} plot",
        "/v1/models/{id}/plots/{plot} plot",
        "/v1/shapes/{id}/mesh format",
        "/v1/shapes/{id}/mesh units",
        "/v1/shapes/{id}/mesh remesh_mm",
        "/v1/shapes/{id}/mesh end_trim_mm",
        "/v1/shapes/{id}/faces extension_diameters",
        "/v1/cohorts/{id}/meshes.zip units",
        "/v1/cohorts/{id}/meshes.zip inlet_below_annulus_mm",
        "/v1/models epochs",
        "/v1/models holdout",
        "/v1/models/{id}/fit iterations",
    ];
    for e in expected {
        assert!(bounded.contains(e), "the document states no rule of {e}");
    }
}

/// Where a probed body value goes: its JSON path, and the field a refusal must name.
#[derive(Debug, Clone)]
enum Step {
    /// An object property.
    Key(String),
    /// Every item of an array (the weights: `[v, 1 − v]`).
    Items,
    /// A property name of a map (the target measurements).
    Name,
}

/// Every bounded leaf of `schema` under `at`.
fn bounded_leaves(doc: &Value, schema: &Value, at: Vec<Step>, out: &mut Vec<(Vec<Step>, Value)>) {
    let schema = resolve(doc, schema);
    if is_bounded(schema) {
        out.push((at, schema.clone()));
        return;
    }
    if let Some(items) = schema.get("items") {
        let mut path = at.clone();
        path.push(Step::Items);
        bounded_leaves(doc, items, path, out);
    }
    for (key, property) in schema["properties"].as_object().into_iter().flatten() {
        let mut path = at.clone();
        path.push(Step::Key(key.clone()));
        bounded_leaves(doc, property, path, out);
    }
    if let Some(names) = schema.get("propertyNames") {
        let mut path = at.clone();
        path.push(Step::Name);
        out.push((path, resolve(doc, names).clone()));
    }
    if let Some(values) = schema.get("additionalProperties").filter(|v| v.is_object()) {
        let mut path = at.clone();
        path.push(Step::Key("annulus_mm".into()));
        bounded_leaves(doc, values, path, out);
    }
}

/// The field a refusal of `value` at `path` names.
fn field_name(path: &[Step], value: &Value) -> String {
    let mut parts = Vec::new();
    for step in path {
        match step {
            Step::Key(k) => parts.push(k.clone()),
            Step::Items => {}
            Step::Name => parts.push(query_text(value)),
        }
    }
    parts.join(".")
}

/// A cohort request on a model that does not exist, valid in every rule the request has
/// without a model, with `value` at `path`. The sampler kind and the targets a probed
/// field needs are filled in.
fn cohort_probe(path: &[Step], value: &Value) -> Value {
    let mut body = json!({
        "model_id": "no-such-model", "count": 1, "arity": 2, "seed": 1, "resolution": 64
    });
    let keys: Vec<&str> = path
        .iter()
        .filter_map(|s| match s {
            Step::Key(k) => Some(k.as_str()),
            _ => None,
        })
        .collect();
    match keys.as_slice() {
        ["sampler", field] => {
            let kind = match *field {
                "kind" => value.clone(),
                "truncation" | "sigma_scale" | "variance_share" | "covariance" | "shrinkage"
                | "latents" => json!("pca_gaussian"),
                "components" | "max_components" | "mixture_modes" => json!("pca_mixture"),
                other => panic!("no sampler kind known for sampler.{other}"),
            };
            body["sampler"] = json!({ "kind": kind });
            if kind != "convex" {
                body.as_object_mut().unwrap().remove("arity");
            }
            if *field != "kind" {
                body["sampler"][*field] = value.clone();
            }
        }
        ["weights"] => {
            let w = value.as_f64().unwrap();
            body["weights"] = json!([w, 1.0 - w]);
        }
        ["targets"] => {
            body["targets"] = json!({ query_text(value): { "min": 1.0 } });
        }
        ["targets", name, bound] => {
            body["targets"] = json!({ *name: { *bound: value } });
        }
        ["max_candidates"] => {
            body["max_candidates"] = value.clone();
            body["targets"] = json!({ "annulus_mm": { "min": 1.0 } });
        }
        [field] => body[*field] = value.clone(),
        other => panic!("no way to probe {other:?}"),
    }
    body
}

#[tokio::test]
async fn every_bounded_cohort_field_is_accepted_inside_and_refused_outside() {
    let (app, _, _) = app_with_a_cohort().await;
    let doc = app.get("/openapi.json").await.json();
    let body = &doc["paths"]["/v1/cohorts"]["post"]["requestBody"]["content"]["application/json"]["schema"];
    let mut leaves = Vec::new();
    bounded_leaves(&doc, body, Vec::new(), &mut leaves);
    let mut failures = Vec::new();
    let mut bounded = BTreeSet::new();
    for (path, schema) in &leaves {
        bounded.insert(field_name(path, &json!("{name}")));
        for probe in probes(schema) {
            let request = cohort_probe(path, &probe.value);
            let field = field_name(path, &probe.value);
            let r = app.create_cohort(&request).await;
            let agrees = match probe.accepted {
                true => accepts(&r, &field),
                false => refuses(&r, &field),
            };
            if !agrees {
                failures.push(format!(
                    "{field}={} (schema: {}) in {request}: {}",
                    probe.value,
                    if probe.accepted { "valid" } else { "invalid" },
                    describe(&r)
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    let expected = [
        "count",
        "arity",
        "weights",
        "resolution",
        "latent_noise",
        "min_novelty",
        "max_candidates",
        "targets.{name}",
        "targets.annulus_mm.min",
        "targets.annulus_mm.max",
        "sampler.kind",
        "sampler.truncation",
        "sampler.sigma_scale",
        "sampler.covariance",
        "sampler.shrinkage",
        "sampler.variance_share",
        "sampler.components",
        "sampler.max_components",
        "sampler.mixture_modes",
        "sampler.latents",
        "weighting",
        "selection",
    ];
    for e in expected {
        assert!(bounded.contains(e), "the document states no rule of {e}");
    }
}

#[tokio::test]
async fn the_largest_documented_offset_is_answered_without_a_next_page() {
    let (app, cohort, _) = app_with_a_cohort().await;
    for path in [
        "/v1/cohorts".to_owned(),
        format!("/v1/cohorts/{cohort}/shapes"),
    ] {
        let r = app
            .get(&format!("{path}?limit=1&offset={}", i64::MAX))
            .await;
        assert_eq!(r.status, StatusCode::OK, "{path}: {}", describe(&r));
        assert!(r.json()["next_offset"].is_null(), "{path}");
    }
}
