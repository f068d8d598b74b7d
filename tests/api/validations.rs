//! Reference populations and validation jobs through the API: uploads checked before they
//! are stored, a validation of a finished cohort run as a job whose stored report has the
//! figures the statistics give on known inputs, and the bad requests named.

use aortagen::formats::{MeshFormat, MeshMetadata, write_mesh};
use axum::http::{Method, StatusCode};
use serde_json::{Value, json};

use crate::engine::{ellipsoid_unit, training_axes};
use crate::helpers::{MODEL, TestApp, TestResponse, cohort_body, multipart, spawn_app};

/// The training ellipsoid `i` as an STL file in mm.
fn ellipsoid_stl(i: usize) -> Vec<u8> {
    let mesh = ellipsoid_unit(training_axes(i), 1.0);
    write_mesh(&mesh, MeshFormat::Stl, &MeshMetadata::new("mm")).unwrap()
}

/// The upload of a mesh reference named `patients`: three training ellipsoids as STL.
fn patient_mesh_parts() -> Vec<(&'static str, Option<&'static str>, Vec<u8>)> {
    vec![
        ("name", None, b"patients".to_vec()),
        ("files", Some("p0.stl"), ellipsoid_stl(0)),
        ("files", Some("p1.stl"), ellipsoid_stl(2)),
        ("files", Some("p2.stl"), ellipsoid_stl(4)),
    ]
}

async fn upload(app: &TestApp, parts: &[(&str, Option<&str>, Vec<u8>)]) -> TestResponse {
    let (content_type, body) = multipart(parts);
    let path = format!("/v1/models/{MODEL}/references");
    app.request(
        Method::POST,
        &path,
        &[("content-type", &content_type)],
        body,
    )
    .await
}

fn problem(r: &TestResponse, status: StatusCode) -> (String, String, String) {
    assert_eq!(r.status, status, "{}", String::from_utf8_lossy(&r.body));
    let p = r.json();
    let text = |k: &str| p[k].as_str().unwrap_or_default().to_owned();
    (text("field"), text("rule"), text("detail"))
}

/// A finished cohort of `count` shapes and its shapes' (area, volume).
async fn finished_cohort(app: &TestApp, count: i64) -> (i64, Vec<(f64, f64)>) {
    let cohort = app.create_cohort_ok(&cohort_body(count, 2)).await;
    app.run_pending_jobs().await;
    let view = app.get(&format!("/v1/cohorts/{cohort}")).await.json();
    assert_eq!(view["status"], "succeeded", "{view}");
    let sizes = app
        .shape_details(cohort)
        .await
        .iter()
        .map(|s| {
            (
                s["area_mm2"].as_f64().unwrap(),
                s["volume_mm3"].as_f64().unwrap(),
            )
        })
        .collect();
    (cohort, sizes)
}

/// Posts a validation, runs it and returns the validation with its report.
async fn validate(app: &TestApp, cohort: i64, body: Value) -> Value {
    let r = app
        .post_json(&format!("/v1/cohorts/{cohort}/validations"), &body)
        .await;
    assert_eq!(
        r.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    let accepted = r.json();
    assert_eq!(accepted["status"], "queued", "{accepted}");
    let id = accepted["id"].as_i64().unwrap();
    let early = app.get(&format!("/v1/validations/{id}/report.html")).await;
    assert_eq!(early.status, StatusCode::CONFLICT);
    app.run_pending_jobs().await;
    let view = app.get(&format!("/v1/validations/{id}")).await.json();
    assert_eq!(view["status"], "succeeded", "{view}");
    view
}

fn feature<'a>(report: &'a Value, name: &str) -> &'a Value {
    report["features"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["feature"] == name)
        .unwrap_or_else(|| panic!("no {name} in {}", report["features"]))
}

