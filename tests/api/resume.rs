//! Resuming work: a failed or cancelled cohort retried keeps its shapes and completes the
//! rest exactly as an uninterrupted run would; the setup a cohort needs (the novelty
//! reference's training surfaces) is stored once and survives restarts, and storing it
//! counts as progress when a restart looks for stalled jobs.

use std::sync::atomic::Ordering;

use axum::http::{Method, StatusCode};
use serde_json::{Value, json};

use crate::engine::{AnalyticEngine, TRAINING_SHAPES};
use crate::helpers::{TestApp, cohort_body, spawn_app, spawn_app_with, spawn_on};
use crate::jobs::wait_for_calls;

async fn retry(app: &TestApp, cohort: i64) -> crate::helpers::TestResponse {
    let path = format!("/v1/cohorts/{cohort}/retry");
    app.request(Method::POST, &path, &[], "").await
}

/// (index, mesh digest, novelty) of every stored shape, in index order.
async fn shapes_of(app: &TestApp, cohort: i64) -> Vec<(i64, String, Option<f64>)> {
    sqlx::query_as(
        "select shape_index, mesh_sha256, novelty_cd from shape where cohort_id = $1
         order by shape_index",
    )
    .bind(cohort)
    .fetch_all(&app.state.pool)
    .await
    .unwrap()
}

async fn cohort(app: &TestApp, id: i64) -> Value {
    app.get(&format!("/v1/cohorts/{id}")).await.json()
}

#[tokio::test]
async fn a_retried_cancelled_cohort_ends_with_the_shapes_of_an_uninterrupted_run() {
    let app = spawn_app_with(AnalyticEngine {
        hold_from_call: Some(2),
        ..Default::default()
    })
    .await;
    let body = cohort_body(5, 2);
    let id = app.create_cohort_ok(&body).await;
    let run = app.spawn_pending_jobs();
    wait_for_calls(&app, 3).await;
    let cancel = format!("/v1/cohorts/{id}/cancel");
    assert_eq!(
        app.request(Method::POST, &cancel, &[], "").await.status,
        StatusCode::ACCEPTED
    );
    run.await.unwrap();
    assert_eq!(cohort(&app, id).await["status"], "cancelled");
    let kept = shapes_of(&app, id).await;
    assert_eq!(kept.len(), 2);

    let r = retry(&app, id).await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.json());
    assert_eq!(r.json()["status"], "queued");
    assert!(r.json()["error"].is_null());
    app.engine.release.store(true, Ordering::SeqCst);
    app.run_pending_jobs().await;
    let resumed = cohort(&app, id).await;
    assert_eq!(resumed["status"], "succeeded");
    assert_eq!(resumed["progress"], json!({ "done": 5, "total": 5 }));
    let retried = shapes_of(&app, id).await;
    assert_eq!(
        retried[..2],
        kept[..],
        "the stored shapes stay as they were"
    );
    assert_eq!(
        app.get(&format!("/v1/cohorts/{id}/metrics")).await.status,
        StatusCode::OK
    );

    let uninterrupted = app.create_cohort_ok(&body).await;
    app.run_pending_jobs().await;
    assert_eq!(retried, shapes_of(&app, uninterrupted).await);
}

#[tokio::test]
async fn a_failed_cohort_is_retried_and_completes() {
    let app = spawn_app_with(AnalyticEngine {
        panic_on_call: Some(1),
        ..Default::default()
    })
    .await;
    let id = app.create_cohort_ok(&cohort_body(3, 2)).await;
    app.run_pending_jobs().await;
    let failed = cohort(&app, id).await;
    assert_eq!(failed["status"], "failed");
    assert!(failed["error"].is_string());
    let r = retry(&app, id).await;
    assert_eq!(r.status, StatusCode::ACCEPTED);
    app.run_pending_jobs().await;
    let done = cohort(&app, id).await;
    assert_eq!(done["status"], "succeeded");
    assert!(done["error"].is_null());
    assert_eq!(shapes_of(&app, id).await.len(), 3);
    let job = app
        .get(&format!("/v1/jobs/{}", done["job_id"]))
        .await
        .json();
    assert_eq!(job["attempts"], 1, "a retry starts the attempts again");
}

