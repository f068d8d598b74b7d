//! Shape provenance, mesh downloads in every format and unit, caching, cohort metrics.

use aortagen::formats::mesh_blob;
use aortagen::formats::{MeshFormat, read_mesh_bytes};
use aortagen::geometry::chamfer::chamfer_distance;
use axum::http::{Method, StatusCode};
use serde_json::Value;

use crate::engine::{CENTRE_MM, mixed_axes, uv_sphere};
use crate::helpers::{MODEL, TestApp, cohort_body, spawn_app, spawn_app_configured};

async fn finished_cohort(app: &TestApp, count: i64) -> (i64, Vec<Value>) {
    let id = app.create_cohort_ok(&cohort_body(count, 3)).await;
    app.run_pending_jobs().await;
    let page = app.get(&format!("/v1/cohorts/{id}/shapes")).await.json();
    (id, page["items"].as_array().unwrap().clone())
}

fn glb_positions(bytes: &[u8]) -> Vec<[f32; 3]> {
    let (doc, buffers, _) = gltf::import_slice(bytes).expect("a valid GLB");
    let primitive = doc.meshes().next().unwrap().primitives().next().unwrap();
    let reader = primitive.reader(|b| Some(&buffers[b.index()]));
    reader.read_positions().unwrap().collect()
}

fn bbox(points: &[[f32; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::MAX; 3];
    let mut hi = [f64::MIN; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k] as f64);
            hi[k] = hi[k].max(p[k] as f64);
        }
    }
    (lo, hi)
}

#[tokio::test]
async fn a_shape_records_its_provenance_and_measures() {
    let app = spawn_app().await;
    let (cohort, shapes) = finished_cohort(&app, 2).await;
    let s = &shapes[1];
    assert_eq!(
        (s["cohort_id"].as_i64(), s["index"].as_i64()),
        (Some(cohort), Some(1))
    );
    let p = &s["provenance"];
    assert_eq!(p["model_id"], MODEL);
    assert_eq!(p["training_indices"].as_array().unwrap().len(), 3);
    let sum: f64 = p["weights"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_f64().unwrap())
        .sum();
    assert!((sum - 1.0).abs() < 1e-9);
    assert_eq!(
        (p["resolution"].as_i64(), p["software_version"].as_str()),
        (Some(64), Some(aortagen::VERSION))
    );
    let reference = uv_sphere(8, 16);
    assert_eq!(
        s["vertex_count"].as_u64(),
        Some(reference.vertex_count() as u64)
    );
    assert_eq!(
        s["triangle_count"].as_u64(),
        Some(reference.triangle_count() as u64)
    );
    assert_eq!(s["units"], "mm");
    let one = app.get(&format!("/v1/shapes/{}", s["id"])).await.json();
    assert_eq!(&one, s);
}

#[tokio::test]
async fn the_glb_download_is_the_mixed_ellipsoid_in_millimetres() {
    let app = spawn_app().await;
    let (_, shapes) = finished_cohort(&app, 1).await;
    let s = &shapes[0];
    let r = app.get(&format!("/v1/shapes/{}/mesh", s["id"])).await;
    assert_eq!(r.status, StatusCode::OK);
    assert_eq!(r.header("content-type"), Some("model/gltf-binary"));
    assert_eq!(
        r.header("cache-control"),
        Some("public, max-age=31536000, immutable")
    );
    let positions = glb_positions(&r.body);
    assert_eq!(positions.len() as u64, s["vertex_count"].as_u64().unwrap());

    let indices: Vec<usize> =
        serde_json::from_value(s["provenance"]["training_indices"].clone()).unwrap();
    let weights: Vec<f64> = serde_json::from_value(s["provenance"]["weights"].clone()).unwrap();
    let axes = mixed_axes(&indices, &weights);
    let (lo, hi) = bbox(&positions);
    for k in 0..3 {
        assert!(
            (lo[k] - (CENTRE_MM[k] - axes[k])).abs() < 1e-3,
            "axis {k}: {lo:?} vs {axes:?}"
        );
        assert!(
            (hi[k] - (CENTRE_MM[k] + axes[k])).abs() < 1e-3,
            "axis {k}: {hi:?} vs {axes:?}"
        );
    }

    let unit = app
        .get(&format!("/v1/shapes/{}/mesh?units=unit", s["id"]))
        .await;
    let (lo, hi) = bbox(&glb_positions(&unit.body));
    let largest = lo.iter().map(|v| v.abs()).chain(hi).fold(0.0, f64::max);
    assert!((largest - 1.0).abs() < 1e-6, "{largest}");
    assert_ne!(unit.header("etag"), r.header("etag"));
}