#[tokio::test]
async fn a_table_reference_gives_the_exact_measurement_figures_and_the_verdict() {
    let app = spawn_app().await;
    let (cohort, sizes) = finished_cohort(&app, 6).await;
    let table = |shift: f64| {
        let mut csv = String::from("patient_id;area_mm2;volume_mm3\n");
        for (i, (a, v)) in sizes.iter().enumerate() {
            csv.push_str(&format!("p{i};{a};{}\n", v + shift));
        }
        csv.into_bytes()
    };
    let same = upload(
        &app,
        &[
            ("name", None, b"same".to_vec()),
            ("table", Some("t.csv"), table(0.0)),
        ],
    )
    .await;
    assert_eq!(
        same.status,
        StatusCode::CREATED,
        "{}",
        String::from_utf8_lossy(&same.body)
    );
    let same = same.json();
    assert_eq!(
        (same["kind"].as_str(), same["shapes"].as_i64()),
        (Some("measurements"), Some(6))
    );
    assert_eq!(same["has_surfaces"], false);
    // Volumes 10⁶ mm³ larger than every cohort shape's: no overlap at all.
    let shifted = upload(
        &app,
        &[
            ("name", None, b"shifted".to_vec()),
            ("table", None, table(1e6)),
        ],
    )
    .await;
    assert_eq!(shifted.status, StatusCode::CREATED);
    let listed = app
        .get(&format!("/v1/models/{MODEL}/references"))
        .await
        .json();
    // The analytic model has no manifest, hence no `training` or `heldout` of its own.
    let names: Vec<&str> = listed
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["same", "shifted"]);

    let criteria = json!({ "ks_p_min": 0.05 });
    let same_id = same["id"].as_i64().unwrap();
    let view = validate(
        &app,
        cohort,
        json!({ "reference": same_id, "criteria": criteria,
        "context_of_use": "TAVI sizing", "resamples": 200 }),
    )
    .await;
    let report = &view["report"];
    let volume = feature(report, "volume_mm3");
    // The same values on both sides: KS distance 0 (p = 1), Wasserstein distance 0.
    assert_eq!(volume["ks"]["statistic"], 0.0, "{volume}");
    assert_eq!(volume["ks"]["p_value"], 1.0, "{volume}");
    assert_eq!(volume["wasserstein"], 0.0, "{volume}");
    assert_eq!(view["verdict"], "pass", "{}", report["checks"]);
    // No surfaces in a table: the shape level says why instead of giving numbers.
    assert!(report["shapes"].is_null());
    assert!(
        report["not_computed"]["shapes"]
            .as_str()
            .unwrap()
            .contains("table"),
        "{report}"
    );
    assert_eq!(report["dossier"]["context_of_use"], "TAVI sizing");
    assert_eq!(report["dossier"]["cohort"]["id"], cohort);
    assert_eq!(report["dossier"]["reference"]["sha256"], same["sha256"]);
    assert_eq!(view["progress"]["done"], view["progress"]["total"]);

    let shifted_id = shifted.json()["id"].as_i64().unwrap();
    let view = validate(
        &app,
        cohort,
        json!({ "reference": shifted_id, "criteria": criteria,
        "resamples": 200 }),
    )
    .await;
    let volume = feature(&view["report"], "volume_mm3");
    // Equal-size samples shifted by a constant: W₁ is the shift; KS distance 1, exact
    // p = 2 / C(12, 6).
    let w1 = volume["wasserstein"].as_f64().unwrap();
    assert!((w1 - 1e6).abs() < 1e-6, "{w1}");
    assert_eq!(volume["ks"]["statistic"], 1.0);
    let p = volume["ks"]["p_value"].as_f64().unwrap();
    assert!((p - 2.0 / 924.0).abs() < 1e-9, "{p}");
    assert_eq!(view["verdict"], "fail");
    let html = app
        .get(&format!("/v1/validations/{}/report.html", view["id"]))
        .await;
    assert_eq!(html.status, StatusCode::OK);
    assert!(
        html.header("content-type")
            .unwrap()
            .starts_with("text/html")
    );
    assert!(String::from_utf8_lossy(&html.body).contains("volume_mm3"));
    let listed = app
        .get(&format!("/v1/cohorts/{cohort}/validations"))
        .await
        .json();
    assert_eq!(listed.as_array().unwrap().len(), 2);
    assert!(
        listed[0].get("report").is_none(),
        "lists leave the reports out"
    );
}

