//! Job state, cancellation of running work, restarts, panics and shutdown.

use std::sync::atomic::Ordering;
use std::time::Duration;

use aortagen::jobs::{ExecutionOutcome, RunOutcome, worker};
use axum::http::{Method, StatusCode};
use serde_json::json;

use crate::engine::AnalyticEngine;
use crate::helpers::{
    TestApp, cohort_body, fresh_database_url, spawn_app, spawn_app_with, spawn_on_configured,
};

/// Waits until the engine has been called `n` times (a held call is then in progress).
pub async fn wait_for_calls(app: &TestApp, n: usize) {
    for _ in 0..5000 {
        if app.engine.calls.load(Ordering::SeqCst) >= n {
            return;
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    panic!("the engine was never called {n} times");
}

/// A worker of the service's process running until the returned sender says stop.
pub fn spawn_worker(
    app: &TestApp,
) -> (
    tokio::task::JoinHandle<()>,
    tokio::sync::watch::Sender<bool>,
) {
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let worker = tokio::spawn(worker::run_worker_until_stopped(
        0,
        app.state.jobs.clone(),
        app.state.queue.waker(),
        stop_rx,
    ));
    (worker, stop_tx)
}

/// Polls a cohort until its status is `want` (or fails after a few seconds).
pub async fn wait_for_status(app: &TestApp, cohort: i64, want: &str) {
    app.poll_json(&format!("/v1/cohorts/{cohort}"), |c| c["status"] == want)
        .await;
}

async fn job_of(app: &TestApp, cohort: i64) -> serde_json::Value {
    let c = app.get(&format!("/v1/cohorts/{cohort}")).await.json();
    app.get(&format!("/v1/jobs/{}", c["job_id"])).await.json()
}

#[tokio::test]
async fn a_job_reports_kind_state_progress_and_timings() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(2, 2)).await;
    let queued = job_of(&app, id).await;
    assert_eq!(
        (queued["kind"].as_str(), queued["status"].as_str()),
        (Some("cohort"), Some("queued"))
    );
    assert!(queued["started_at"].is_null());
    app.run_pending_jobs().await;
    let done = job_of(&app, id).await;
    assert_eq!(done["status"], "succeeded");
    assert_eq!(done["progress"], json!({ "done": 2, "total": 2 }));
    assert_eq!(done["attempts"], 1);
    assert!(done["started_at"].is_string() && done["finished_at"].is_string());
    assert_eq!(done["subject"], format!("/v1/cohorts/{id}"));
    assert!(done["error"].is_null());
}

#[tokio::test]
async fn cancelling_a_running_cohort_stops_it_and_keeps_finished_shapes() {
    let app = spawn_app_with(AnalyticEngine {
        hold_from_call: Some(2),
        ..Default::default()
    })
    .await;
    let id = app.create_cohort_ok(&cohort_body(5, 2)).await;
    let (worker, stop) = spawn_worker(&app);
    wait_for_calls(&app, 3).await;
    assert_eq!(
        app.get(&format!("/v1/cohorts/{id}")).await.json()["status"],
        "running"
    );

    let r = app
        .request(Method::POST, &format!("/v1/cohorts/{id}/cancel"), &[], "")
        .await;
    assert_eq!(r.status, StatusCode::ACCEPTED);
    wait_for_status(&app, id, "cancelled").await;
    let c = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(c["progress"], json!({ "done": 2, "total": 5 }));
    assert_eq!(app.count("shape").await, 2);
    stop.send(true).unwrap();
    worker.await.unwrap();
    assert_eq!(
        app.engine.calls.load(Ordering::SeqCst),
        3,
        "no shape started after the cancel"
    );
}

