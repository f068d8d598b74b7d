//! Tasks under leases: one holder per task, takeover after expiry on the database's clock,
//! late commits refused by token, stalled tasks given up, cancellation reaching a worker
//! of another process, and start-up leaving other processes' work alone. Runs on SQLite
//! and, with `AORTAGEN_TEST_POSTGRES_URL`, on PostgreSQL.

use std::collections::HashSet;
use std::sync::atomic::Ordering;
use std::time::Duration;

use aortagen::db::{self, states::TaskKind, tasks};
use aortagen::jobs::{
    ExecutionOutcome, JobContext, JobControls, LeaseSettings, RunOutcome, try_execute_job, worker,
};
use axum::http::{Method, StatusCode};

use crate::engine::{AnalyticEngine, TRAINING_SHAPES};
use crate::helpers::{TestApp, cohort_body, spawn_app, spawn_app_with, spawn_on};
use crate::jobs::wait_for_calls;

/// The service's job context as another process would have it: its own interrupt flags and
/// lease owner, the same database.
fn other_process(app: &TestApp, owner: &str, leases: LeaseSettings) -> JobContext {
    let mut ctx = app.state.jobs.clone();
    ctx.controls = JobControls::default();
    ctx.owner = owner.to_owned();
    ctx.leases = leases;
    ctx
}

fn short_leases(lease_ms: u64) -> LeaseSettings {
    LeaseSettings {
        lease: Duration::from_millis(lease_ms),
        heartbeat: Duration::from_millis(lease_ms / 10),
        max_stalls: 3,
    }
}

async fn job_id(app: &TestApp, cohort: i64) -> i64 {
    app.get(&format!("/v1/cohorts/{cohort}")).await.json()["job_id"]
        .as_i64()
        .unwrap()
}

#[tokio::test]
async fn concurrent_claims_never_hand_one_task_to_two_workers() {
    let app = spawn_app().await;
    for _ in 0..3 {
        app.create_cohort_ok(&cohort_body(8, 2)).await;
    }
    let pool = app.state.pool.clone();
    let claimers: Vec<_> = (0..8)
        .map(|w| {
            let pool = pool.clone();
            tokio::spawn(async move {
                let mut mine = Vec::new();
                while let Some(lease) = tasks::claim(
                    &pool,
                    &format!("test/{w}"),
                    &format!("token-{w}-{}", mine.len()),
                    60_000,
                )
                .await
                .unwrap()
                {
                    mine.push(lease.task_id);
                }
                mine
            })
        })
        .collect();
    let mut all = Vec::new();
    for c in claimers {
        all.extend(c.await.unwrap());
    }
    let distinct: HashSet<i64> = all.iter().copied().collect();
    assert_eq!(
        distinct.len(),
        all.len(),
        "a task was claimed twice: {all:?}"
    );
    // Setup tasks (5 training surfaces, shared by the three cohorts' model and resolution,
    // one set per job) are claimable; shapes wait for them, so not every task was handed out.
    let total: i64 = sqlx::query_scalar("select count(*) from task")
        .fetch_one(&pool)
        .await
        .unwrap();
    assert!(
        !all.is_empty() && (all.len() as i64) < total,
        "{} of {total}",
        all.len()
    );
}

#[tokio::test]
async fn a_late_commit_after_a_takeover_is_refused_and_the_new_holder_commits() {
    let app = spawn_app().await;
    app.create_cohort_ok(&cohort_body(1, 2)).await;
    let pool = &app.state.pool;
    let first = tasks::claim(pool, "a/1/1/0", "token-a", 150)
        .await
        .unwrap()
        .expect("a task is queued");
    // Not expired yet: nobody else gets it.
    let next = tasks::claim(pool, "b/1/1/0", "token-b", 60_000)
        .await
        .unwrap();
    assert_ne!(next.as_ref().map(|l| l.task_id), Some(first.task_id));
    // Drain the other claimable tasks, then wait for the first lease to run out.
    while tasks::claim(pool, "b/1/1/0", "token-drain", 60_000)
        .await
        .unwrap()
        .is_some()
    {}
    tokio::time::sleep(Duration::from_millis(300)).await;
    let taken = tasks::claim(pool, "c/1/1/0", "token-c", 60_000)
        .await
        .unwrap()
        .expect("the expired task is taken over");
    assert_eq!(taken.task_id, first.task_id);
    assert_eq!((taken.attempts, taken.stalled_attempts), (2, 1));
    let mut tx = db::begin_write(pool).await.unwrap();
    let late = tasks::complete(&mut tx, &first).await;
    assert!(matches!(late, Err(tasks::LeaseError::Lost(id)) if id == first.task_id));
    drop(tx);
    let beat = tasks::heartbeat(pool, &first, 60_000, false).await.unwrap();
    assert_eq!(beat, tasks::Heartbeat::Lost);
    let mut tx = db::begin_write(pool).await.unwrap();
    tasks::complete(&mut tx, &taken).await.unwrap();
    tx.commit().await.unwrap();
    let status: String = sqlx::query_scalar("select status from task where task_id = $1")
        .bind(taken.task_id)
        .fetch_one(pool)
        .await
        .unwrap();
    assert_eq!(status, "done");
}

