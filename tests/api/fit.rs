//! Fitting new shapes (`POST /v1/models/{id}/fit`), anchors, and anchors in cohorts. The
//! analytic engine "fits" a mesh by its bounding box's half extents (its ellipsoid
//! semi-axes), so the stored latent and the mixed shapes have exact expectations.

use aortagen::formats::{MeshFormat, MeshMetadata, write_mesh};
use axum::http::{Method, StatusCode};
use serde_json::{Value, json};

use crate::engine::{ellipsoid_unit, mixed_axes, uv_sphere};
use crate::helpers::{MAX_UPLOAD, MODEL, TestApp, TestResponse, multipart, spawn_app};

/// Starts training a model `id` of two spheres (a job left queued).
async fn upload_two_spheres(app: &TestApp, id: &str) -> TestResponse {
    let stl = write_mesh(&uv_sphere(6, 8), MeshFormat::Stl, &MeshMetadata::new("mm")).unwrap();
    app.upload_model(&[
        ("id", None, id.as_bytes().to_vec()),
        ("files", Some("a.stl"), stl.clone()),
        ("files", Some("b.stl"), stl),
    ])
    .await
}

/// Semi-axes (mm) of the uploaded ellipsoid, and where it is centred.
const AXES: [f64; 3] = [13.0, 14.0, 34.5];
const CENTRE: [f32; 3] = [5.0, -3.0, 2.0];

fn ellipsoid_stl(axes: [f64; 3]) -> Vec<u8> {
    let mut mesh = ellipsoid_unit(axes, 1.0);
    for p in &mut mesh.positions {
        for (c, o) in p.iter_mut().zip(CENTRE) {
            *c += o;
        }
    }
    write_mesh(&mesh, MeshFormat::Stl, &MeshMetadata::new("mm")).unwrap()
}

async fn fit(app: &TestApp, model: &str, parts: &[(&str, Option<&str>, Vec<u8>)]) -> TestResponse {
    let (content_type, body) = multipart(parts);
    let path = format!("/v1/models/{model}/fit");
    app.request(
        Method::POST,
        &path,
        &[("content-type", &content_type)],
        body,
    )
    .await
}

/// Fits the test ellipsoid under `name` and runs the job; returns the anchor id.
async fn fitted_anchor(app: &TestApp, model: &str, name: &str) -> i64 {
    let parts = [
        ("name", None, name.as_bytes().to_vec()),
        ("file", Some("patient.stl"), ellipsoid_stl(AXES)),
    ];
    let r = fit(app, model, &parts).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
    app.run_pending_jobs().await;
    r.json()["anchor_id"].as_i64().unwrap()
}

async fn cancel(app: &TestApp, path: &str) -> TestResponse {
    app.request(Method::POST, path, &[], "").await
}

fn text(r: &TestResponse) -> String {
    String::from_utf8_lossy(&r.body).into_owned()
}

