//! Cohort science: diversity controls (latent noise, spread selection), novelty against
//! the training shapes and anatomical measurements per shape.

use axum::http::StatusCode;
use serde_json::{Value, json};

use crate::engine::{TRAINING_SHAPES, mixed_axes};
use crate::helpers::{cohort_body, cohort_body_with, spawn_app};

#[tokio::test]
async fn a_cohort_with_latent_noise_and_spread_selection_succeeds_and_records_them() {
    let app = spawn_app().await;
    let plain = app.create_cohort_ok(&cohort_body(4, 2)).await;
    let body = cohort_body_with(json!({ "latent_noise": 0.5, "selection": "spread" }));
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

    let noisy = app.shape_details(id).await;
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
    for s in app.shape_details(plain).await {
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
        let r = app.create_cohort(&cohort_body_with(extra.clone())).await;
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

#[tokio::test]
async fn every_shape_reports_its_novelty_and_the_metrics_summarise_it() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(5, 2)).await;
    app.run_pending_jobs().await;
    let shapes = app.shape_details(id).await;
    assert_eq!(shapes.len(), 5);
    let mut cds = Vec::new();
    for s in &shapes {
        let cd = s["novelty_cd"].as_f64().unwrap_or_else(|| panic!("{s}"));
        assert!(cd.is_finite() && cd >= 0.0, "{s}");
        let nearest = s["nearest_training_index"].as_u64().unwrap() as usize;
        assert!(nearest < TRAINING_SHAPES, "{s}");
        assert_eq!(
            (s["redraws"].as_i64(), s["novelty_met"].as_bool()),
            (Some(0), Some(true))
        );
        cds.push(cd);
    }
    let m = app.get(&format!("/v1/cohorts/{id}/metrics")).await;
    assert_eq!(m.status, StatusCode::OK);
    let novelty = &m.json()["novelty"];
    assert_eq!(novelty["summary"]["count"], 5, "{novelty}");
    let mean = cds.iter().sum::<f64>() / 5.0;
    assert!((novelty["summary"]["mean"].as_f64().unwrap() - mean).abs() < 1e-12 * mean.max(1.0));
    let max = cds.iter().cloned().fold(0.0, f64::max);
    assert_eq!(novelty["summary"]["max"].as_f64(), Some(max));
    assert_eq!(
        novelty["summary"]["histogram"]["counts"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_i64().unwrap())
            .sum::<i64>(),
        5
    );
    let counts: Vec<i64> =
        serde_json::from_value(novelty["nearest_training_counts"].clone()).unwrap();
    assert_eq!(
        (counts.len(), counts.iter().sum::<i64>()),
        (TRAINING_SHAPES, 5)
    );
    assert_eq!(
        (
            novelty["redraws_total"].as_i64(),
            novelty["not_met"].as_i64()
        ),
        (Some(0), Some(0))
    );
}

#[tokio::test]
async fn an_unreachable_min_novelty_keeps_the_most_novel_draw_and_flags_it() {
    let app = spawn_app().await;
    let id = app
        .create_cohort_ok(&cohort_body_with(json!({ "count": 2, "min_novelty": 1e6 })))
        .await;
    app.run_pending_jobs().await;
    let c = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(c["status"], "succeeded", "{c}");
    assert_eq!(
        (c["min_novelty"].as_f64(), c["redraws_total"].as_i64()),
        (Some(1e6), Some(20))
    );
    for s in app.shape_details(id).await {
        assert_eq!(
            (s["redraws"].as_i64(), s["novelty_met"].as_bool()),
            (Some(10), Some(false)),
            "{s}"
        );
        let attempt = s["provenance"]["attempt"].as_i64().unwrap();
        assert!((0..=10).contains(&attempt), "{s}");
    }
    // 2 shapes × 11 draws each.
    assert_eq!(
        app.engine.calls.load(std::sync::atomic::Ordering::SeqCst),
        22
    );
    let novelty = &app.get(&format!("/v1/cohorts/{id}/metrics")).await.json()["novelty"];
    assert_eq!(
        (
            novelty["redraws_total"].as_i64(),
            novelty["not_met"].as_i64()
        ),
        (Some(20), Some(2))
    );

    // A reachable minimum: every shape meets it, and a replay gives the same shapes.
    let easy = cohort_body_with(json!({ "count": 3, "min_novelty": 0.0 }));
    let a = app.create_cohort_ok(&easy).await;
    app.run_pending_jobs().await;
    for s in app.shape_details(a).await {
        assert_eq!(
            (s["redraws"].as_i64(), s["novelty_met"].as_bool()),
            (Some(0), Some(true)),
            "{s}"
        );
    }
}

#[tokio::test]
async fn the_most_novel_draw_is_the_one_kept() {
    let app = spawn_app().await;
    let id = app
        .create_cohort_ok(&cohort_body_with(
            json!({ "count": 1, "min_novelty": 1e6, "weighting": "dirichlet" }),
        ))
        .await;
    app.run_pending_jobs().await;
    let kept = &app.shape_details(id).await[0];
    let kept_cd = kept["novelty_cd"].as_f64().unwrap();
    // Every draw of the same shape, replayed without a minimum from its recorded attempt seeds,
    // is no more novel than the kept one: compare against draws 0 (the plain cohort).
    let plain = app
        .create_cohort_ok(&cohort_body_with(
            json!({ "count": 1, "weighting": "dirichlet" }),
        ))
        .await;
    app.run_pending_jobs().await;
    let first = &app.shape_details(plain).await[0];
    assert!(
        kept_cd >= first["novelty_cd"].as_f64().unwrap(),
        "{kept} vs {first}"
    );
}