#[tokio::test]
async fn a_mesh_reference_gets_the_shape_level_and_deletions_keep_reports_consistent() {
    let app = spawn_app().await;
    let (cohort, _) = finished_cohort(&app, 4).await;
    let parts = patient_mesh_parts();
    let r = upload(&app, &parts).await;
    assert_eq!(
        r.status,
        StatusCode::CREATED,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    let reference = r.json();
    assert_eq!(
        (reference["kind"].as_str(), reference["shapes"].as_i64()),
        (Some("meshes"), Some(3))
    );
    let id = reference["id"].as_i64().unwrap();
    assert_eq!(
        r.header("location"),
        Some(format!("/v1/references/{id}").as_str())
    );
    // The same name twice: 409, nothing stored.
    assert_eq!(upload(&app, &parts).await.status, StatusCode::CONFLICT);
    assert_eq!(app.count("reference_population").await, 1);

    let view = validate(
        &app,
        cohort,
        json!({ "reference": id, "points": 500, "subsets": 20,
        "resamples": 100, "seed": 3 }),
    )
    .await;
    let shapes = &view["report"]["shapes"];
    let nna = shapes["nna"]["mean"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&nna), "{shapes}");
    assert!(shapes["pairwise"]["cohort"]["median"].as_f64().unwrap() > 0.0);
    assert_eq!(view["report"]["dossier"]["reference"]["kind"], "meshes");
    // The same request again gives the same figures (seeded).
    let again = validate(
        &app,
        cohort,
        json!({ "reference": id, "points": 500, "subsets": 20,
        "resamples": 100, "seed": 3 }),
    )
    .await;
    assert_eq!(again["report"]["shapes"], view["report"]["shapes"]);

    // A reference named by validations stays; a validation goes, then the reference.
    let path = format!("/v1/references/{id}");
    let r = app.request(Method::DELETE, &path, &[], "").await;
    problem(&r, StatusCode::CONFLICT);
    for v in [&view, &again] {
        let r = app
            .request(
                Method::DELETE,
                &format!("/v1/validations/{}", v["id"]),
                &[],
                "",
            )
            .await;
        assert_eq!(r.status, StatusCode::NO_CONTENT);
    }
    assert_eq!(
        app.request(Method::DELETE, &path, &[], "").await.status,
        StatusCode::NO_CONTENT
    );
    assert_eq!(app.get(&path).await.status, StatusCode::NOT_FOUND);

    // A cohort's validations and their jobs go with it.
    let table = b"id,volume_mm3\na,1\nb,2\n".to_vec();
    let r = upload(
        &app,
        &[("name", None, b"t".to_vec()), ("table", None, table)],
    )
    .await;
    let table_id = r.json()["id"].as_i64().unwrap();
    let v = validate(
        &app,
        cohort,
        json!({ "reference": table_id, "resamples": 50 }),
    )
    .await;
    let jobs_before = app.count("job").await;
    let r = app
        .request(Method::DELETE, &format!("/v1/cohorts/{cohort}"), &[], "")
        .await;
    assert_eq!(r.status, StatusCode::NO_CONTENT);
    assert_eq!(app.count("validation").await, 0);
    assert_eq!(app.count("job").await, jobs_before - 2);
    assert_eq!(
        app.get(&format!("/v1/validations/{}", v["id"]))
            .await
            .status,
        StatusCode::NOT_FOUND
    );
}

