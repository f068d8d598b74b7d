//! Re-fitting a model's training shapes in the service (`POST /v1/models/{id}/refit`): one
//! task per shape, the fits stored per shape, a refit continued after a failure, and
//! cohorts drawn from the re-fitted latents. The analytic engine "re-fits" ellipsoid i to
//! its semi-axes × 1.1 (plus a trace of the shape's seed), so every stored latent has an
//! exact expectation.

use std::sync::atomic::Ordering;

use aortagen::formats::{MeshFormat, MeshMetadata, write_mesh};
use axum::http::{Method, StatusCode};
use serde_json::{Value, json};

use crate::engine::{AnalyticEngine, REFIT_SCALE, TRAINING_SHAPES, refitted_axes, uv_sphere};
use crate::helpers::{MODEL, TestApp, cohort_body, spawn_app, spawn_app_with};

fn refit_path() -> String {
    format!("/v1/models/{MODEL}/refit")
}

fn density_cohort(latents: &str) -> Value {
    let mut body = cohort_body(6, 2);
    body.as_object_mut().unwrap().remove("arity");
    body["sampler"] = json!({ "kind": "pca_gaussian", "latents": latents });
    body
}

async fn volumes(app: &TestApp, cohort: i64) -> Vec<f64> {
    app.shape_details(cohort)
        .await
        .iter()
        .map(|s| s["volume_mm3"].as_f64().unwrap())
        .collect()
}