#[tokio::test]
async fn every_format_downloads_the_same_triangles() {
    let app = spawn_app().await;
    let (_, shapes) = finished_cohort(&app, 1).await;
    let id = &shapes[0]["id"];
    let triangles = shapes[0]["triangle_count"].as_u64().unwrap() as usize;
    for (name, format, mime) in [
        ("gltf", MeshFormat::Gltf, "model/gltf+json"),
        ("stl", MeshFormat::Stl, "model/stl"),
        ("obj", MeshFormat::Obj, "model/obj"),
        ("ply", MeshFormat::Ply, "application/x-ply"),
    ] {
        let r = app
            .get(&format!("/v1/shapes/{id}/mesh?format={name}"))
            .await;
        assert_eq!(
            (r.status, r.header("content-type")),
            (StatusCode::OK, Some(mime)),
            "{name}"
        );
        let mesh = read_mesh_bytes(&r.body, format, name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(mesh.triangle_count(), triangles, "{name}");
    }
}

#[tokio::test]
async fn a_matching_if_none_match_answers_304_without_a_body() {
    let app = spawn_app().await;
    let (_, shapes) = finished_cohort(&app, 1).await;
    let path = format!("/v1/shapes/{}/mesh?format=stl", shapes[0]["id"]);
    let first = app.get(&path).await;
    let etag = first.header("etag").unwrap().to_owned();
    let again = app
        .request(Method::GET, &path, &[("if-none-match", &etag)], "")
        .await;
    assert_eq!(again.status, StatusCode::NOT_MODIFIED);
    assert!(again.body.is_empty());
    let other = app
        .request(Method::GET, &path, &[("if-none-match", "\"nope\"")], "")
        .await;
    assert_eq!(
        (other.status, other.body.len()),
        (StatusCode::OK, first.body.len())
    );
}

#[tokio::test]
async fn cohort_metrics_hold_the_pairwise_chamfer_of_the_stored_meshes() {
    let app = spawn_app().await;
    let early = app.create_cohort_ok(&cohort_body(2, 2)).await;
    assert_eq!(
        app.get(&format!("/v1/cohorts/{early}/metrics"))
            .await
            .status,
        StatusCode::CONFLICT
    );
    app.run_pending_jobs().await;
    let (id, shapes) = finished_cohort(&app, 4).await;

    let m = app
        .get(&format!("/v1/cohorts/{id}/metrics?matrix=true"))
        .await
        .json();
    let ids: Vec<i64> = shapes.iter().map(|s| s["id"].as_i64().unwrap()).collect();
    assert_eq!(m["shape_ids"], serde_json::json!(ids));
    assert_eq!(m["summary"]["pairs"], 6);
    let blobs: Vec<Vec<u8>> = sqlx::query_scalar(
        "select b.bytes from shape s join blob b on b.sha256 = s.mesh_sha256
             where s.cohort_id = $1 order by s.shape_index",
    )
    .bind(id)
    .fetch_all(&app.state.pool)
    .await
    .unwrap();
    let meshes: Vec<_> = blobs
        .iter()
        .map(|b| mesh_blob::decode(b).unwrap())
        .collect();
    let expected = chamfer_distance(&meshes[1].positions, &meshes[3].positions);
    assert!((m["matrix"][1][3].as_f64().unwrap() - expected).abs() <= 1e-12 * expected.max(1.0));
    assert!(expected > 0.0);

    let csv = app
        .get(&format!("/v1/cohorts/{id}/metrics?format=csv"))
        .await;
    assert_eq!(csv.header("content-type"), Some("text/csv; charset=utf-8"));
    let text = String::from_utf8(csv.body.to_vec()).unwrap();
    assert_eq!(text.lines().count(), 1 + 6);
    assert!(text.starts_with("shape_a,shape_b,chamfer\n"));
}

/// Every stored mesh of a cohort in shape-index order.
async fn cohort_meshes(app: &TestApp, cohort: i64) -> Vec<aortagen::geometry::TriMesh> {
    let blobs: Vec<Vec<u8>> = sqlx::query_scalar(
        "select b.bytes from shape s join blob b on b.sha256 = s.mesh_sha256
             where s.cohort_id = $1 order by s.shape_index",
    )
    .bind(cohort)
    .fetch_all(&app.state.pool)
    .await
    .unwrap();
    blobs
        .iter()
        .map(|b| mesh_blob::decode(b).unwrap())
        .collect()
}

/// Metrics tasks of a cohort's job, done or not.
async fn metrics_tasks(app: &TestApp, cohort: i64) -> i64 {
    sqlx::query_scalar(
        "select count(*) from task t join cohort c on c.job_id = t.job_id
         where c.cohort_id = $1 and t.kind = 'metrics'",
    )
    .bind(cohort)
    .fetch_one(&app.state.pool)
    .await
    .unwrap()
}

#[tokio::test]
async fn metrics_split_over_several_tasks_assemble_every_pair_of_the_matrix() {
    // 30 shapes: 435 pairs, more than one task's share.
    let app = spawn_app().await;
    let (id, _) = finished_cohort(&app, 30).await;
    assert_eq!(metrics_tasks(&app, id).await, 2);
    let m = app
        .get(&format!("/v1/cohorts/{id}/metrics?matrix=true"))
        .await
        .json();
    let summary = &m["summary"];
    assert_eq!(
        (
            &summary["pairs"],
            &summary["population_pairs"],
            &summary["sampled"]
        ),
        (
            &serde_json::json!(435),
            &serde_json::json!(435),
            &serde_json::json!(false)
        )
    );
    assert!(summary["mean_ci95"].is_null() && summary["median_ci95"].is_null());
    let meshes = cohort_meshes(&app, id).await;
    let mut sum = 0.0;
    for i in 0..30 {
        assert_eq!(m["matrix"][i][i], 0.0);
        for j in i + 1..30 {
            let expected = chamfer_distance(&meshes[i].positions, &meshes[j].positions);
            let got = m["matrix"][i][j].as_f64().unwrap();
            assert!(
                (got - expected).abs() <= 1e-12 * expected.max(1.0),
                "({i}, {j})"
            );
            assert_eq!(m["matrix"][j][i].as_f64(), Some(got));
            sum += expected;
        }
    }
    let mean = summary["mean"].as_f64().unwrap();
    assert!((mean - sum / 435.0).abs() <= 1e-9 * mean);
    // The parts' pairs are assembled and removed.
    assert_eq!(app.count("cohort_pair").await, 0);
}

#[tokio::test]
async fn a_large_cohort_summarises_a_seeded_sample_of_its_pairs_with_intervals() {
    // 110 shapes: 5 995 pairs, of which a sample of 4 950 is computed.
    let app = spawn_app_configured(|c| c.max_count = 110).await;
    let (id, _) = finished_cohort(&app, 110).await;
    assert_eq!(metrics_tasks(&app, id).await, 13);
    let m = app
        .get(&format!("/v1/cohorts/{id}/metrics?matrix=true"))
        .await
        .json();
    let summary = &m["summary"];
    assert_eq!(summary["pairs"], 4950);
    assert_eq!(summary["population_pairs"], 5995);
    assert_eq!(summary["sampled"], true);
    let meshes = cohort_meshes(&app, id).await;
    let (mut sampled, mut all) = (Vec::new(), Vec::new());
    for i in 0..110 {
        for j in i + 1..110 {
            let exact = chamfer_distance(&meshes[i].positions, &meshes[j].positions);
            all.push(exact);
            if let Some(got) = m["matrix"][i][j].as_f64() {
                assert!((got - exact).abs() <= 1e-12 * exact.max(1.0), "({i}, {j})");
                sampled.push(got);
            } else {
                assert!(m["matrix"][j][i].is_null());
            }
        }
    }
    assert_eq!(sampled.len(), 4950);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!((summary["mean"].as_f64().unwrap() - mean(&sampled)).abs() <= 1e-9 * mean(&sampled));
    // The interval is around the sample mean and holds the mean over every pair.
    let ci: Vec<f64> = serde_json::from_value(summary["mean_ci95"].clone()).unwrap();
    assert!(ci[0] < mean(&sampled) && mean(&sampled) < ci[1], "{ci:?}");
    assert!(
        ci[0] <= mean(&all) && mean(&all) <= ci[1],
        "{ci:?} vs {}",
        mean(&all)
    );
    let median: Vec<f64> = serde_json::from_value(summary["median_ci95"].clone()).unwrap();
    assert!(median[0] <= summary["quantiles"]["p50"].as_f64().unwrap());
    assert!(median[1] >= summary["quantiles"]["p50"].as_f64().unwrap());

    // The pair list holds the sample; the cohort's view carries the same summary.
    let csv = app
        .get(&format!("/v1/cohorts/{id}/metrics?format=csv"))
        .await;
    assert_eq!(String::from_utf8_lossy(&csv.body).lines().count(), 1 + 4950);
    let view = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(view["summary"]["pairwise_chamfer"], *summary);

    // The same request draws the same pairs.
    let again = app.create_cohort_ok(&cohort_body(110, 3)).await;
    app.run_pending_jobs().await;
    let a = app
        .get(&format!("/v1/cohorts/{again}/metrics?matrix=true"))
        .await
        .json();
    assert_eq!(a["matrix"], m["matrix"]);
    assert_eq!(a["summary"], m["summary"]);
}

#[tokio::test]
async fn a_repeated_download_is_served_from_memory_with_the_same_bytes() {
    let app = spawn_app().await;
    let (_, shapes) = finished_cohort(&app, 2).await;
    let path = format!("/v1/shapes/{}/mesh", shapes[0]["id"]);
    assert_eq!(app.state.mesh_cache.bytes(), 0);
    let first = app.get(&path).await;
    assert_eq!(first.status, StatusCode::OK);
    assert_eq!(app.state.mesh_cache.bytes(), first.body.len());
    let again = app.get(&path).await;
    assert_eq!(again.body, first.body);
    assert_eq!(again.header("etag"), first.header("etag"));
    let stl = app.get(&format!("{path}?format=stl")).await;
    assert_ne!(stl.body, first.body);
    assert_eq!(
        app.state.mesh_cache.bytes(),
        first.body.len() + stl.body.len()
    );
}