#[tokio::test]
async fn a_fitted_mesh_becomes_a_ready_anchor_through_a_fit_job() {
    let app = spawn_app().await;
    let parts = [
        ("name", None, b"patient-7".to_vec()),
        ("iterations", None, b"25".to_vec()),
        ("seed", None, b"3".to_vec()),
        ("file", Some("patient.stl"), ellipsoid_stl(AXES)),
    ];
    let r = fit(&app, MODEL, &parts).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
    let accepted = r.json();
    let (anchor, job) = (
        accepted["anchor_id"].as_i64().unwrap(),
        accepted["job_id"].as_i64().unwrap(),
    );
    assert_eq!(
        r.header("location"),
        Some(format!("/v1/jobs/{job}").as_str())
    );
    assert_eq!(accepted["links"]["self"], format!("/v1/anchors/{anchor}"));
    let before = app.get(&format!("/v1/anchors/{anchor}")).await.json();
    assert_eq!(before["status"], "fitting");
    assert!(before["latent"].is_null() && before["chamfer"].is_null());
    let job_view = app.get(&format!("/v1/jobs/{job}")).await.json();
    assert_eq!(
        (
            job_view["kind"].as_str(),
            job_view["progress"]["total"].as_i64()
        ),
        (Some("fit"), Some(25))
    );
    assert_eq!(job_view["subject"], format!("/v1/anchors/{anchor}"));

    app.run_pending_jobs().await;
    let job_view = app.get(&format!("/v1/jobs/{job}")).await.json();
    assert_eq!(job_view["status"], "succeeded");
    assert_eq!(job_view["progress"]["done"], 25);
    let a = app.get(&format!("/v1/anchors/{anchor}")).await.json();
    assert_eq!(
        (
            a["status"].as_str(),
            a["name"].as_str(),
            a["model_id"].as_str()
        ),
        (Some("ready"), Some("patient-7"), Some(MODEL))
    );
    assert_eq!(
        (a["iterations"].as_i64(), a["seed"].as_i64()),
        (Some(25), Some(3))
    );
    assert_eq!(a["source_name"], "patient.stl");
    let latent: Vec<f64> = serde_json::from_value(a["latent"].clone()).unwrap();
    for (z, axis) in latent.iter().zip(AXES) {
        assert!((z - axis).abs() < 1e-4, "{latent:?}");
    }
    assert!(a["chamfer"].as_f64().unwrap() < 1e-9, "{}", a["chamfer"]);
    let centre: Vec<f64> = serde_json::from_value(a["transform"]["centre"].clone()).unwrap();
    for (c, o) in centre.iter().zip(CENTRE) {
        assert!((c - f64::from(o)).abs() < 1e-4, "{centre:?}");
    }
    assert!((a["transform"]["radius"].as_f64().unwrap() - 34.5).abs() < 1e-4);
    let list = app.get(&format!("/v1/models/{MODEL}/anchors")).await.json();
    assert_eq!(list.as_array().unwrap().len(), 1);
    assert_eq!(list[0]["id"], anchor);
}

#[tokio::test]
async fn a_raw_body_is_fitted_and_default_names_stay_unique() {
    let app = spawn_app().await;
    let mut names = Vec::new();
    for _ in 0..2 {
        let r = app
            .request(
                Method::POST,
                &format!("/v1/models/{MODEL}/fit?file_name=case%2012.stl&iterations=5"),
                &[("content-type", "application/octet-stream")],
                ellipsoid_stl(AXES),
            )
            .await;
        assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
        names.push(r.json()["name"].as_str().unwrap().to_owned());
    }
    assert_eq!(names, ["case_12", "case_12-2"]);
    app.run_pending_jobs().await;
    let list = app.get(&format!("/v1/models/{MODEL}/anchors")).await.json();
    assert!(
        list.as_array()
            .unwrap()
            .iter()
            .all(|a| a["status"] == "ready")
    );
}

/// One refused fit request and what the problem document must say.
struct Case {
    what: &'static str,
    model: &'static str,
    parts: Vec<(&'static str, Option<&'static str>, Vec<u8>)>,
    status: StatusCode,
    field: Option<&'static str>,
    rule: Option<&'static str>,
}

fn case(
    what: &'static str,
    parts: Vec<(&'static str, Option<&'static str>, Vec<u8>)>,
    status: StatusCode,
    field: Option<&'static str>,
    rule: Option<&'static str>,
) -> Case {
    Case {
        what,
        model: MODEL,
        parts,
        status,
        field,
        rule,
    }
}