#[tokio::test]
async fn only_failed_or_cancelled_cohorts_can_be_retried() {
    let app = spawn_app_with(AnalyticEngine {
        hold_from_call: Some(2),
        ..Default::default()
    })
    .await;
    let running = app.create_cohort_ok(&cohort_body(4, 2)).await;
    let queued = app.create_cohort_ok(&cohort_body(2, 2)).await;
    let run = app.spawn_pending_jobs();
    wait_for_calls(&app, 3).await;
    for (id, state) in [(running, "running"), (queued, "queued")] {
        let r = retry(&app, id).await;
        assert_eq!(r.status, StatusCode::CONFLICT, "{id}");
        assert_eq!(r.header("content-type"), Some("application/problem+json"));
        let detail = r.detail();
        assert!(detail.contains(state), "{detail}");
    }
    app.engine.release.store(true, Ordering::SeqCst);
    run.await.unwrap();
    app.run_pending_jobs().await;
    let r = retry(&app, running).await;
    assert_eq!(r.status, StatusCode::CONFLICT);
    assert!(r.detail().contains("succeeded"));
    assert_eq!(cohort(&app, running).await["status"], "succeeded");
    assert_eq!(retry(&app, 999).await.status, StatusCode::NOT_FOUND);
}

#[tokio::test]
async fn a_retry_waits_for_room_in_the_queue() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(2, 2)).await;
    let cancel = format!("/v1/cohorts/{id}/cancel");
    app.request(Method::POST, &cancel, &[], "").await;
    for _ in 0..crate::helpers::MAX_QUEUE {
        app.create_cohort_ok(&cohort_body(2, 2)).await;
    }
    let r = retry(&app, id).await;
    assert_eq!(r.status, StatusCode::TOO_MANY_REQUESTS);
    assert_eq!(cohort(&app, id).await["status"], "cancelled");
}

#[tokio::test]
async fn the_novelty_surfaces_are_stored_once_and_reused_after_a_restart() {
    let first = spawn_app().await;
    let a = first.create_cohort_ok(&cohort_body(2, 2)).await;
    first.run_pending_jobs().await;
    assert_eq!(
        first.engine.surfaces_built.load(Ordering::SeqCst),
        TRAINING_SHAPES
    );
    assert_eq!(first.count("novelty_surface").await, TRAINING_SHAPES as i64);
    let setup: i64 = sqlx::query_scalar(
        "select setup_done from job where job_id = (select job_id from cohort where cohort_id = $1)",
    )
    .bind(a)
    .fetch_one(&first.state.pool)
    .await
    .unwrap();
    assert_eq!(setup, TRAINING_SHAPES as i64);

    let second = spawn_on(
        AnalyticEngine::default(),
        first.dir.clone(),
        first.database_url.clone(),
    )
    .await;
    let b = second.create_cohort_ok(&cohort_body(2, 2)).await;
    second.run_pending_jobs().await;
    assert_eq!(cohort(&second, b).await["status"], "succeeded");
    assert_eq!(
        second.engine.surfaces_built.load(Ordering::SeqCst),
        0,
        "the stored surfaces are read back, not recomputed"
    );
    assert_eq!(shapes_of(&second, b).await, shapes_of(&second, a).await);

    // Another resolution needs its own surfaces.
    let mut finer = cohort_body(1, 2);
    finer["resolution"] = json!(96);
    second.create_cohort_ok(&finer).await;
    second.run_pending_jobs().await;
    assert_eq!(
        second.engine.surfaces_built.load(Ordering::SeqCst),
        TRAINING_SHAPES
    );
}