#[tokio::test]
async fn bad_references_and_validation_requests_are_named_and_store_nothing() {
    let app = spawn_app().await;
    let name = ("name", None, b"r".to_vec());
    // A column that is no feature, a length in cm, a cell that is no number.
    for (csv, field, rule) in [
        (
            "id,annulus_mm,colour\na,20,red\nb,21,blue\n",
            "columns[colour]",
            "unknown-column",
        ),
        ("id,D_an [cm]\na,2\nb,2.1\n", "columns[D_an [cm]]", "units"),
        (
            "id,annulus_mm\na,20\nb,big\n",
            "rows[1].annulus_mm",
            "value",
        ),
    ] {
        let r = upload(
            &app,
            &[name.clone(), ("table", None, csv.as_bytes().to_vec())],
        )
        .await;
        let (f, ru, detail) = problem(&r, StatusCode::UNPROCESSABLE_ENTITY);
        assert_eq!(f, field, "{detail}");
        assert_eq!(ru, rule, "{detail}");
    }
    let one_row = b"id,annulus_mm\na,20\n".to_vec();
    let r = upload(&app, &[name.clone(), ("table", None, one_row)]).await;
    let (field, rule, _) = problem(&r, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!((field.as_str(), rule.as_str()), ("rows", "too-few"));
    let r = upload(
        &app,
        &[name.clone(), ("files", Some("a.stl"), ellipsoid_stl(0))],
    )
    .await;
    assert_eq!(problem(&r, StatusCode::UNPROCESSABLE_ENTITY).0, "files");
    let r = upload(
        &app,
        &[
            name.clone(),
            ("files", Some("a.stl"), ellipsoid_stl(0)),
            ("files", Some("b.ply"), b"ply\nnonsense".to_vec()),
        ],
    )
    .await;
    assert_eq!(
        problem(&r, StatusCode::UNPROCESSABLE_ENTITY).0,
        "files[b.ply]"
    );
    let both = [
        name.clone(),
        ("table", None, b"id,annulus_mm\na,1\nb,2\n".to_vec()),
        ("files", Some("a.stl"), ellipsoid_stl(0)),
        ("files", Some("b.stl"), ellipsoid_stl(1)),
    ];
    assert_eq!(
        problem(&upload(&app, &both).await, StatusCode::UNPROCESSABLE_ENTITY).1,
        "exclusive"
    );
    let reserved = [
        ("name", None, b"heldout".to_vec()),
        ("table", None, b"id,annulus_mm\na,1\nb,2\n".to_vec()),
    ];
    assert_eq!(
        problem(
            &upload(&app, &reserved).await,
            StatusCode::UNPROCESSABLE_ENTITY
        )
        .1,
        "reserved"
    );
    assert_eq!(app.count("reference_population").await, 0);

    // Validation requests.
    let queued = app.create_cohort_ok(&cohort_body(3, 2)).await;
    let path = format!("/v1/cohorts/{queued}/validations");
    let r = app
        .post_json(&path, &json!({ "reference": "training" }))
        .await;
    let (_, _, detail) = problem(&r, StatusCode::CONFLICT);
    assert!(detail.contains("queued"), "{detail}");
    app.run_pending_jobs().await;
    for (body, field) in [
        (json!({ "reference": "heldout" }), "reference"),
        (json!({ "reference": 999 }), "reference"),
        (json!({ "reference": [1] }), "reference"),
        (
            json!({ "reference": "training", "criteria": { "nna_max": 2.0 } }),
            "criteria.nna_max",
        ),
        (json!({ "reference": "training", "points": 0 }), "points"),
        (
            json!({ "reference": "training", "discount": { "kind": "fixed", "value": -1.0 } }),
            "discount.value",
        ),
    ] {
        let r = app.post_json(&path, &body).await;
        let (f, _, detail) = problem(&r, StatusCode::UNPROCESSABLE_ENTITY);
        assert_eq!(f, field, "{body}: {detail}");
    }
    let r = app
        .post_json(&path, &json!({ "reference": "training", "colour": 1 }))
        .await;
    assert!(r.status.is_client_error(), "{}", r.status);
    assert_eq!(app.count("validation").await, 0);
    let r = app
        .post_json(
            "/v1/cohorts/999/validations",
            &json!({ "reference": "training" }),
        )
        .await;
    problem(&r, StatusCode::NOT_FOUND);

    // The shape-level work budget: 3 cohort shapes against 3 patients are 3 + 9 + 3 + 3 = 18
    // Chamfer distances; at 1 000 points that is 18 000.
    let app = crate::helpers::spawn_app_configured(|c| c.max_validation_work = 17_999).await;
    let cohort = app.create_cohort_ok(&cohort_body(3, 2)).await;
    app.run_pending_jobs().await;
    let parts = [
        ("name", None, b"p".to_vec()),
        ("files", Some("a.stl"), ellipsoid_stl(0)),
        ("files", Some("b.stl"), ellipsoid_stl(1)),
        ("files", Some("c.stl"), ellipsoid_stl(2)),
    ];
    let id = upload(&app, &parts).await.json()["id"].as_i64().unwrap();
    let path = format!("/v1/cohorts/{cohort}/validations");
    let r = app
        .post_json(&path, &json!({ "reference": id, "points": 1000 }))
        .await;
    let (field, rule, detail) = problem(&r, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(
        (field.as_str(), rule.as_str()),
        ("points", "budget"),
        "{detail}"
    );
    assert!(
        detail.contains("18 distances") && detail.contains("at most 999 points"),
        "{detail}"
    );
    let r = app
        .post_json(&path, &json!({ "reference": id, "points": 999 }))
        .await;
    assert_eq!(r.status, StatusCode::ACCEPTED);
}

#[tokio::test(flavor = "multi_thread")]
async fn the_bundled_models_training_shapes_are_a_reference_under_the_models_hash() {
    let app = crate::helpers::spawn_neural(&["default"], 500).await;
    let body =
        json!({ "model_id": "default", "count": 3, "arity": 2, "seed": 5, "resolution": 32 });
    let r = app.create_cohort(&body).await;
    assert_eq!(
        r.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    let cohort = r.json()["id"].as_i64().unwrap();
    app.run_pending_jobs().await;
    let refs = app.get("/v1/models/default/references").await.json();
    assert_eq!(refs.as_array().unwrap().len(), 1, "{refs}");
    assert_eq!(
        (refs[0]["id"].as_str(), refs[0]["shapes"].as_i64()),
        (Some("training"), Some(16))
    );
    // Trained without a holdout: no new patients to compare with.
    let path = format!("/v1/cohorts/{cohort}/validations");
    let r = app
        .post_json(&path, &json!({ "reference": "heldout" }))
        .await;
    let (field, _, detail) = problem(&r, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(field, "reference");
    assert!(detail.contains("holdout"), "{detail}");

    let r = app
        .post_json(
            &path,
            &json!({ "reference": "training", "points": 300, "subsets": 10, "resamples": 50 }),
        )
        .await;
    assert_eq!(
        r.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    let id = r.json()["id"].as_i64().unwrap();
    app.run_pending_jobs().await;
    let view = app.get(&format!("/v1/validations/{id}")).await.json();
    assert_eq!(view["status"], "succeeded", "{view}");
    let report = &view["report"];
    let manifest: Value = serde_json::from_slice(
        &std::fs::read(app.dir.path().join("models/default/manifest.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(
        report["dossier"]["model_sha256"],
        manifest["weights"]["sha256"]
    );
    assert_eq!(report["dossier"]["reference"]["shapes"], 16);
    assert_eq!(report["dossier"]["cohort"]["shapes"], 3);
    let shapes = &report["shapes"];
    assert!(shapes["nna"]["mean"].is_f64(), "{shapes}");
    // Against its own training set there is no real-vs-real baseline, and DCR has no
    // new patients to stand beside.
    assert!(shapes["baseline"].is_null(), "{shapes}");
    let why = |k: &str| {
        shapes["not_computed"][k]
            .as_str()
            .unwrap_or_default()
            .to_owned()
    };
    assert!(why("baseline").contains("training set"), "{shapes}");
    assert!(
        shapes["dcr"].is_null() && why("dcr").contains("held-out"),
        "{shapes}"
    );
    assert_eq!(shapes["pairwise"]["reference"]["count"], 16 * 15 / 2);
    let total = view["progress"]["total"].as_i64().unwrap();
    assert!(total > 0 && view["progress"]["done"] == total, "{view}");
}

#[tokio::test]
async fn a_validation_cancelled_during_its_chamfer_distances_stops_there() {
    let app = spawn_app().await;
    let (cohort, _) = finished_cohort(&app, 4).await;
    let parts = patient_mesh_parts();
    let r = upload(&app, &parts).await;
    assert_eq!(r.status, StatusCode::CREATED);
    let reference = r.json()["id"].as_i64().unwrap();
    // Many points per shape: each distance takes a while, so the cancel lands among them.
    let r = app
        .post_json(
            &format!("/v1/cohorts/{cohort}/validations"),
            &json!({ "reference": reference, "points": 100_000, "subsets": 10, "resamples": 50 }),
        )
        .await;
    assert_eq!(
        r.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    let validation = r.json();
    let path = format!("/v1/validations/{}", validation["id"]);
    let (worker, stop) = crate::jobs::spawn_worker(&app);
    let seen = app
        .poll_json(&path, |v| v["progress"]["done"].as_i64().unwrap_or(0) > 0)
        .await;
    let total = seen["progress"]["total"].as_i64().unwrap();
    let r = app
        .request(
            Method::POST,
            &format!("/v1/jobs/{}/cancel", validation["job_id"]),
            &[],
            "",
        )
        .await;
    assert_eq!(
        r.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    let seen = app.poll_json(&path, |v| v["status"] == "cancelled").await;
    assert!(
        seen["report"].is_null() && seen["verdict"].is_null(),
        "{seen}"
    );
    stop.send(true).unwrap();
    worker.await.unwrap();
    let done = app.get(&path).await.json()["progress"]["done"]
        .as_i64()
        .unwrap();
    assert!(
        done < total,
        "every one of the {total} distances was computed after the cancel"
    );
}