#[tokio::test]
async fn a_restart_resumes_an_interrupted_cohort_without_losing_or_duplicating_shapes() {
    let dir = std::sync::Arc::new(tempfile::tempdir().unwrap());
    let url = fresh_database_url(dir.path()).await;
    let one_second_leases = |c: &mut aortagen::config::Config| c.work.lease_secs = 1;
    let engine = AnalyticEngine {
        hold_from_call: Some(2),
        ..Default::default()
    };
    let first = spawn_on_configured(engine, dir.clone(), url.clone(), one_second_leases).await;
    let id = first.create_cohort_ok(&cohort_body(5, 2)).await;
    let (worker, _stop) = spawn_worker(&first);
    wait_for_calls(&first, 3).await;
    // The process "dies": its worker is dropped mid-shape, nothing more is written and its
    // lease is no longer renewed.
    worker.abort();
    assert!(worker.await.unwrap_err().is_cancelled());
    first.engine.release.store(true, Ordering::SeqCst);
    assert_eq!(first.count("shape").await, 2);

    let second = spawn_on_configured(AnalyticEngine::default(), dir, url, one_second_leases).await;
    // The dead worker's lease runs out on the database's clock, then the task is taken over.
    tokio::time::sleep(Duration::from_millis(1100)).await;
    let outcomes = second.run_pending_jobs().await;
    assert!(
        outcomes.iter().all(|o| matches!(
            o,
            ExecutionOutcome::TaskCompleted {
                outcome: RunOutcome::Succeeded,
                ..
            }
        )),
        "{outcomes:?}"
    );
    let indices: Vec<i64> =
        sqlx::query_scalar("select shape_index from shape where cohort_id = $1 order by 1")
            .bind(id)
            .fetch_all(&second.state.pool)
            .await
            .unwrap();
    assert_eq!(indices, vec![0, 1, 2, 3, 4]);
    assert_eq!(
        second.engine.calls.load(Ordering::SeqCst),
        3,
        "only the missing shapes are generated"
    );
    let job = job_of(&second, id).await;
    assert_eq!(job["status"], "succeeded");
    let (attempts, stalls): (i64, i64) = sqlx::query_as(
        "select attempts, stalled_attempts from task where kind = 'shape' and item = 2",
    )
    .fetch_one(&second.state.pool)
    .await
    .unwrap();
    assert_eq!((attempts, stalls), (2, 1), "taken over once");
}

#[tokio::test]
async fn an_engine_panic_fails_the_job_and_the_worker_keeps_going() {
    let app = spawn_app_with(AnalyticEngine {
        panic_on_call: Some(1),
        ..Default::default()
    })
    .await;
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let worker = tokio::spawn(worker::run_worker_until_stopped(
        0,
        app.state.jobs.clone(),
        app.state.queue.waker(),
        stop_rx,
    ));
    let broken = app.create_cohort_ok(&cohort_body(3, 2)).await;
    let fine = app.create_cohort_ok(&cohort_body(2, 2)).await;
    wait_for_status(&app, fine, "succeeded").await;
    let failed = job_of(&app, broken).await;
    assert_eq!(failed["status"], "failed");
    let error = failed["error"].as_str().unwrap();
    assert!(
        error.contains("shape 1") && error.contains("panicked"),
        "{error}"
    );
    assert_eq!(
        app.get(&format!("/v1/cohorts/{fine}")).await.json()["status"],
        "succeeded"
    );
    assert_eq!(
        app.get(&format!("/v1/cohorts/{broken}")).await.json()["progress"]["done"],
        1
    );
    stop_tx.send(true).unwrap();
    worker.await.unwrap();
}

#[tokio::test]
async fn shutdown_puts_a_running_job_back_in_the_queue_with_its_shapes() {
    let app = spawn_app_with(AnalyticEngine {
        hold_from_call: Some(1),
        ..Default::default()
    })
    .await;
    let id = app.create_cohort_ok(&cohort_body(3, 2)).await;
    let (worker, stop) = spawn_worker(&app);
    wait_for_calls(&app, 2).await;
    app.state.jobs.controls.shut_down();
    wait_for_status(&app, id, "queued").await;
    assert_eq!(app.count("shape").await, 1);
    let held: Vec<(String, String)> =
        sqlx::query_as("select kind, status from task where status <> 'done' order by task_id")
            .fetch_all(&app.state.pool)
            .await
            .unwrap();
    assert!(
        held.iter()
            .all(|(kind, status)| kind == "shape" && status == "queued"),
        "{held:?}"
    );
    stop.send(true).unwrap();
    worker.await.unwrap();
}
