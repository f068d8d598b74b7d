//! Conditioned cohorts: target ranges for anatomical measurements, their validation and
//! feasibility, and the bounded per-shape candidate search.

use std::sync::atomic::Ordering;

use aortagen::anatomy::shape::{MEASUREMENT_VERSION, measure_shape};
use aortagen::geometry::normalize::UnitBallTransform;
use axum::http::StatusCode;
use serde_json::json;

use crate::engine::{AnalyticEngine, CENTRE_MM, TRAINING_SHAPES, ellipsoid_unit, training_axes};
use crate::helpers::{MODEL, cohort_body, cohort_body_with, spawn_app, spawn_on_configured};

/// Centreline lengths (mm) of the analytic training ellipsoids, measured as the service
/// measures them.
fn training_lengths() -> Vec<f64> {
    (0..TRAINING_SHAPES)
        .map(|i| {
            let axes = training_axes(i);
            let radius = axes.iter().cloned().fold(0.0, f64::max);
            let transform = UnitBallTransform {
                centre: CENTRE_MM,
                radius,
            };
            let mesh = transform.mesh_to_mesh_units(&ellipsoid_unit(axes, radius));
            measure_shape(&mesh)
                .expect("an ellipsoid measures")
                .length_mm
        })
        .collect()
}

#[tokio::test]
async fn bad_targets_are_rejected_naming_the_field_and_rule() {
    let app = spawn_app().await;
    let cases = [
        (json!({ "targets": {} }), "targets", "non-empty"),
        (
            json!({ "targets": { "aorta_mm": { "min": 1.0 } } }),
            "targets.aorta_mm",
            "unknown-measurement",
        ),
        (
            json!({ "targets": { "length_mm": { "min": 80.0, "max": 60.0 } } }),
            "targets.length_mm",
            "min-le-max",
        ),
        (
            json!({ "targets": { "length_mm": { "min": -1.0 } } }),
            "targets.length_mm.min",
            "non-negative",
        ),
        (
            json!({ "targets": { "length_mm": { "max": "NaN" } } }),
            "targets.length_mm.max",
            "type",
        ),
        (
            json!({ "targets": { "length_mm": {} } }),
            "targets.length_mm",
            "bound-required",
        ),
        (
            json!({ "targets": { "length_mm": { "min": 1.0, "mx": 2.0 } } }),
            "targets.length_mm.mx",
            "unknown-field",
        ),
        (
            json!({ "targets": { "length_mm": { "min": 1.0 } }, "max_candidates": 0 }),
            "max_candidates",
            "range",
        ),
        (
            json!({ "targets": { "length_mm": { "min": 1.0 } }, "max_candidates": 101 }),
            "max_candidates",
            "range",
        ),
        (
            json!({ "max_candidates": 5 }),
            "max_candidates",
            "requires-targets",
        ),
    ];
    for (extra, field, rule) in cases {
        let r = app.create_cohort(&cohort_body_with(extra.clone())).await;
        assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY, "{extra}");
        assert_eq!(r.header("content-type"), Some("application/problem+json"));
        let p = r.json();
        assert_eq!(
            (p["field"].as_str(), p["rule"].as_str()),
            (Some(field), Some(rule)),
            "{p}"
        );
    }
    assert_eq!(app.count("cohort").await, 0);
}

#[tokio::test]
async fn an_impossible_target_is_refused_with_the_achievable_range() {
    let app = spawn_app().await;
    let lengths = training_lengths();
    let longest = lengths.iter().cloned().fold(0.0, f64::max);
    let shortest = lengths.iter().cloned().fold(f64::INFINITY, f64::min);
    // Beyond the 5 % margin above the longest training shape.
    let min = (longest * 1.06).ceil();
    let body = cohort_body_with(json!({ "targets": { "length_mm": { "min": min } } }));
    let r = app.create_cohort(&body).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
    let p = r.json();
    assert_eq!(
        (p["field"].as_str(), p["rule"].as_str()),
        (Some("targets.length_mm"), Some("feasible")),
        "{p}"
    );
    let detail = p["detail"].as_str().unwrap();
    let achievable = format!(
        "[{:.2}, {:.2}] mm",
        shortest - 0.05 * longest,
        longest + 0.05 * longest
    );
    assert!(detail.contains(&achievable), "{detail} lacks {achievable}");
    assert_eq!(app.count("cohort").await, 0);
    // The training shapes were measured once and stored with the model.
    let calls = app.engine.calls.load(Ordering::SeqCst);
    assert_eq!(calls, TRAINING_SHAPES);
    let r = app.create_cohort(&body).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(app.engine.calls.load(Ordering::SeqCst), calls);
}