#[tokio::test]
async fn a_refit_fits_every_training_shape_and_cohorts_then_draw_from_its_latents() {
    let app = spawn_app().await;
    let refused = app.create_cohort(&density_cohort("refitted")).await;
    assert_eq!(refused.status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(refused.detail().contains("/refit"), "{}", refused.detail());
    assert_eq!(
        app.get(&refit_path()).await.status,
        StatusCode::NOT_FOUND,
        "no refit before one is asked for"
    );

    let r = app
        .post_json(&refit_path(), &json!({ "iterations": 30, "seed": 5 }))
        .await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.detail());
    assert_eq!(r.header("location"), Some(refit_path().as_str()));
    let queued = r.json();
    assert_eq!(queued["status"], "refitting");
    assert_eq!(
        queued["progress"],
        json!({ "done": 0, "total": TRAINING_SHAPES })
    );
    let job_id = queued["job_id"].as_i64().unwrap();
    let deleted = app
        .request(Method::DELETE, &format!("/v1/models/{MODEL}"), &[], "")
        .await;
    assert_eq!(
        deleted.status,
        StatusCode::CONFLICT,
        "a model being re-fitted stays"
    );

    let outcomes = app.run_pending_jobs().await;
    assert_eq!(
        outcomes.len(),
        TRAINING_SHAPES,
        "one task per training shape"
    );
    let refit = app.get(&refit_path()).await.json();
    assert_eq!(refit["status"], "ready");
    assert_eq!(refit["progress"]["done"], TRAINING_SHAPES);
    let shapes = refit["shapes"].as_array().unwrap();
    assert_eq!(shapes.len(), TRAINING_SHAPES);
    for (i, shape) in shapes.iter().enumerate() {
        assert_eq!(shape["index"], i);
        assert_eq!(shape["name"], format!("ellipsoid-{i}"));
        assert_eq!(shape["seed"], 5 + 2 * i as u64);
        let latent: Vec<f64> = shape["latent"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let expected = refitted_axes(i, 5);
        for (got, want) in latent.iter().zip(expected) {
            assert!(
                (got - want).abs() < 1e-4,
                "shape {i}: {latent:?} vs {expected:?}"
            );
        }
    }
    let median = refit["median_chamfer"].as_f64().unwrap();
    assert!((median - 3e-4).abs() < 1e-12, "{median}");
    let job = app.get(&format!("/v1/jobs/{job_id}")).await.json();
    assert_eq!(job["status"], "succeeded");
    assert_eq!(job["kind"], "refit");
    assert_eq!(
        job["progress"],
        json!({ "done": TRAINING_SHAPES, "total": TRAINING_SHAPES })
    );

    // The same request again is the same refit; other settings are refused.
    let again = app
        .post_json(&refit_path(), &json!({ "iterations": 30, "seed": 5 }))
        .await;
    assert_eq!(again.status, StatusCode::OK);
    assert_eq!(again.json()["job_id"], job_id);
    let other = app
        .post_json(&refit_path(), &json!({ "iterations": 30, "seed": 6 }))
        .await;
    assert_eq!(other.status, StatusCode::CONFLICT);
    assert!(other.detail().contains("seed 5"), "{}", other.detail());

    // The same cohort request on both latent sources: the re-fitted ellipsoids are 10 %
    // larger, so the cohort drawn from them is larger by about 1.1³ in volume.
    let from_training = app.create_cohort_ok(&density_cohort("training")).await;
    let from_refits = app.create_cohort_ok(&density_cohort("refitted")).await;
    app.run_pending_jobs().await;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (training, refitted) = (
        volumes(&app, from_training).await,
        volumes(&app, from_refits).await,
    );
    assert_eq!(refitted.len(), 6);
    let ratio = mean(&refitted) / mean(&training);
    assert!(
        (ratio - REFIT_SCALE.powi(3)).abs() < 0.15,
        "volume ratio {ratio}: {refitted:?} against {training:?}"
    );
    let detail = app.shape_details(from_refits).await;
    assert_eq!(detail[0]["provenance"]["sampler"]["latents"], "refitted");
}

#[tokio::test]
async fn a_failed_refit_keeps_its_fitted_shapes_and_continues_with_the_rest() {
    let engine = AnalyticEngine {
        refit_breaks_at: Some(3),
        ..AnalyticEngine::default()
    };
    let app = spawn_app_with(engine).await;
    let r = app.post_json(&refit_path(), &json!({})).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.detail());
    let first_job = r.json()["job_id"].as_i64().unwrap();
    app.run_pending_jobs().await;
    let failed = app.get(&refit_path()).await.json();
    assert_eq!(failed["status"], "failed");
    assert_eq!(failed["iterations"], 800, "the default of `aortagen refit`");
    assert!(
        failed["error"].as_str().unwrap().contains("ellipsoid-3"),
        "{failed}"
    );
    let kept: Vec<i64> = failed["shapes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["index"].as_i64().unwrap())
        .collect();
    assert!(!kept.contains(&3), "{kept:?}");
    assert_eq!(
        app.create_cohort(&density_cohort("refitted")).await.status,
        StatusCode::UNPROCESSABLE_ENTITY,
        "an incomplete refit is not drawn from"
    );

    app.engine.refit_mended.store(true, Ordering::SeqCst);
    let calls_before = app.engine.refit_calls.load(Ordering::SeqCst);
    let r = app
        .post_json(&refit_path(), &json!({ "iterations": 800 }))
        .await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.detail());
    let continued = r.json();
    assert_ne!(continued["job_id"].as_i64().unwrap(), first_job);
    assert_eq!(continued["progress"]["done"], kept.len());
    assert_eq!(continued["status"], "refitting");
    app.run_pending_jobs().await;
    let calls = app.engine.refit_calls.load(Ordering::SeqCst) - calls_before;
    assert_eq!(
        calls,
        TRAINING_SHAPES - kept.len(),
        "only the shapes without a fit are fitted again"
    );
    let ready = app.get(&refit_path()).await.json();
    assert_eq!(ready["status"], "ready");
    assert_eq!(
        app.create_cohort(&density_cohort("refitted")).await.status,
        StatusCode::ACCEPTED
    );
}

