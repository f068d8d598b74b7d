//! Creating, listing, cancelling and deleting cohorts.

use axum::http::{Method, StatusCode};
use serde_json::json;

use crate::helpers::{MAX_QUEUE, MODEL, cohort_body, spawn_app};
use aortagen::db::states::TaskKind;
use aortagen::jobs::{ExecutionOutcome, RunOutcome};

#[tokio::test]
async fn create_cohort_answers_202_with_location_and_a_queued_job() {
    let app = spawn_app().await;
    let r = app.create_cohort(&cohort_body(3, 2)).await;
    assert_eq!(r.status, StatusCode::ACCEPTED);
    let body = r.json();
    let id = body["id"].as_i64().unwrap();
    assert_eq!(
        r.header("location"),
        Some(format!("/v1/cohorts/{id}").as_str())
    );
    assert_eq!(body["status"], "queued");
    assert_eq!(body["progress"], json!({ "done": 0, "total": 3 }));
    assert_eq!(
        (body["seed"].as_u64(), body["resolution"].as_i64()),
        (Some(7), Some(64))
    );
    assert_eq!(body["weighting"], "dirichlet");
    let status: String = sqlx::query_scalar("select status from job where job_id = $1")
        .bind(body["job_id"].as_i64())
        .fetch_one(&app.state.pool)
        .await
        .unwrap();
    assert_eq!(status, "queued");
}