#[tokio::test]
async fn training_measurements_of_an_earlier_method_are_taken_again() {
    let app = spawn_app().await;
    let lengths = training_lengths();
    let longest = lengths.iter().cloned().fold(0.0, f64::max);
    let body = cohort_body_with(json!({ "targets": { "length_mm": { "min": longest * 1.06 } } }));
    let r = app.create_cohort(&body).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
    let calls = app.engine.calls.load(Ordering::SeqCst);
    // The stored record as an earlier method left it: no version, other lengths.
    let pool = &app.state.pool;
    let mut stored = aortagen::db::models::training_anatomy(pool, MODEL)
        .await
        .unwrap()
        .expect("measured by the first request");
    assert_eq!(stored.measurement_version, MEASUREMENT_VERSION);
    let mut old = serde_json::to_value(&stored).unwrap();
    old.as_object_mut().unwrap().remove("measurement_version");
    for shape in old["shapes"].as_array_mut().unwrap() {
        shape.as_object_mut().unwrap().remove("measurement_version");
        shape["length_mm"] = json!(10.0 * longest);
    }
    stored = serde_json::from_value(old).unwrap();
    assert_eq!(stored.measurement_version, 1);
    aortagen::db::models::set_training_anatomy(pool, MODEL, &stored)
        .await
        .unwrap();
    // Against the old lengths the target would be feasible; today's measure refuses it.
    let r = app.create_cohort(&body).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(r.json()["rule"], "feasible");
    assert_eq!(
        app.engine.calls.load(Ordering::SeqCst),
        calls + TRAINING_SHAPES,
        "every training shape measured again"
    );
    let again = aortagen::db::models::training_anatomy(pool, MODEL)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(again.measurement_version, MEASUREMENT_VERSION);
    assert!(
        again
            .shapes
            .iter()
            .flatten()
            .all(|a| a.length_mm < 2.0 * longest)
    );
    assert_eq!(app.count("cohort").await, 0);
}

#[tokio::test]
async fn a_first_targeted_request_does_not_wait_out_the_measurement_and_its_job_checks() {
    // The training shapes' measurement cannot finish until released, so a request that
    // waited for it would run into its 3 s deadline (408).
    let engine = AnalyticEngine {
        hold_from_call: Some(0),
        ..AnalyticEngine::default()
    };
    let dir = std::sync::Arc::new(tempfile::tempdir().unwrap());
    let url = format!("sqlite://{}", dir.path().join("aortagen.db").display());
    let app = spawn_on_configured(engine, dir, url, |c| c.request_timeout_secs = 3).await;
    let longest = training_lengths().into_iter().fold(0.0, f64::max);
    let min = (longest * 1.06).ceil();
    let body = cohort_body_with(json!({ "targets": { "length_mm": { "min": min } } }));
    let r = app.create_cohort(&body).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.json());
    let cohort = r.json()["id"].as_i64().unwrap();

    app.engine.release.store(true, Ordering::SeqCst);
    app.run_pending_jobs().await;
    let c = app.get(&format!("/v1/cohorts/{cohort}")).await.json();
    let job = app.get(&format!("/v1/jobs/{}", c["job_id"])).await.json();
    assert_eq!(job["status"], "failed", "{job}");
    let error = job["error"].as_str().unwrap();
    assert!(
        error.contains("length_mm") && error.contains("outside the achievable range"),
        "{error}"
    );
    assert_eq!(app.count("shape").await, 0);
    // The request and the job shared one measurement, now stored: the same request is
    // refused at the edge without measuring again.
    assert_eq!(app.engine.calls.load(Ordering::SeqCst), TRAINING_SHAPES);
    let r = app.create_cohort(&body).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(r.json()["rule"], "feasible");
    assert_eq!(app.engine.calls.load(Ordering::SeqCst), TRAINING_SHAPES);
}