#[tokio::test]
async fn a_cancelled_refit_is_continued_by_asking_again() {
    let app = spawn_app().await;
    let model = app.get(&format!("/v1/models/{MODEL}")).await.json();
    assert_eq!(model["refit_url"], refit_path());
    let r = app.post_json(&refit_path(), &json!({ "seed": 2 })).await;
    let job_id = r.json()["job_id"].as_i64().unwrap();
    let cancel = app
        .request(Method::POST, &format!("/v1/jobs/{job_id}/cancel"), &[], "")
        .await;
    assert!(cancel.status.is_success(), "{}", cancel.status);
    let cancelled = app.get(&refit_path()).await.json();
    assert_eq!(cancelled["status"], "cancelled");
    assert!(
        app.run_pending_jobs().await.is_empty(),
        "nothing left to run"
    );
    let r = app.post_json(&refit_path(), &json!({ "seed": 2 })).await;
    assert_eq!(r.status, StatusCode::ACCEPTED);
    assert_ne!(r.json()["job_id"], job_id);
    app.run_pending_jobs().await;
    let ready = app.get(&refit_path()).await.json();
    assert_eq!(ready["status"], "ready");
    assert_eq!(ready["shapes"][4]["seed"], 2 + 2 * 4);
}

/// The files of a directory with their bytes, by name.
fn files_of(dir: &std::path::Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let path = e.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(&path).unwrap())
        })
        .collect();
    files.sort();
    files
}

#[tokio::test]
async fn a_worker_without_the_uploaded_meshes_fetches_them_before_re_fitting() {
    let app = spawn_app().await;
    let stl = |rings| {
        write_mesh(
            &uv_sphere(rings, 8),
            MeshFormat::Stl,
            &MeshMetadata::new("mm"),
        )
    };
    let upload = app
        .upload_model(&[
            ("id", None, b"uploaded".to_vec()),
            ("files", Some("a.stl"), stl(6).unwrap()),
            ("files", Some("b.stl"), stl(8).unwrap()),
        ])
        .await;
    assert_eq!(upload.status, StatusCode::ACCEPTED, "{}", upload.detail());
    app.run_pending_jobs().await;
    // What a worker on another machine sees: the model, but not the upload's directory.
    let input = app.dir.path().join("models/uploaded/input");
    let uploaded = files_of(&input);
    assert_eq!(uploaded.len(), 2);
    std::fs::remove_dir_all(&input).unwrap();
    let r = app.post_json("/v1/models/uploaded/refit", &json!({})).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.detail());
    app.run_pending_jobs().await;
    let refit = app.get("/v1/models/uploaded/refit").await.json();
    assert_eq!(refit["status"], "ready", "{refit}");
    assert_eq!(refit["progress"], json!({ "done": 2, "total": 2 }));
    assert_eq!(
        files_of(&input),
        uploaded,
        "the same meshes, from the object store"
    );
}

#[tokio::test]
async fn bad_refit_requests_are_refused_naming_the_field_and_store_nothing() {
    let app = spawn_app().await;
    let cases = [
        (json!({ "iterations": 0 }), "iterations", "range"),
        (json!({ "iterations": 10001 }), "iterations", "range"),
        (json!({ "seed": 9223372036854775808u64 }), "seed", "range"),
    ];
    for (body, field, rule) in cases {
        let r = app.post_json(&refit_path(), &body).await;
        assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
        let p = r.json();
        assert_eq!(
            (p["field"].as_str(), p["rule"].as_str()),
            (Some(field), Some(rule)),
            "{p}"
        );
    }
    let r = app.post_json(&refit_path(), &json!({ "steps": 10 })).await;
    assert!(r.status.is_client_error(), "{}", r.status);
    assert!(r.detail().contains("steps"), "{}", r.detail());
    let r = app.post_json("/v1/models/nope/refit", &json!({})).await;
    assert_eq!(r.status, StatusCode::NOT_FOUND);

    let stl = write_mesh(&uv_sphere(6, 8), MeshFormat::Stl, &MeshMetadata::new("mm")).unwrap();
    let upload = app
        .upload_model(&[
            ("id", None, b"fresh".to_vec()),
            ("files", Some("a.stl"), stl.clone()),
            ("files", Some("b.stl"), stl),
        ])
        .await;
    assert_eq!(upload.status, StatusCode::ACCEPTED);
    let r = app.post_json("/v1/models/fresh/refit", &json!({})).await;
    assert_eq!(r.status, StatusCode::CONFLICT, "a model still training");
    assert_eq!(app.count("model_refit").await, 0, "nothing was stored");
    assert_eq!(app.count("job where kind = 'refit'").await, 0);
}
