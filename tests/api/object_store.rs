//! Objects outside the database (`AORTAGEN_BLOB_STORE`): a cohort's meshes are written to a
//! directory or an S3-compatible bucket under their SHA-256, the database keeps only the
//! rows that name them, downloads read them back checked, and a sweep removes the objects
//! of deleted cohorts once their grace period is over. The S3 case runs against the real
//! s3s-fs server `scripts/test` starts (`tests/support/s3-server.sh`).

use std::time::Duration;

use aortagen::digest::sha256_hex;
use aortagen::jobs::{ExecutionOutcome, RunOutcome, try_execute_job};
use aortagen::objects::{BlobStoreUrl, ExternalStore};
use axum::http::{Method, StatusCode};

use crate::helpers::{cohort_body, spawn_app_configured};

/// The bucket of the test S3 server with a prefix of this test's own, or None when no
/// server is configured (`cargo test` alone; `scripts/test` always starts one).
fn s3_store(name: &str) -> Option<BlobStoreUrl> {
    let url = std::env::var("AORTAGEN_TEST_S3_URL").ok()?;
    let BlobStoreUrl::S3 { bucket, prefix } = url.parse().ok()? else {
        return None;
    };
    let unique = format!(
        "{prefix}/{name}-{}-{:08x}",
        std::process::id(),
        rand::random::<u32>()
    );
    Some(BlobStoreUrl::S3 {
        bucket,
        prefix: unique.trim_start_matches('/').to_owned(),
    })
}

async fn meshes_live_in_the_store_and_are_swept_after_their_cohort(store: BlobStoreUrl) {
    let configured = store.clone();
    let app = spawn_app_configured(move |c| c.storage.blob_store = configured).await;
    let id = app.create_cohort_ok(&cohort_body(3, 2)).await;
    app.run_pending_jobs().await;
    let view = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(view["status"], "succeeded", "{view}");

    let in_database: i64 = sqlx::query_scalar("select count(*) from blob")
        .fetch_one(&app.state.pool)
        .await
        .unwrap();
    assert_eq!(in_database, 0, "no mesh bytes in the database");
    let rows: Vec<(i64, String)> = sqlx::query_as(
        "select shape_id, mesh_sha256 from shape where cohort_id = $1 order by shape_index",
    )
    .bind(id)
    .fetch_all(&app.state.pool)
    .await
    .unwrap();
    assert_eq!(rows.len(), 3);
    let external = ExternalStore::open(&store).unwrap();
    for (_, sha) in &rows {
        let bytes = external.get(sha).await.unwrap().expect("the object exists");
        assert_eq!(&sha256_hex(&bytes), sha, "stored under its SHA-256");
    }

    let (shape, _) = &rows[0];
    let glb = app.get(&format!("/v1/shapes/{shape}/mesh")).await;
    assert_eq!(glb.status, StatusCode::OK);
    let document = gltf::Gltf::from_slice(&glb.body).expect("a valid GLB");
    assert_eq!(document.meshes().count(), 1);

    let deleted = app
        .request(Method::DELETE, &format!("/v1/cohorts/{id}"), &[], "")
        .await;
    assert_eq!(deleted.status, StatusCode::NO_CONTENT);
    let objects = &app.state.jobs.objects;
    // Within the grace period the objects stay (a writer may be about to name them).
    let kept = objects
        .sweep(&app.state.pool, Duration::from_secs(3600))
        .await
        .unwrap();
    assert_eq!(kept, 0);
    tokio::time::sleep(Duration::from_millis(20)).await;
    let swept = objects
        .sweep(&app.state.pool, Duration::ZERO)
        .await
        .unwrap();
    assert!(swept >= 3, "{swept} objects swept");
    for (_, sha) in &rows {
        assert!(external.get(sha).await.unwrap().is_none(), "{sha} swept");
    }
}

#[tokio::test]
async fn a_directory_store_holds_the_meshes() {
    let dir = tempfile::tempdir().unwrap();
    meshes_live_in_the_store_and_are_swept_after_their_cohort(BlobStoreUrl::Directory(
        dir.path().join("objects"),
    ))
    .await;
}

#[tokio::test]
async fn an_s3_bucket_holds_the_meshes() {
    let Some(store) = s3_store("meshes") else {
        eprintln!("AORTAGEN_TEST_S3_URL is not set: the S3 case runs under scripts/test");
        return;
    };
    meshes_live_in_the_store_and_are_swept_after_their_cohort(store).await;
}

#[tokio::test]
async fn a_failing_store_is_a_storage_fault_and_the_cohort_waits() {
    let dir = tempfile::tempdir().unwrap();
    let objects = dir.path().join("objects");
    let store = BlobStoreUrl::Directory(objects.clone());
    let app = spawn_app_configured(move |c| c.storage.blob_store = store).await;
    let id = app.create_cohort_ok(&cohort_body(1, 2)).await;
    // The store's directory turns into a file (a lost mount): every write fails.
    std::fs::remove_dir_all(&objects).unwrap();
    std::fs::write(&objects, b"").unwrap();
    // Setup tasks write no object; the shape's task is the first to meet the store.
    let outcome = loop {
        let outcome = try_execute_job(&app.state.jobs).await.unwrap();
        match &outcome {
            ExecutionOutcome::TaskCompleted {
                outcome: RunOutcome::Succeeded,
                kind,
                ..
            } if *kind != aortagen::db::states::TaskKind::Shape => continue,
            _ => break outcome,
        }
    };
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
    let view = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_ne!(view["status"], "failed", "{view}");

    // The store comes back: the cohort finishes.
    std::fs::remove_file(&objects).unwrap();
    std::fs::create_dir(&objects).unwrap();
    app.run_pending_jobs().await;
    let view = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(view["status"], "succeeded", "{view}");
}