#[tokio::test]
async fn a_feasible_target_is_met_by_every_shape_and_reported() {
    let app = spawn_app().await;
    let mut lengths = training_lengths();
    lengths.sort_by(f64::total_cmp);
    // The middle of the training range: plain draws of two shapes often miss it.
    let (lo, hi) = (lengths[1], lengths[3]);
    let targets = json!({ "length_mm": { "min": lo, "max": hi } });
    let body = cohort_body_with(json!({ "count": 5, "targets": targets, "max_candidates": 20 }));
    let id = app.create_cohort_ok(&body).await;
    app.run_pending_jobs().await;
    let c = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(c["status"], "succeeded", "{c}");
    assert_eq!(c["targets"], targets);
    assert_eq!(c["max_candidates"], 20);

    let shapes = app.shape_details(id).await;
    let mut total = 0;
    let mut met = 0;
    for s in &shapes {
        let prov = &s["provenance"];
        let candidates = prov["candidates"].as_i64().unwrap();
        assert!((1..=20).contains(&candidates), "{s}");
        total += candidates;
        let length = s["anatomy"]["length_mm"].as_f64().unwrap();
        let inside = (lo..=hi).contains(&length);
        assert_eq!(prov["targets_met"].as_bool(), Some(inside), "{s}");
        met += i64::from(inside);
    }
    assert_eq!(met, 5, "every shape should meet the target: {shapes:?}");
    assert!(
        total > 5,
        "the band is narrow enough that some shapes search: {total}"
    );
    assert_eq!(c["candidates_total"].as_i64(), Some(total));
    assert_eq!(c["targets_not_met"].as_i64(), Some(0));

    let anatomy = &app.get(&format!("/v1/cohorts/{id}/metrics")).await.json()["anatomy"];
    assert_eq!(
        anatomy["candidates_total"].as_i64(),
        Some(total),
        "{anatomy}"
    );
    let t = &anatomy["targets"][0];
    assert_eq!(t["measurement"], "length_mm");
    assert_eq!(t["target"], targets["length_mm"]);
    assert_eq!(
        (t["inside"].as_i64(), t["measured"].as_i64()),
        (Some(5), Some(5))
    );
    assert_eq!(t["fraction_inside"].as_f64(), Some(1.0));
    assert!(t["achieved"]["min"].as_f64().unwrap() >= lo, "{t}");
    assert!(t["achieved"]["max"].as_f64().unwrap() <= hi, "{t}");

    // The same request and seed give the same shapes, candidate for candidate.
    let again = app.create_cohort_ok(&body).await;
    app.run_pending_jobs().await;
    let replay = app.shape_details(again).await;
    for (a, b) in shapes.iter().zip(&replay) {
        assert_eq!(
            a["provenance"]["training_indices"],
            b["provenance"]["training_indices"]
        );
        assert_eq!(a["provenance"]["weights"], b["provenance"]["weights"]);
        assert_eq!(a["provenance"]["candidates"], b["provenance"]["candidates"]);
        assert_eq!(a["provenance"]["attempt"], b["provenance"]["attempt"]);
        assert_eq!(a["anatomy"], b["anatomy"]);
    }
}