#[tokio::test]
async fn a_task_whose_leases_keep_expiring_fails_with_its_job() {
    let app = spawn_app().await;
    let cohort = app.create_cohort_ok(&cohort_body(2, 2)).await;
    let ctx = other_process(&app, "gone/1/1/0", short_leases(100));
    let pool = &app.state.pool;
    // Three claims whose holder never renews: each lease expires in turn.
    let mut task_id = None;
    for round in 0..3 {
        let lease = tasks::claim(pool, &ctx.owner, &format!("t{round}"), 50)
            .await
            .unwrap()
            .expect("claimable");
        assert_eq!(*task_id.get_or_insert(lease.task_id), lease.task_id);
        assert_eq!(lease.stalled_attempts, round);
        tokio::time::sleep(Duration::from_millis(120)).await;
    }
    // The next worker finds it stalled max_stalls times: the task and its job fail.
    let outcome = try_execute_job(&ctx).await.unwrap();
    assert!(
        !matches!(outcome, ExecutionOutcome::TaskCompleted { task_id: t, .. } if Some(t) == task_id)
    );
    let job = app
        .get(&format!("/v1/jobs/{}", job_id(&app, cohort).await))
        .await
        .json();
    assert_eq!(job["status"], "failed", "{job}");
    assert!(
        job["error"].as_str().unwrap().contains("3 times in a row"),
        "{job}"
    );
}

#[tokio::test]
async fn a_renewed_lease_is_never_taken_over() {
    let app = spawn_app_with(AnalyticEngine {
        hold_from_call: Some(0),
        ..Default::default()
    })
    .await;
    let cohort = app.create_cohort_ok(&cohort_body(1, 2)).await;
    // Setup first, by anyone.
    let setup = other_process(&app, "setup/1/1/0", short_leases(2000));
    for _ in 0..TRAINING_SHAPES {
        let done = try_execute_job(&setup).await.unwrap();
        assert!(matches!(
            done,
            ExecutionOutcome::TaskCompleted {
                kind: TaskKind::Surface,
                ..
            }
        ));
    }
    // The shape runs in a worker whose lease (200 ms) is far shorter than the hold.
    let holder = other_process(&app, "holder/1/1/0", short_leases(200));
    let run = tokio::spawn({
        let holder = holder.clone();
        async move { try_execute_job(&holder).await }
    });
    wait_for_calls(&app, 1).await;
    tokio::time::sleep(Duration::from_millis(800)).await;
    // Four lease lengths later, another worker still finds nothing to take.
    let thief = other_process(&app, "thief/1/1/0", short_leases(200));
    assert_eq!(
        try_execute_job(&thief).await.unwrap(),
        ExecutionOutcome::EmptyQueue
    );
    app.engine.release.store(true, Ordering::SeqCst);
    let done = run.await.unwrap().unwrap();
    assert!(matches!(
        done,
        ExecutionOutcome::TaskCompleted {
            outcome: RunOutcome::Succeeded,
            ..
        }
    ));
    app.run_pending_jobs().await;
    assert_eq!(
        app.get(&format!("/v1/cohorts/{cohort}")).await.json()["status"],
        "succeeded"
    );
}

#[tokio::test]
async fn a_cancel_reaches_a_task_running_in_another_process() {
    let app = spawn_app_with(AnalyticEngine {
        hold_from_call: Some(1),
        ..Default::default()
    })
    .await;
    let cohort = app.create_cohort_ok(&cohort_body(4, 2)).await;
    let elsewhere = other_process(&app, "elsewhere/1/1/0", short_leases(1000));
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let worker = tokio::spawn(worker::run_worker_until_stopped(
        0,
        elsewhere.clone(),
        app.state.queue.waker(),
        stop_rx,
    ));
    wait_for_calls(&app, 2).await;
    let r = app
        .request(
            Method::POST,
            &format!("/v1/cohorts/{cohort}/cancel"),
            &[],
            "",
        )
        .await;
    assert_eq!(r.status, StatusCode::ACCEPTED);
    // This process runs nothing of it: the other worker learns at its next renewal.
    assert_eq!(r.json()["status"], "running");
    crate::jobs::wait_for_status(&app, cohort, "cancelled").await;
    assert_eq!(app.count("shape").await, 1);
    assert_eq!(tasks::live_leases(&app.state.pool).await.unwrap(), 0);
    stop_tx.send(true).unwrap();
    worker.await.unwrap();
}

