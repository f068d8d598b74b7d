//! Storage faults: a database that refuses writes makes writing requests 503 and the
//! service not ready, while reads keep working, nothing stored changes, jobs wait instead
//! of failing, and everything resumes when the fault clears, without a restart.
//!
//! These run on SQLite on every pass. The fault injected is the service's `ReadOnlySwitch`: every pooled connection is set to
//! `PRAGMA query_only`, so each write fails with SQLITE_READONLY (primary code 8), the
//! result SQLite gives when the database file or its file system is read-only. Removing
//! write permission from the file is no test: the tests run as root (permissions do not
//! apply), and connections opened before a `chmod` keep writing through their open file
//! descriptors anyway. A full disk (SQLITE_FULL) takes the same path through the same
//! classification and is not reproduced here.

use std::sync::atomic::Ordering;
use std::time::Duration;

use aortagen::jobs::{ExecutionOutcome, RunOutcome, try_execute_job};
use axum::http::StatusCode;
use serde_json::json;

use crate::engine::AnalyticEngine;
use crate::helpers::{cohort_body, spawn_sqlite_app_with};
use crate::jobs::wait_for_calls;

#[tokio::test]
async fn a_read_only_database_refuses_writes_keeps_reads_and_recovers() {
    let app = spawn_sqlite_app_with(AnalyticEngine::default()).await;
    let id = app.create_cohort_ok(&cohort_body(2, 2)).await;
    app.run_pending_jobs().await;
    let shapes_before = app.get(&format!("/v1/cohorts/{id}/shapes")).await;
    assert_eq!(shapes_before.status, StatusCode::OK);
    let first_shape = shapes_before.json()["items"][0]["id"].as_i64().unwrap();
    let mesh_before = app.get(&format!("/v1/shapes/{first_shape}/mesh")).await;
    assert_eq!(app.get("/readyz").await.status, StatusCode::OK);

    app.state.read_only_switch.set(true);
    let refused = app.create_cohort(&cohort_body(1, 2)).await;
    assert_eq!(refused.status, StatusCode::SERVICE_UNAVAILABLE);
    assert_eq!(
        refused.header("content-type"),
        Some("application/problem+json")
    );
    assert_eq!(
        refused.json()["detail"],
        "storage unavailable: database is read-only"
    );
    let delete = app
        .request(
            axum::http::Method::DELETE,
            &format!("/v1/cohorts/{id}"),
            &[],
            "",
        )
        .await;
    assert_eq!(delete.status, StatusCode::SERVICE_UNAVAILABLE);
    let ready = app.get("/readyz").await;
    assert_eq!(ready.status, StatusCode::SERVICE_UNAVAILABLE);
    let detail = ready.detail();
    assert!(detail.contains("read-only"), "{detail}");
    assert_eq!(
        app.get(&format!("/v1/cohorts/{id}")).await.status,
        StatusCode::OK
    );
    let mesh_during = app.get(&format!("/v1/shapes/{first_shape}/mesh")).await;
    assert_eq!(mesh_during.status, StatusCode::OK);
    assert_eq!(mesh_during.body, mesh_before.body);

    app.state.read_only_switch.set(false);
    assert_eq!(app.get("/readyz").await.status, StatusCode::OK);
    let second = app.create_cohort_ok(&cohort_body(1, 2)).await;
    app.run_pending_jobs().await;
    assert_eq!(
        app.get(&format!("/v1/cohorts/{second}")).await.json()["status"],
        "succeeded"
    );
    assert_eq!(
        app.count("cohort").await,
        2,
        "the refused POST stored nothing"
    );
    let shapes_after = app.get(&format!("/v1/cohorts/{id}/shapes")).await;
    assert_eq!(shapes_after.body, shapes_before.body);
    let mesh_after = app.get(&format!("/v1/shapes/{first_shape}/mesh")).await;
    assert_eq!(mesh_after.body, mesh_before.body);
    let integrity: String = sqlx::query_scalar("pragma integrity_check")
        .fetch_one(&app.state.pool)
        .await
        .unwrap();
    assert_eq!(integrity, "ok");
}

#[tokio::test]
async fn a_job_hitting_a_storage_fault_goes_back_to_the_queue_and_finishes_later() {
    let app = spawn_sqlite_app_with(AnalyticEngine {
        hold_from_call: Some(1),
        ..Default::default()
    })
    .await;
    let id = app.create_cohort_ok(&cohort_body(3, 2)).await;
    let ctx = app.state.jobs.clone();
    // Tasks run one after another until one ends on the storage fault.
    let run = tokio::spawn(async move {
        loop {
            let outcome = try_execute_job(&ctx).await?;
            if matches!(
                outcome,
                ExecutionOutcome::EmptyQueue
                    | ExecutionOutcome::TaskCompleted {
                        outcome: RunOutcome::StorageFault(_),
                        ..
                    }
            ) {
                return anyhow::Ok(outcome);
            }
        }
    });
    wait_for_calls(&app, 2).await;

    // Shape 0 is stored; shape 1 is being generated when storage turns read-only. Storage
    // stays read-only until shape 1 has left the engine and had ample time to reach its
    // write, however slowly the machine runs.
    app.state.read_only_switch.set(true);
    app.engine.release.store(true, Ordering::SeqCst);
    for _ in 0..15_000 {
        if app.engine.returned.load(Ordering::SeqCst) >= 2 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    assert_eq!(
        app.engine.returned.load(Ordering::SeqCst),
        2,
        "shape 1 was never generated"
    );
    tokio::time::sleep(Duration::from_millis(2_000)).await;
    assert!(!run.is_finished(), "the worker waits for storage");
    let during = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(during["status"], "running", "not failed: {during}");

    app.state.read_only_switch.set(false);
    let outcome = tokio::time::timeout(Duration::from_secs(10), run)
        .await
        .expect("the job is released once storage recovers")
        .unwrap()
        .unwrap();
    assert!(
        matches!(
            outcome,
            ExecutionOutcome::TaskCompleted {
                outcome: RunOutcome::StorageFault(_),
                ..
            }
        ),
        "{outcome:?}"
    );
    let queued = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(queued["status"], "queued");
    assert_eq!(queued["progress"], json!({ "done": 1, "total": 3 }));

    app.run_pending_jobs().await;
    let done = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(done["status"], "succeeded");
    assert_eq!(done["progress"], json!({ "done": 3, "total": 3 }));
    assert_eq!(app.count("shape").await, 3);
    let job = app
        .get(&format!("/v1/jobs/{}", done["job_id"]))
        .await
        .json();
    assert_eq!(job["attempts"], 2);
    assert!(job["error"].is_null(), "{job}");
}
