//! SIGTERM in the middle of a cohort: `aortagen serve` stops accepting connections, puts the
//! running job back in the queue with its finished shapes, and exits 0 within 10 s; after a
//! restart the cohort completes with exactly its count of shapes.

use std::time::{Duration, Instant};

use serde_json::json;

use crate::process::ServiceDir;

#[test]
fn sigterm_mid_cohort_exits_cleanly_and_the_cohort_resumes() {
    let mut dir = ServiceDir::new();
    let server = dir.start(1);
    let count = 12;
    let body = json!({ "model_id": "default", "count": count, "arity": 2,
                       "seed": 5, "resolution": 64 });
    let r = server.post_json("/v1/cohorts", &body);
    assert_eq!(r.status, 202, "{}", r.text());
    let cohort = r.json()["id"].as_i64().unwrap();
    let job = r.json()["job_id"].as_i64().unwrap();

    // Wait until the job runs and has committed at least one shape, so the stop lands
    // in the middle of the cohort.
    let start = Instant::now();
    loop {
        let view = server.get_json(&format!("/v1/jobs/{job}"));
        if view["status"] == "running" && view["progress"]["done"].as_i64() > Some(0) {
            break;
        }
        assert_ne!(
            view["status"], "succeeded",
            "the cohort finished before the stop"
        );
        // A liveness bound, generous for a 2-core machine shared with other test binaries.
        assert!(start.elapsed() < Duration::from_secs(300), "{view}");
        std::thread::sleep(Duration::from_millis(20));
    }
    let (status, took, log) = server.terminate(Duration::from_secs(10));
    let status = status.unwrap_or_else(|| panic!("still running 10 s after SIGTERM:\n{log}"));
    assert!(status.success(), "exit status {status}:\n{log}");
    assert!(took < Duration::from_secs(10), "{took:?}");

    let done_at_stop = crate::process::with_database(&dir.database(), async move |pool| {
        let (status, done): (String, i64) =
            sqlx::query_as("select status, progress_done from job where job_id = $1")
                .bind(job)
                .fetch_one(pool)
                .await
                .unwrap();
        assert_eq!(status, "queued", "the interrupted job is back in the queue");
        let shapes: i64 = sqlx::query_scalar("select count(*) from shape where cohort_id = $1")
            .bind(cohort)
            .fetch_one(pool)
            .await
            .unwrap();
        assert_eq!(shapes, done, "progress counts the stored shapes");
        done
    });
    assert!(
        (1..count).contains(&done_at_stop),
        "stopped mid-cohort with {done_at_stop} shapes kept"
    );

    let server = dir.start(1);
    let start = Instant::now();
    loop {
        let view = server.get_json(&format!("/v1/cohorts/{cohort}"));
        match view["status"].as_str() {
            Some("succeeded") => break,
            Some("queued" | "running") => {}
            _ => panic!("{view}\n{}", server.log()),
        }
        assert!(start.elapsed() < Duration::from_secs(300), "{view}");
        std::thread::sleep(Duration::from_millis(100));
    }
    let page = server.get_json(&format!("/v1/cohorts/{cohort}/shapes?limit=100"));
    let indices: Vec<i64> = page["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["index"].as_i64().unwrap())
        .collect();
    assert_eq!(indices, (0..count).collect::<Vec<_>>());
    let job_view = server.get_json(&format!("/v1/jobs/{job}"));
    assert_eq!(job_view["attempts"], 2, "{job_view}");
    let (status, _, log) = server.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{log}");
}

/// Work too large to finish within the grace period (at 1024³ the model's training surfaces
/// come first, then the shape): the process still exits 0 within 10 s, abandoning the task,
/// and the job is back in the queue.
#[test]
fn sigterm_during_a_long_shape_exits_within_the_grace_period() {
    let mut dir = ServiceDir::new();
    // The bundled model's 16 training surfaces at 1024³ and the shape: 17 fields.
    dir.env.push((
        "AORTAGEN_MAX_COHORT_VOXELS".into(),
        (17 * 1024u64.pow(3)).to_string(),
    ));
    let server = dir.start(1);
    let body = json!({ "model_id": "default", "count": 1, "arity": 2,
                       "seed": 9, "resolution": 1024 });
    let r = server.post_json("/v1/cohorts", &body);
    assert_eq!(r.status, 202, "{}", r.text());
    let job = r.json()["job_id"].as_i64().unwrap();
    let start = Instant::now();
    while server.get_json(&format!("/v1/jobs/{job}"))["status"] != "running" {
        assert!(start.elapsed() < Duration::from_secs(60));
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(500));
    let (status, took, log) = server.terminate(Duration::from_secs(10));
    let status = status.unwrap_or_else(|| panic!("still running 10 s after SIGTERM:\n{log}"));
    assert!(status.success(), "exit status {status}:\n{log}");
    assert!(took < Duration::from_secs(10), "{took:?}");
    assert!(
        log.contains("did not stop within the shutdown grace period"),
        "the shape was abandoned:\n{log}"
    );
    let status = crate::process::with_database(&dir.database(), async move |pool| {
        sqlx::query_scalar::<_, String>("select status from job where job_id = $1")
            .bind(job)
            .fetch_one(pool)
            .await
            .unwrap()
    });
    assert_eq!(status, "queued");
}