#[tokio::test]
async fn start_up_frees_the_leases_of_dead_local_processes_only() {
    let app = spawn_app().await;
    app.create_cohort_ok(&cohort_body(2, 2)).await;
    let pool = app.state.pool.clone();
    let host = aortagen::jobs::host_name();
    // A dead process of this host (pid 0 never names a running process), a live one (this
    // test process), and a process on another machine.
    let dead = format!("{host}/0/1/0");
    let live = format!("{}/0", aortagen::jobs::process_identity());
    let remote = "another-machine/4242/99/0".to_owned();
    let mut held = Vec::new();
    for owner in [&dead, &live, &remote] {
        let lease = tasks::claim(&pool, owner, owner, 600_000)
            .await
            .unwrap()
            .expect("claimable");
        held.push((owner.clone(), lease.task_id));
    }
    let restarted = spawn_on(
        AnalyticEngine::default(),
        app.dir.clone(),
        app.database_url.clone(),
    )
    .await;
    for (owner, task_id) in held {
        let (status, expires): (String, Option<i64>) =
            sqlx::query_as("select status, lease_expires_ms from task where task_id = $1")
                .bind(task_id)
                .fetch_one(&restarted.state.pool)
                .await
                .unwrap();
        assert_eq!(status, "running");
        let expired = expires == Some(0);
        assert_eq!(expired, owner == dead, "{owner}");
    }
}

/// Claims a task as this process's worker would and then never records its end, as when
/// the final write fails for a reason other than storage or the run dies past every guard.
async fn abandon_a_task(app: &TestApp, lease_ms: i64) -> tasks::Lease {
    let pool = &app.state.pool;
    let lease = tasks::claim(pool, &app.state.jobs.owner, "abandoned", lease_ms)
        .await
        .unwrap()
        .expect("a task is queued");
    let mut conn = pool.acquire().await.unwrap();
    db::jobs::start(&mut conn, lease.job_id).await.unwrap();
    lease
}

/// Runs this process's queue housekeeping and work until `done` holds, for at most 5 s.
async fn drive_until(app: &TestApp, ctx: &JobContext, done: impl AsyncFn(&TestApp) -> bool) {
    for _ in 0..500 {
        if done(app).await {
            return;
        }
        try_execute_job(ctx).await.unwrap();
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    panic!("not reached within 5 s");
}

#[tokio::test]
async fn a_task_whose_end_was_never_recorded_stays_cancellable_and_is_taken_over() {
    let app = spawn_app().await;
    let ctx = other_process(&app, &app.state.jobs.owner, short_leases(1000));
    let status = async |app: &TestApp, cohort: i64| {
        app.get(&format!("/v1/cohorts/{cohort}")).await.json()["status"]
            .as_str()
            .unwrap()
            .to_owned()
    };

    // Cancelled while the dead lease lasts: requested at once, settled when it runs out,
    // and the job leaves the queue bound.
    let cancelled = app.create_cohort_ok(&cohort_body(1, 2)).await;
    let lease = abandon_a_task(&app, 100).await;
    assert_eq!(lease.job_id, job_id(&app, cancelled).await);
    let path = format!("/v1/cohorts/{cancelled}/cancel");
    let r = app.request(Method::POST, &path, &[], "").await;
    assert_eq!(r.status, StatusCode::ACCEPTED);
    assert_eq!(r.json()["status"], "running");
    drive_until(&app, &ctx, async |app| {
        status(app, cancelled).await == "cancelled"
    })
    .await;
    assert_eq!(tasks::live_leases(&app.state.pool).await.unwrap(), 0);
    let pending: i64 =
        sqlx::query_scalar("select count(*) from job where status in ('queued', 'running')")
            .fetch_one(&app.state.pool)
            .await
            .unwrap();
    assert_eq!(pending, 0);

    // Left alone: the task is taken over once its lease runs out and the cohort finishes.
    let finished = app.create_cohort_ok(&cohort_body(2, 2)).await;
    let lease = abandon_a_task(&app, 100).await;
    drive_until(&app, &ctx, async |app| {
        status(app, finished).await == "succeeded"
    })
    .await;
    let (task_status, attempts): (String, i64) =
        sqlx::query_as("select status, attempts from task where task_id = $1")
            .bind(lease.task_id)
            .fetch_one(&app.state.pool)
            .await
            .unwrap();
    assert_eq!((task_status.as_str(), attempts), ("done", 2));
    let view = app.get(&format!("/v1/cohorts/{finished}")).await.json();
    assert_eq!(view["progress"]["done"], 2, "{view}");
}