#[tokio::test]
async fn bad_fit_requests_are_refused_naming_the_field_and_rule() {
    let app = spawn_app().await;
    let mesh = || ("file", Some("p.stl"), ellipsoid_stl(AXES));
    let unprocessable = StatusCode::UNPROCESSABLE_ENTITY;
    fitted_anchor(&app, MODEL, "taken").await;
    let cases = vec![
        Case {
            model: "no-such-model",
            ..case(
                "unknown model",
                vec![mesh()],
                StatusCode::NOT_FOUND,
                None,
                None,
            )
        },
        case(
            "no file",
            vec![("name", None, b"x".to_vec())],
            unprocessable,
            Some("file"),
            Some("count"),
        ),
        case(
            "two files",
            vec![mesh(), mesh()],
            unprocessable,
            Some("file"),
            Some("count"),
        ),
        case(
            "malformed mesh",
            vec![("file", Some("bad.ply"), b"ply\nnonsense".to_vec())],
            unprocessable,
            Some("file"),
            Some("mesh"),
        ),
        case(
            "unknown format",
            vec![("file", Some("notes.txt"), b"hello".to_vec())],
            unprocessable,
            Some("file"),
            Some("format"),
        ),
        case(
            "zero iterations",
            vec![("iterations", None, b"0".to_vec()), mesh()],
            unprocessable,
            Some("iterations"),
            Some("range"),
        ),
        case(
            "too many iterations",
            vec![("iterations", None, b"10001".to_vec()), mesh()],
            unprocessable,
            Some("iterations"),
            Some("range"),
        ),
        case(
            "iterations not a number",
            vec![("iterations", None, b"many".to_vec()), mesh()],
            unprocessable,
            Some("iterations"),
            Some("type"),
        ),
        case(
            "bad name",
            vec![("name", None, b"two words".to_vec()), mesh()],
            unprocessable,
            Some("name"),
            Some("format"),
        ),
        case(
            "unknown field",
            vec![("colour", None, b"red".to_vec()), mesh()],
            unprocessable,
            Some("colour"),
            Some("unknown-field"),
        ),
        case(
            "name taken",
            vec![("name", None, b"taken".to_vec()), mesh()],
            StatusCode::CONFLICT,
            None,
            None,
        ),
    ];
    let anchors_before = app.count("anchor").await;
    let jobs_before = app.count("job").await;
    for c in &cases {
        let r = fit(&app, c.model, &c.parts).await;
        assert_eq!(r.status, c.status, "{}: {}", c.what, text(&r));
        assert_eq!(
            r.header("content-type"),
            Some("application/problem+json"),
            "{}",
            c.what
        );
        let problem = r.json();
        assert_eq!(problem["field"].as_str(), c.field, "{}: {problem}", c.what);
        assert_eq!(problem["rule"].as_str(), c.rule, "{}: {problem}", c.what);
    }
    assert_eq!(app.count("anchor").await, anchors_before, "nothing stored");
    assert_eq!(app.count("job").await, jobs_before, "nothing queued");

    let too_big = app
        .request(
            Method::POST,
            &format!("/v1/models/{MODEL}/fit?file_name=p.stl"),
            &[("content-type", "application/octet-stream")],
            vec![0u8; MAX_UPLOAD + 1],
        )
        .await;
    assert_eq!(too_big.status, StatusCode::PAYLOAD_TOO_LARGE);
}

#[tokio::test]
async fn a_model_that_is_not_ready_cannot_be_fitted() {
    let app = spawn_app().await;
    let r = upload_two_spheres(&app, "young").await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
    let r = fit(
        &app,
        "young",
        &[("file", Some("p.stl"), ellipsoid_stl(AXES))],
    )
    .await;
    assert_eq!(r.status, StatusCode::CONFLICT, "{}", text(&r));
    assert!(r.detail().contains("training"));
}

#[tokio::test]
async fn queued_fit_and_training_jobs_are_cancelled_and_their_subjects_marked_failed() {
    let app = spawn_app().await;
    let r = fit(&app, MODEL, &[("file", Some("p.stl"), ellipsoid_stl(AXES))]).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
    let (anchor, fit_job) = (
        r.json()["anchor_id"].as_i64().unwrap(),
        r.json()["job_id"].as_i64().unwrap(),
    );
    let r = upload_two_spheres(&app, "young").await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
    let training_job = r.json()["job_id"].as_i64().unwrap();

    for job in [fit_job, training_job] {
        let r = cancel(&app, &format!("/v1/jobs/{job}/cancel")).await;
        assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
        assert_eq!(
            (
                r.json()["status"].as_str(),
                r.json()["cancel_requested"].as_bool()
            ),
            (Some("cancelled"), Some(true))
        );
    }
    // Nothing is left for a worker, and what the jobs were to produce is marked.
    assert!(app.run_pending_jobs().await.is_empty());
    let a = app.get(&format!("/v1/anchors/{anchor}")).await.json();
    assert_eq!(
        (a["status"].as_str(), a["error"].as_str()),
        (Some("failed"), Some("cancelled"))
    );
    let m = app.get("/v1/models/young").await.json();
    assert_eq!(m["status"], "failed");
    // A cancelled anchor is not fitting any more, so it can be deleted.
    let r = app
        .request(Method::DELETE, &format!("/v1/anchors/{anchor}"), &[], "")
        .await;
    assert_eq!(r.status, StatusCode::NO_CONTENT, "{}", text(&r));

    let again = cancel(&app, &format!("/v1/jobs/{fit_job}/cancel")).await;
    assert_eq!(again.status, StatusCode::CONFLICT, "{}", text(&again));
    assert!(again.detail().contains("cancelled"));
    for unknown in ["/v1/jobs/999/cancel", "/v1/jobs/abc/cancel"] {
        let r = cancel(&app, unknown).await;
        assert_eq!(r.status, StatusCode::NOT_FOUND, "{unknown}: {}", text(&r));
    }
}

