//! Cohort science: diversity controls (latent noise, spread selection), novelty against
//! the training shapes and anatomical measurements per shape.

use axum::http::StatusCode;
use serde_json::{Value, json};

use crate::engine::{TRAINING_SHAPES, mixed_axes};
use crate::helpers::{TestApp, cohort_body, spawn_app};

fn body_with(extra: Value) -> Value {
    let mut body = cohort_body(4, 2);
    for (k, v) in extra.as_object().unwrap() {
        body[k] = v.clone();
    }
    body
}

async fn shapes(app: &TestApp, cohort: i64) -> Vec<Value> {
    let page = app
        .get(&format!("/v1/cohorts/{cohort}/shapes"))
        .await
        .json();
    let mut out = Vec::new();
    for item in page["items"].as_array().unwrap() {
        let r = app.get(&format!("/v1/shapes/{}", item["id"])).await;
        assert_eq!(r.status, StatusCode::OK);
        out.push(r.json());
    }
    out
}

#[tokio::test]
async fn a_cohort_with_latent_noise_and_spread_selection_succeeds_and_records_them() {
    let app = spawn_app().await;
    let plain = app.create_cohort_ok(&cohort_body(4, 2)).await;
    let body = body_with(json!({ "latent_noise": 0.5, "selection": "spread" }));
    let r = app.create_cohort(&body).await;
    assert_eq!(r.status, StatusCode::ACCEPTED);
    assert_eq!(r.json()["latent_noise"], 0.5);
    assert_eq!(r.json()["selection"], "spread");
    let id = r.json()["id"].as_i64().unwrap();
    app.run_pending_jobs().await;

    let c = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(c["status"], "succeeded", "{c}");
    assert_eq!(
        (c["latent_noise"].as_f64(), c["selection"].as_str()),
        (Some(0.5), Some("spread"))
    );
    let p = app.get(&format!("/v1/cohorts/{plain}")).await.json();
    assert_eq!(
        (p["latent_noise"].as_f64(), p["selection"].as_str()),
        (Some(0.0), Some("uniform"))
    );

    let noisy = shapes(&app, id).await;
    assert_eq!(noisy.len(), 4);
    for s in &noisy {
        let prov = &s["provenance"];
        assert_eq!(
            (prov["latent_noise"].as_f64(), prov["selection"].as_str()),
            (Some(0.5), Some("spread"))
        );
        // The noise moves the shape off the plain mixture of its parents.
        let indices: Vec<usize> = serde_json::from_value(prov["training_indices"].clone()).unwrap();
        let weights: Vec<f64> = serde_json::from_value(prov["weights"].clone()).unwrap();
        assert!(indices.iter().all(|&i| i < TRAINING_SHAPES));
        let radius = mixed_axes(&indices, &weights)
            .into_iter()
            .fold(0.0, f64::max);
        assert!(
            (s["transform"]["radius"].as_f64().unwrap() - radius).abs() > 1e-3,
            "{s}"
        );
    }
    for s in shapes(&app, plain).await {
        assert_eq!(
            (
                s["provenance"]["latent_noise"].as_f64(),
                s["provenance"]["attempt"].as_i64()
            ),
            (Some(0.0), Some(0))
        );
    }
}

#[tokio::test]
async fn bad_diversity_and_novelty_values_are_rejected_naming_the_field() {
    let app = spawn_app().await;
    let cases = [
        (json!({ "latent_noise": -0.1 }), "latent_noise"),
        (json!({ "selection": "farthest" }), "selection"),
        (json!({ "min_novelty": -1e-3 }), "min_novelty"),
    ];
    for (extra, field) in cases {
        let r = app.create_cohort(&body_with(extra.clone())).await;
        assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY, "{extra}");
        assert_eq!(
            r.header("content-type"),
            Some("application/problem+json"),
            "{extra}"
        );
        assert_eq!(r.json()["field"], field, "{extra}: {}", r.json());
    }
    assert_eq!(app.count("cohort").await, 0);
}