#[tokio::test]
async fn every_shape_carries_its_anatomy_or_the_reason_and_the_metrics_summarise_it() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(4, 2)).await;
    app.run_pending_jobs().await;
    let mut lengths = Vec::new();
    let mut annuli = Vec::new();
    let mut failed = 0;
    for s in app.shape_details(id).await {
        match (&s["anatomy"], &s["anatomy_error"]) {
            (Value::Object(a), Value::Null) => {
                let length = a["length_mm"].as_f64().unwrap();
                // The analytic shapes are ellipsoids: measured along their long axis (mm).
                let long_axis = 2.0 * s["transform"]["radius"].as_f64().unwrap();
                assert!(length > 0.0 && length <= long_axis * 1.01, "{s}");
                lengths.push(length);
                match a["method"].as_str() {
                    Some("root") => annuli.push(a["annulus_mm"].as_f64().unwrap()),
                    Some("vessel") => assert!(a["annulus_mm"].is_null(), "{s}"),
                    _ => panic!("unknown method: {s}"),
                }
            }
            (Value::Null, Value::String(reason)) => {
                assert!(!reason.is_empty());
                failed += 1;
            }
            other => panic!("anatomy and its error must be exclusive: {other:?}"),
        }
    }
    let m = app.get(&format!("/v1/cohorts/{id}/metrics")).await.json();
    let anatomy = &m["anatomy"];
    assert_eq!(
        anatomy["measured"].as_i64(),
        Some(lengths.len() as i64),
        "{anatomy}"
    );
    assert_eq!(anatomy["failed"].as_i64(), Some(failed), "{anatomy}");
    assert_eq!(
        anatomy["roots"].as_u64(),
        Some(annuli.len() as u64),
        "{anatomy}"
    );
    for key in ["annulus_mm", "sinus_mm", "stj_mm", "sinus_height_mm"] {
        match annuli.len() {
            0 => assert!(anatomy[key].is_null(), "{key}: {anatomy}"),
            n => assert_eq!(anatomy[key]["count"].as_u64(), Some(n as u64), "{key}"),
        }
    }
    if let Some(min) = annuli.iter().cloned().reduce(f64::min) {
        assert_eq!(anatomy["annulus_mm"]["min"].as_f64(), Some(min));
    }
    if lengths.is_empty() {
        assert!(anatomy["length_mm"].is_null());
    } else {
        let mean = lengths.iter().sum::<f64>() / lengths.len() as f64;
        assert_eq!(
            anatomy["length_mm"]["count"].as_u64(),
            Some(lengths.len() as u64)
        );
        assert!((anatomy["length_mm"]["mean"].as_f64().unwrap() - mean).abs() < 1e-9 * mean);
    }
}

#[tokio::test]
async fn remeasuring_brings_stored_measurements_of_an_earlier_method_to_todays() {
    use aortagen::anatomy::shape::{MEASUREMENT_VERSION, ShapeAnatomy};
    use aortagen::jobs::remeasure::{RemeasureCounts, remeasure_stored_shapes};
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(4, 2)).await;
    app.run_pending_jobs().await;
    let today = app.shape_details(id).await;
    let pool = &app.state.pool;
    // As an earlier method left them: measured shapes without a version and with other
    // lengths; one shape with a failure's reason instead.
    let mut measured = 0;
    for (i, shape) in today.iter().enumerate() {
        let shape_id = shape["id"].as_i64().unwrap();
        let old = match (i, &shape["anatomy"]) {
            (0, _) | (_, Value::Null) => Err("no centreline (earlier method)"),
            (_, anatomy) => {
                measured += 1;
                let mut a = anatomy.clone();
                a.as_object_mut().unwrap().remove("measurement_version");
                a["length_mm"] = json!(12345.0);
                Ok(serde_json::from_value::<ShapeAnatomy>(a).unwrap())
            }
        };
        assert!(
            aortagen::db::shapes::set_anatomy(pool, shape_id, old.as_ref().map_err(|e| *e))
                .await
                .unwrap()
        );
    }
    assert!(measured > 0, "the analytic shapes measure: {today:?}");
    let metrics = app.get(&format!("/v1/cohorts/{id}/metrics")).await.json();
    assert_eq!(metrics["anatomy"]["length_mm"]["max"], 12345.0, "{metrics}");

    let mut seen = Vec::new();
    let counts = remeasure_stored_shapes(pool, &app.state.jobs.objects, &mut |c| seen.push(*c))
        .await
        .unwrap();
    assert_eq!(counts.examined, today.len() as u64);
    assert_eq!((counts.current, counts.unreadable), (0, 0), "{counts:?}");
    assert_eq!(counts.measured + counts.failed, today.len() as u64);
    assert_eq!(seen.last(), Some(&counts));
    // Every shape reads as it did when it was made, the failed one included.
    assert_eq!(app.shape_details(id).await, today);
    for shape in &today {
        if let Value::Object(a) = &shape["anatomy"] {
            assert_eq!(a["measurement_version"], MEASUREMENT_VERSION);
        }
    }
    // A second pass finds nothing to do but the shapes that cannot be measured.
    let failing = today.iter().filter(|s| s["anatomy"].is_null()).count() as u64;
    let again = remeasure_stored_shapes(pool, &app.state.jobs.objects, &mut |_| {})
        .await
        .unwrap();
    assert_eq!(
        again,
        RemeasureCounts {
            examined: today.len() as u64,
            current: today.len() as u64 - failing,
            measured: 0,
            failed: failing,
            unreadable: 0,
        }
    );
}