#[tokio::test]
async fn an_anchor_is_deleted_unless_it_is_fitting_or_used_by_a_cohort() {
    let app = spawn_app().await;
    let r = fit(&app, MODEL, &[("file", Some("p.stl"), ellipsoid_stl(AXES))]).await;
    let anchor = r.json()["anchor_id"].as_i64().unwrap();
    let path = format!("/v1/anchors/{anchor}");
    assert_eq!(
        app.request(Method::DELETE, &path, &[], "").await.status,
        StatusCode::CONFLICT,
        "still fitting"
    );
    app.run_pending_jobs().await;
    let mut body = cohort_with_anchors(&[anchor]);
    body["count"] = json!(1);
    let cohort = app.create_cohort_ok(&body).await;
    let refused = app.request(Method::DELETE, &path, &[], "").await;
    assert_eq!(refused.status, StatusCode::CONFLICT);
    assert!(text(&refused).contains("cohort"));
    app.run_pending_jobs().await;
    app.request(Method::DELETE, &format!("/v1/cohorts/{cohort}"), &[], "")
        .await;
    assert_eq!(
        app.request(Method::DELETE, &path, &[], "").await.status,
        StatusCode::NO_CONTENT
    );
    assert_eq!(app.get(&path).await.status, StatusCode::NOT_FOUND);
    assert_eq!(
        app.get("/v1/anchors/nope").await.status,
        StatusCode::NOT_FOUND
    );
}

#[tokio::test]
async fn an_archive_of_several_files_is_refused_before_it_is_decompressed() {
    use crate::helpers::MAX_ARCHIVE_BYTES;
    let app = spawn_app().await;
    // Its second member alone expands past the bound: only counting first answers 422.
    let archive = crate::models::zip_of(&[
        ("a.stl", ellipsoid_stl(AXES)),
        ("b.obj", vec![b' '; MAX_ARCHIVE_BYTES + 1]),
    ]);
    let r = fit(&app, MODEL, &[("file", Some("two.zip"), archive)]).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY, "{}", text(&r));
    let p = r.json();
    assert_eq!(
        (p["field"].as_str(), p["rule"].as_str()),
        (Some("file"), Some("count"))
    );
    assert!(
        p["detail"].as_str().unwrap().contains("got 2 in two.zip"),
        "{p}"
    );

    let one = crate::models::zip_of(&[("a.stl", ellipsoid_stl(AXES))]);
    let r = fit(&app, MODEL, &[("file", Some("one.zip"), one)]).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
}

#[tokio::test]
async fn a_deleted_anchors_id_is_not_given_again() {
    let app = spawn_app().await;
    let r = fit(&app, MODEL, &[("file", Some("p.stl"), ellipsoid_stl(AXES))]).await;
    let anchor = r.json()["anchor_id"].as_i64().unwrap();
    app.run_pending_jobs().await;
    let path = format!("/v1/anchors/{anchor}");
    assert_eq!(
        app.request(Method::DELETE, &path, &[], "").await.status,
        StatusCode::NO_CONTENT
    );
    let again = fit(&app, MODEL, &[("file", Some("p.stl"), ellipsoid_stl(AXES))]).await;
    assert_eq!(again.status, StatusCode::ACCEPTED);
    let next = again.json()["anchor_id"].as_i64().unwrap();
    assert!(next > anchor, "anchor {next} after {anchor}");
    assert_eq!(app.get(&path).await.status, StatusCode::NOT_FOUND);
}

fn cohort_with_anchors(anchors: &[i64]) -> Value {
    json!({
        "model_id": MODEL, "count": 3, "arity": 2, "seed": 7, "resolution": 64,
        "weights": [0.5, 0.5], "anchors": anchors,
    })
}