#[tokio::test]
async fn a_cohort_runs_to_completion_with_every_shape_and_its_metrics() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(4, 3)).await;
    let outcomes = app.run_pending_jobs().await;
    let kinds: Vec<TaskKind> = outcomes
        .iter()
        .map(|o| match o {
            ExecutionOutcome::TaskCompleted {
                kind,
                outcome: RunOutcome::Succeeded,
                ..
            } => *kind,
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(
        kinds.iter().filter(|k| **k == TaskKind::Shape).count(),
        4,
        "one task per shape: {kinds:?}"
    );
    assert_eq!(kinds.last(), Some(&TaskKind::Metrics), "{kinds:?}");

    let c = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(c["status"], "succeeded");
    assert_eq!(c["progress"], json!({ "done": 4, "total": 4 }));
    assert!(c["finished_at"].is_string());
    let area = &c["summary"]["area_mm2"];
    assert!(area["min"].as_f64().unwrap() <= area["mean"].as_f64().unwrap());
    assert_eq!(c["summary"]["pairwise_chamfer"]["pairs"], 6);
    let indices: Vec<i64> =
        sqlx::query_scalar("select shape_index from shape where cohort_id = $1 order by 1")
            .bind(id)
            .fetch_all(&app.state.pool)
            .await
            .unwrap();
    assert_eq!(indices, vec![0, 1, 2, 3]);
}

#[tokio::test]
async fn the_same_seed_reproduces_the_same_shapes() {
    let app = spawn_app().await;
    let a = app.create_cohort_ok(&cohort_body(3, 2)).await;
    let b = app.create_cohort_ok(&cohort_body(3, 2)).await;
    let mut other = cohort_body(3, 2);
    other["seed"] = json!(8);
    let c = app.create_cohort_ok(&other).await;
    app.run_pending_jobs().await;
    let shas = |id: i64| {
        let pool = app.state.pool.clone();
        async move {
            sqlx::query_scalar::<_, String>("select training_indices || weights || mesh_sha256 from shape where cohort_id = $1 order by shape_index")
                .bind(id)
                .fetch_all(&pool)
                .await
                .unwrap()
        }
    };
    assert_eq!(shas(a).await, shas(b).await);
    assert_ne!(shas(a).await, shas(c).await);
}

#[tokio::test]
async fn an_idempotency_key_returns_the_first_cohort_and_refuses_another_body() {
    let app = spawn_app().await;
    let body = cohort_body(2, 2).to_string();
    let headers = [
        ("content-type", "application/json"),
        ("idempotency-key", "retry-1"),
    ];
    let first = app
        .request(Method::POST, "/v1/cohorts", &headers, body.clone())
        .await;
    let again = app
        .request(Method::POST, "/v1/cohorts", &headers, body)
        .await;
    assert_eq!(
        (first.status, again.status),
        (StatusCode::ACCEPTED, StatusCode::ACCEPTED)
    );
    assert_eq!(first.json()["id"], again.json()["id"]);
    assert_eq!(again.header("idempotent-replayed"), Some("true"));
    assert_eq!(app.count("cohort").await, 1);

    let changed = app
        .request(
            Method::POST,
            "/v1/cohorts",
            &headers,
            cohort_body(3, 2).to_string(),
        )
        .await;
    assert_eq!(changed.status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(changed.json()["field"], "Idempotency-Key");
    assert_eq!(app.count("cohort").await, 1);
}

#[tokio::test]
async fn a_full_queue_answers_429_with_retry_after() {
    let app = spawn_app().await;
    for _ in 0..MAX_QUEUE {
        app.create_cohort_ok(&cohort_body(1, 2)).await;
    }
    let r = app.create_cohort(&cohort_body(1, 2)).await;
    assert_eq!(r.status, StatusCode::TOO_MANY_REQUESTS);
    assert_eq!(r.header("retry-after"), Some("30"));
    assert_eq!(r.header("content-type"), Some("application/problem+json"));
    assert_eq!(app.count("cohort").await, MAX_QUEUE);
    app.run_pending_jobs().await;
    assert_eq!(
        app.create_cohort(&cohort_body(1, 2)).await.status,
        StatusCode::ACCEPTED
    );
}

#[tokio::test]
async fn cohorts_are_listed_newest_first_with_filters_and_pages() {
    let app = spawn_app().await;
    let a = app.create_cohort_ok(&cohort_body(1, 2)).await;
    let b = app.create_cohort_ok(&cohort_body(1, 2)).await;
    app.run_pending_jobs().await;
    let c = app.create_cohort_ok(&cohort_body(1, 2)).await;

    let all = app.get("/v1/cohorts").await.json();
    let listed: Vec<i64> = all["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["id"].as_i64().unwrap())
        .collect();
    assert_eq!(listed, vec![c, b, a]);
    let queued = app.get("/v1/cohorts?status=queued").await.json();
    assert_eq!(queued["items"].as_array().unwrap().len(), 1);
    assert_eq!(queued["items"][0]["id"], c);
    let page = app.get("/v1/cohorts?limit=2").await.json();
    assert_eq!(
        (
            page["items"].as_array().unwrap().len(),
            page["next_offset"].as_i64()
        ),
        (2, Some(2))
    );
    let rest = app.get("/v1/cohorts?limit=2&offset=2").await.json();
    assert_eq!(rest["items"][0]["id"], a);
    let other = app.get("/v1/cohorts?model_id=other").await.json();
    assert!(other["items"].as_array().unwrap().is_empty());
    let mine = app
        .get(&format!("/v1/cohorts?model_id={MODEL}"))
        .await
        .json();
    assert_eq!(mine["items"].as_array().unwrap().len(), 3);
}

#[tokio::test]
async fn a_queued_cohort_is_cancelled_at_once_and_never_runs() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(2, 2)).await;
    let r = app
        .request(Method::POST, &format!("/v1/cohorts/{id}/cancel"), &[], "")
        .await;
    assert_eq!(r.status, StatusCode::ACCEPTED);
    assert_eq!(r.json()["status"], "cancelled");
    assert!(app.run_pending_jobs().await.is_empty());
    let again = app
        .request(Method::POST, &format!("/v1/cohorts/{id}/cancel"), &[], "")
        .await;
    assert_eq!(again.status, StatusCode::CONFLICT);
}

#[tokio::test]
async fn deleting_a_cohort_removes_its_shapes_metrics_and_job() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(2, 2)).await;
    app.run_pending_jobs().await;
    assert_eq!(app.count("shape").await, 2);
    let r = app
        .request(Method::DELETE, &format!("/v1/cohorts/{id}"), &[], "")
        .await;
    assert_eq!(r.status, StatusCode::NO_CONTENT);
    assert_eq!(
        app.get(&format!("/v1/cohorts/{id}")).await.status,
        StatusCode::NOT_FOUND
    );
    for table in ["shape", "cohort_metric", "cohort", "job"] {
        assert_eq!(app.count(table).await, 0, "{table}");
    }
}

#[tokio::test]
async fn metrics_list_the_shape_ids_without_reading_any_mesh() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(3, 2)).await;
    app.run_pending_jobs().await;
    let path = format!("/v1/cohorts/{id}/metrics?matrix=true");
    let before = app.get(&path).await.json();
    let ids: Vec<i64> =
        sqlx::query_scalar("select shape_id from shape where cohort_id = $1 order by shape_index")
            .bind(id)
            .fetch_all(&app.state.pool)
            .await
            .unwrap();
    assert_eq!(before["shape_ids"], json!(ids));

    // Without the stored mesh objects a read of any mesh fails: the endpoint must not need
    // them.
    sqlx::query("delete from blob")
        .execute(&app.state.pool)
        .await
        .unwrap();
    let after = app.get(&path).await;
    assert_eq!(
        after.status,
        StatusCode::OK,
        "{}",
        String::from_utf8_lossy(&after.body)
    );
    assert_eq!(after.json(), before);
}

/// A cohort's job, cohort and shape ids, read back from the service.
async fn cohort_ids(app: &crate::helpers::TestApp, cohort: i64) -> (i64, i64, Vec<i64>) {
    let view = app.get(&format!("/v1/cohorts/{cohort}")).await.json();
    let shapes: Vec<i64> =
        sqlx::query_scalar("select shape_id from shape where cohort_id = $1 order by shape_index")
            .bind(cohort)
            .fetch_all(&app.state.pool)
            .await
            .unwrap();
    (cohort, view["job_id"].as_i64().unwrap(), shapes)
}

