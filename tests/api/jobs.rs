//! Job state, cancellation of running work, restarts, panics and shutdown.

use std::sync::atomic::Ordering;
use std::time::Duration;

use aortagen::jobs::{ExecutionOutcome, RunOutcome, try_execute_job, worker};
use axum::http::{Method, StatusCode};
use serde_json::json;

use crate::engine::AnalyticEngine;
use crate::helpers::{TestApp, cohort_body, spawn_app, spawn_app_with, spawn_on};

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

fn spawn_one_job(app: &TestApp) -> tokio::task::JoinHandle<anyhow::Result<ExecutionOutcome>> {
    let ctx = app.state.jobs.clone();
    tokio::spawn(async move { try_execute_job(&ctx).await })
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
    let run = spawn_one_job(&app);
    wait_for_calls(&app, 3).await;
    assert_eq!(
        app.get(&format!("/v1/cohorts/{id}")).await.json()["status"],
        "running"
    );

    let r = app
        .request(Method::POST, &format!("/v1/cohorts/{id}/cancel"), &[], "")
        .await;
    assert_eq!(r.status, StatusCode::ACCEPTED);
    let outcome = run.await.unwrap().unwrap();
    assert!(matches!(
        outcome,
        ExecutionOutcome::TaskCompleted {
            outcome: RunOutcome::Cancelled,
            ..
        }
    ));
    let c = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(c["status"], "cancelled");
    assert_eq!(c["progress"], json!({ "done": 2, "total": 5 }));
    assert_eq!(app.count("shape").await, 2);
    assert_eq!(
        app.engine.calls.load(Ordering::SeqCst),
        3,
        "no shape started after the cancel"
    );
}

#[tokio::test]
async fn a_restart_resumes_an_interrupted_cohort_without_losing_or_duplicating_shapes() {
    let first = spawn_app_with(AnalyticEngine {
        hold_from_call: Some(2),
        ..Default::default()
    })
    .await;
    let id = first.create_cohort_ok(&cohort_body(5, 2)).await;
    let run = spawn_one_job(&first);
    wait_for_calls(&first, 3).await;
    // The process "dies": the job future is dropped mid-shape, nothing more is written.
    run.abort();
    assert!(run.await.unwrap_err().is_cancelled());
    first.engine.release.store(true, Ordering::SeqCst);
    assert_eq!(first.count("shape").await, 2);

    let second = spawn_on(
        AnalyticEngine::default(),
        first.dir.clone(),
        first.database_url.clone(),
    )
    .await;
    let outcomes = second.run_pending_jobs().await;
    assert!(matches!(
        &outcomes[..],
        [ExecutionOutcome::TaskCompleted {
            outcome: RunOutcome::Succeeded,
            ..
        }]
    ));
    let indices: Vec<i64> =
        sqlx::query_scalar("select shape_index from shape where cohort_id = ? order by 1")
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
    assert_eq!(
        (job["status"].as_str(), job["attempts"].as_i64()),
        (Some("succeeded"), Some(2))
    );
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
    for _ in 0..5000 {
        if app.get(&format!("/v1/cohorts/{fine}")).await.json()["status"] == "succeeded" {
            break;
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
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
    let run = spawn_one_job(&app);
    wait_for_calls(&app, 2).await;
    app.state.jobs.controls.shut_down();
    let outcome = run.await.unwrap().unwrap();
    assert!(matches!(
        outcome,
        ExecutionOutcome::TaskCompleted {
            outcome: RunOutcome::Released,
            ..
        }
    ));
    assert_eq!(job_of(&app, id).await["status"], "queued");
    assert_eq!(app.count("shape").await, 1);
}

/// Recovery after a killed process: interruptions that committed progress never fail a job;
/// `max_attempts` interruptions in a row without progress do.
#[tokio::test]
async fn only_interruptions_without_progress_count_towards_failing_a_job() {
    use aortagen::db::jobs;
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(20, 2)).await;
    let job_id = job_of(&app, id).await["id"].as_i64().unwrap();
    let pool = &app.state.pool;
    let status = async || {
        job_of(&app, id).await["status"]
            .as_str()
            .unwrap()
            .to_owned()
    };
    // Eight kills, each after one more shape: far more than max_attempts = 2.
    for done in 1..=8 {
        let claimed = jobs::claim_next(pool)
            .await
            .unwrap()
            .expect("the job is queued");
        assert_eq!(claimed.job_id, job_id);
        let mut conn = pool.acquire().await.unwrap();
        jobs::set_progress(&mut conn, job_id, done).await.unwrap();
        drop(conn);
        assert_eq!(jobs::requeue_interrupted(pool, 2).await.unwrap(), (1, 0));
        assert_eq!(status().await, "queued");
    }
    // Two kills in a row with nothing committed: the job is given up.
    jobs::claim_next(pool).await.unwrap().expect("queued");
    assert_eq!(jobs::requeue_interrupted(pool, 2).await.unwrap(), (1, 0));
    jobs::claim_next(pool).await.unwrap().expect("queued");
    assert_eq!(jobs::requeue_interrupted(pool, 2).await.unwrap(), (0, 1));
    let job = job_of(&app, id).await;
    assert_eq!(job["status"], "failed");
    assert!(
        job["error"]
            .as_str()
            .unwrap()
            .contains("2 times in a row without progress"),
        "{job}"
    );
}