#[tokio::test]
async fn a_cohort_mixes_its_forced_anchor_into_every_shape_and_records_it() {
    let app = spawn_app().await;
    let anchor = fitted_anchor(&app, MODEL, "patient").await;
    let id = app.create_cohort_ok(&cohort_with_anchors(&[anchor])).await;
    let view = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(view["anchors"], json!([anchor]));
    app.run_pending_jobs().await;
    let shapes = app.get(&format!("/v1/cohorts/{id}/shapes")).await.json();
    let shapes = shapes["items"]
        .as_array()
        .or(shapes.as_array())
        .unwrap()
        .clone();
    assert_eq!(shapes.len(), 3);
    for s in &shapes {
        let p = &s["provenance"];
        assert_eq!(p["anchor_ids"], json!([anchor]), "{p}");
        let training: Vec<usize> = serde_json::from_value(p["training_indices"].clone()).unwrap();
        assert_eq!(
            training.len(),
            1,
            "arity 2 = one training shape + the anchor"
        );
        assert_eq!(p["weights"], json!([0.5, 0.5]));
        // The generated ellipsoid's semi-axes are the weighted training and anchor axes.
        let mut axes = mixed_axes(&training, &[0.5]);
        for (a, z) in axes.iter_mut().zip(AXES) {
            *a += 0.5 * z;
        }
        let radius = axes.iter().cloned().fold(0.0, f64::max);
        let volume = ellipsoid_unit(axes, radius).signed_volume() * radius.powi(3);
        let stored = s["volume_mm3"].as_f64().unwrap();
        assert!(
            (stored - volume).abs() < 1e-6 * volume,
            "{stored} vs {volume}"
        );
    }
    // Without anchors the same request draws other shapes, and the fingerprint differs.
    let key = [
        ("content-type", "application/json"),
        ("idempotency-key", "k-1"),
    ];
    let with = cohort_with_anchors(&[anchor]);
    let r = app
        .request(Method::POST, "/v1/cohorts", &key, with.to_string())
        .await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
    let mut without = with.clone();
    without.as_object_mut().unwrap().remove("anchors");
    let r = app
        .request(Method::POST, "/v1/cohorts", &key, without.to_string())
        .await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY, "{}", text(&r));
    assert_eq!(r.json()["rule"], "reused-key");
}

#[tokio::test]
async fn cohort_anchors_must_be_ready_distinct_and_of_the_same_model() {
    let app = spawn_app().await;
    let ready = fitted_anchor(&app, MODEL, "ready").await;
    let second = fitted_anchor(&app, MODEL, "second").await;
    // A second model with an anchor of its own.
    let r = upload_two_spheres(&app, "other").await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
    app.run_pending_jobs().await;
    let foreign = fitted_anchor(&app, "other", "foreign").await;
    let r = fit(
        &app,
        MODEL,
        &[("file", Some("pending.stl"), ellipsoid_stl(AXES))],
    )
    .await;
    let not_ready = r.json()["anchor_id"].as_i64().unwrap();
    let cases: Vec<(Value, &str, &str)> = vec![
        (json!([]), "anchors", "length"),
        (json!([ready, second, foreign]), "anchors", "length"),
        (json!([ready, ready]), "anchors[1]", "distinct"),
        (json!([987_654]), "anchors[0]", "exists"),
        (json!([foreign]), "anchors[0]", "same-model"),
        (json!([ready, not_ready]), "anchors[1]", "ready"),
    ];
    for (anchors, field, rule) in cases {
        let mut body = cohort_with_anchors(&[]);
        body["anchors"] = anchors.clone();
        let r = app.create_cohort(&body).await;
        assert_eq!(
            r.status,
            StatusCode::UNPROCESSABLE_ENTITY,
            "{anchors}: {}",
            text(&r)
        );
        let p = r.json();
        assert_eq!(
            (p["field"].as_str(), p["rule"].as_str()),
            (Some(field), Some(rule)),
            "{anchors}: {p}"
        );
    }
}