#[tokio::test]
async fn ids_of_a_deleted_cohort_its_job_and_shapes_are_never_given_again() {
    let app = spawn_app().await;
    let first = app.create_cohort_ok(&cohort_body(2, 2)).await;
    app.run_pending_jobs().await;
    let (cohort, job, shapes) = cohort_ids(&app, first).await;
    let mesh_path = format!("/v1/shapes/{}/mesh", shapes[0]);
    let mesh = app.get(&mesh_path).await;
    assert_eq!(mesh.status, StatusCode::OK);
    let etag = mesh.header("etag").unwrap();
    assert!(etag.starts_with('"'), "a strong ETag: {etag}");
    assert!(mesh.header("cache-control").unwrap().contains("immutable"));
    let r = app
        .request(Method::DELETE, &format!("/v1/cohorts/{first}"), &[], "")
        .await;
    assert_eq!(r.status, StatusCode::NO_CONTENT);

    let second = app.create_cohort_ok(&cohort_body(2, 2)).await;
    app.run_pending_jobs().await;
    let (new_cohort, new_job, new_shapes) = cohort_ids(&app, second).await;
    assert!(new_cohort > cohort, "cohort {new_cohort} after {cohort}");
    assert!(new_job > job, "job {new_job} after {job}");
    assert!(
        new_shapes.iter().all(|s| !shapes.contains(s)),
        "{new_shapes:?} reuses {shapes:?}"
    );
    // The URL a cache may hold as immutable names nothing now, not the new cohort's shape.
    assert_eq!(app.get(&mesh_path).await.status, StatusCode::NOT_FOUND);
}

/// Runs `body` (SQL statements) inside the table's trigger `when` (e.g. `before insert on
/// cohort`), on either backend: the interleaving of a concurrent request at the exact
/// moment between a handler's checks and its write.
async fn install_trigger(app: &crate::helpers::TestApp, when: &str, body: &str) {
    let pool = &app.state.pool;
    let statements = match aortagen::db::Backend::of(pool) {
        aortagen::db::Backend::Sqlite => vec![format!(
            "create trigger concurrent_change {when} for each row begin {body}; end"
        )],
        aortagen::db::Backend::Postgres => vec![
            format!(
                "create function concurrent_change() returns trigger language plpgsql as
                 $$ begin {body}; return new; end $$"
            ),
            format!(
                "create trigger concurrent_change {when} for each row
                 execute function concurrent_change()"
            ),
        ],
    };
    for sql in statements {
        sqlx::query(sqlx::AssertSqlSafe(sql))
            .execute(pool)
            .await
            .unwrap();
    }
}

#[tokio::test]
async fn a_model_deleted_while_a_cohort_is_posted_is_a_409_and_stores_nothing() {
    let app = spawn_app().await;
    // The model disappears after the request's checks passed, just before its insert.
    install_trigger(
        &app,
        "before insert on cohort",
        "delete from model where model_id = new.model_id",
    )
    .await;
    let r = app.create_cohort(&cohort_body(2, 2)).await;
    assert_eq!(
        r.status,
        StatusCode::CONFLICT,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    assert_eq!(r.header("content-type"), Some("application/problem+json"));
    let detail = r.detail();
    assert!(detail.contains("concurrent request"), "{detail}");
    // The whole submission was rolled back: the model (deleted inside the refused
    // transaction) is still there, and no cohort or job was stored.
    for table in ["cohort", "job"] {
        assert_eq!(app.count(table).await, 0, "{table}");
    }
    assert_eq!(
        app.get(&format!("/v1/models/{MODEL}")).await.status,
        StatusCode::OK
    );
}

#[tokio::test]
async fn refitted_latents_are_refused_for_a_model_whose_shapes_were_not_refitted() {
    let app = spawn_app().await;
    let sampler = |latents: &str| {
        let mut body = cohort_body(2, 2);
        body.as_object_mut().unwrap().remove("arity");
        body["sampler"] = json!({ "kind": "pca_gaussian", "latents": latents });
        body
    };
    let r = app.create_cohort(&sampler("refitted")).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
    let p = r.json();
    assert_eq!(
        (p["field"].as_str(), p["rule"].as_str()),
        (Some("sampler.latents"), Some("unavailable"))
    );
    assert!(
        p["detail"].as_str().unwrap().contains("aortagen refit"),
        "{p}"
    );
    assert_eq!(app.count("cohort").await, 0, "nothing was stored");
    let r = app.create_cohort(&sampler("training")).await;
    assert_eq!(r.status, StatusCode::ACCEPTED);
    let r = app.create_cohort(&sampler("recent")).await;
    assert!(r.status.is_client_error(), "{}", r.status);
}