#[tokio::test]
async fn drawn_weights_are_refined_into_a_narrow_target_and_fixed_weights_are_kept() {
    let app = spawn_app().await;
    let mut lengths = training_lengths();
    lengths.sort_by(f64::total_cmp);
    // A 1 mm band between two training shapes: a plain draw lands in it about one time in
    // ten, a refinement of a mixture that spans it almost always.
    let mid = (lengths[1] + lengths[2]) / 2.0;
    let (lo, hi) = (mid - 0.5, mid + 0.5);
    let targets = json!({ "length_mm": { "min": lo, "max": hi } });
    let body = cohort_body_with(json!({ "count": 6, "targets": targets, "max_candidates": 5 }));
    let id = app.create_cohort_ok(&body).await;
    app.run_pending_jobs().await;
    let c = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(c["targets_not_met"].as_i64(), Some(0), "{c}");
    for s in app.shape_details(id).await {
        let length = s["anatomy"]["length_mm"].as_f64().unwrap();
        assert!((lo..=hi).contains(&length), "{s}");
        let weights: Vec<f64> = serde_json::from_value(s["provenance"]["weights"].clone()).unwrap();
        let sum: f64 = weights.iter().sum();
        assert!(
            (sum - 1.0).abs() < 1e-9 && weights.iter().all(|&w| w >= 0.0),
            "{s}"
        );
    }

    // Weights the request fixes are never refined: the search only redraws the shapes.
    let fixed = cohort_body_with(json!({
        "count": 3, "targets": targets, "max_candidates": 3, "weights": [0.7, 0.3]
    }));
    let id = app.create_cohort_ok(&fixed).await;
    app.run_pending_jobs().await;
    for s in app.shape_details(id).await {
        assert_eq!(s["provenance"]["weights"], json!([0.7, 0.3]), "{s}");
    }
}

#[tokio::test]
async fn an_unmet_target_is_searched_to_the_bound_and_the_closest_shape_is_flagged() {
    let app = spawn_app().await;
    let lengths = training_lengths();
    let longest = lengths.iter().cloned().fold(0.0, f64::max);
    // Inside the feasibility margin but beyond every mixture of the training shapes.
    let min = longest * 1.03;
    let body = cohort_body_with(json!({
        "count": 2,
        "resolution": 96,
        "targets": { "length_mm": { "min": min } },
        "max_candidates": 3
    }));
    let id = app.create_cohort_ok(&body).await;
    app.run_pending_jobs().await;
    let c = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(c["status"], "succeeded", "{c}");
    assert_eq!(
        (
            c["candidates_total"].as_i64(),
            c["targets_not_met"].as_i64()
        ),
        (Some(6), Some(2)),
        "{c}"
    );
    for s in app.shape_details(id).await {
        let prov = &s["provenance"];
        assert_eq!(
            (prov["candidates"].as_i64(), prov["targets_met"].as_bool()),
            (Some(3), Some(false)),
            "{s}"
        );
        assert!(s["anatomy"]["length_mm"].as_f64().unwrap() < min, "{s}");
    }
    // Training shapes once, then per shape three coarse screens (resolution 96 > 64) and
    // one final mesh of the closest.
    assert_eq!(
        app.engine.calls.load(Ordering::SeqCst),
        TRAINING_SHAPES + 2 * (3 + 1)
    );
    let t = &app.get(&format!("/v1/cohorts/{id}/metrics")).await.json()["anatomy"]["targets"][0];
    assert_eq!(
        (t["inside"].as_i64(), t["fraction_inside"].as_f64()),
        (Some(0), Some(0.0))
    );
}

#[tokio::test]
async fn cohorts_without_targets_report_no_search() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(2, 2)).await;
    app.run_pending_jobs().await;
    let c = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert!(
        c.get("targets").is_none() && c.get("max_candidates").is_none(),
        "{c}"
    );
    assert_eq!(
        (
            c["candidates_total"].as_i64(),
            c["targets_not_met"].as_i64()
        ),
        (Some(0), Some(0))
    );
    for s in app.shape_details(id).await {
        assert!(s["provenance"]["candidates"].is_null(), "{s}");
        assert!(s["provenance"]["targets_met"].is_null(), "{s}");
    }
    // No training measurements were needed: one engine call per shape.
    assert_eq!(app.engine.calls.load(Ordering::SeqCst), 2);
}