/// A database made by the previous schema, with a finished cohort job, is upgraded in place:
/// rows and their links survive the job table's rebuild, foreign keys are enforced again
/// and the new job kind is accepted.
#[tokio::test]
async fn the_fit_migration_upgrades_a_populated_database() {
    use std::str::FromStr;
    let dir = tempfile::tempdir().unwrap();
    let older = dir.path().join("older-migrations");
    std::fs::create_dir(&older).unwrap();
    let all = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("migrations/sqlite");
    for entry in std::fs::read_dir(&all).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if name.as_str() < "20261129000400" {
            std::fs::copy(&path, older.join(&name)).unwrap();
        }
    }
    let url = format!("sqlite://{}", dir.path().join("old.db").display());
    let options = sqlx::sqlite::SqliteConnectOptions::from_str(&url)
        .unwrap()
        .create_if_missing(true)
        .foreign_keys(true);
    let pool = sqlx::SqlitePool::connect_with(options).await.unwrap();
    let migrator = sqlx::migrate::Migrator::new(older.as_path()).await.unwrap();
    migrator.run(&pool).await.unwrap();
    for sql in [
        "insert into model (model_id, dir_path, manifest) values ('m', 'd', '{}')",
        "insert into job (kind, payload, status, progress_done, progress_total, claim_progress,
             stalled_attempts) values ('cohort', '{\"cohort_id\": 1}', 'succeeded', 3, 3, 2, 1)",
        "insert into cohort (model_id, job_id, count, arity, weighting, seed, resolution,
             request_hash) values ('m', 1, 3, 2, 'equal', 1, 64, 'h')",
    ] {
        sqlx::query(sql).execute(&pool).await.unwrap();
    }
    pool.close().await;

    let pool = aortagen::db::connect(&url, 2).await.unwrap();
    let job: (String, String, i64) =
        sqlx::query_as("select kind, status, progress_done from job where job_id = 1")
            .fetch_one(&pool)
            .await
            .unwrap();
    assert_eq!(job, ("cohort".into(), "succeeded".into(), 3));
    let cohort_job: i64 = sqlx::query_scalar("select job_id from cohort where cohort_id = 1")
        .fetch_one(&pool)
        .await
        .unwrap();
    assert_eq!(cohort_job, 1);
    let orphan = sqlx::query("delete from job where job_id = 1")
        .execute(&pool)
        .await;
    assert!(orphan.is_err(), "the cohort's foreign key still holds");
    sqlx::query("insert into job (kind, payload) values ('fit', '{}')")
        .execute(&pool)
        .await
        .unwrap();
    let bogus = sqlx::query("insert into job (kind, payload) values ('bogus', '{}')")
        .execute(&pool)
        .await;
    assert!(bogus.is_err(), "the kind check still holds");
    let index: i64 = sqlx::query_scalar(
        "select count(*) from sqlite_master where type = 'index' and name = 'job_status_idx'",
    )
    .fetch_one(&pool)
    .await
    .unwrap();
    assert_eq!(index, 1);
}

#[tokio::test]
async fn a_training_cancelled_while_its_worker_died_leaves_its_model_failed_and_deletable() {
    let app = spawn_app().await;
    let r = upload_two_spheres(&app, "young").await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
    let job = r.json()["job_id"].as_i64().unwrap();
    // A worker of another process claims the training, then dies with it.
    let owner = "elsewhere/1/1/0";
    let lease = aortagen::db::tasks::claim(&app.state.pool, owner, "token", 60_000)
        .await
        .unwrap()
        .expect("the training task is claimable");
    assert_eq!(lease.job_id, job);
    let mut conn = app.state.pool.acquire().await.unwrap();
    aortagen::db::jobs::start(&mut conn, job).await.unwrap();
    drop(conn);
    let r = cancel(&app, &format!("/v1/jobs/{job}/cancel")).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", text(&r));
    let m = app.get("/v1/models/young").await.json();
    assert_eq!(m["status"], "training", "still running elsewhere: {m}");

    // Its lease runs out; the next worker's housekeeping ends the job and the model.
    aortagen::db::tasks::expire_owner(&app.state.pool, owner)
        .await
        .unwrap();
    app.run_pending_jobs().await;
    let j = app.get(&format!("/v1/jobs/{job}")).await.json();
    assert_eq!(j["status"], "cancelled", "{j}");
    let m = app.get("/v1/models/young").await.json();
    assert_eq!(m["status"], "failed", "{m}");
    let r = app
        .request(Method::DELETE, "/v1/models/young", &[], "")
        .await;
    assert_eq!(r.status, StatusCode::NO_CONTENT, "{}", text(&r));
}
