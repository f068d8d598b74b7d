//! The model registry and training uploads.

use aortagen::formats::{MeshFormat, MeshMetadata, write_mesh};
use axum::http::{Method, StatusCode};

use crate::engine::uv_sphere;
use crate::helpers::{MAX_UPLOAD, MODEL, TestApp, cohort_body, spawn_app};

#[tokio::test]
async fn models_report_training_set_size_and_reconstruction_fidelity() {
    let app = spawn_app().await;
    let list = app.get("/v1/models").await.json();
    assert_eq!(list.as_array().unwrap().len(), 1);
    let m = app.get(&format!("/v1/models/{MODEL}")).await.json();
    assert_eq!(
        (m["status"].as_str(), m["training_shapes"].as_u64()),
        (Some("ready"), Some(5))
    );
    assert_eq!(m["latent_dim"], 3);
    let cd = &m["reconstruction_cd"];
    // The analytic model reports 0.001·(i+1) for i = 0..5.
    assert_eq!(cd["count"], 5);
    assert!((cd["mean"].as_f64().unwrap() - 0.003).abs() < 1e-12);
    assert!((cd["median"].as_f64().unwrap() - 0.003).abs() < 1e-12);
    assert!((cd["max"].as_f64().unwrap() - 0.005).abs() < 1e-12);
    let shapes = app.get(&format!("/v1/models/{MODEL}/shapes")).await.json();
    assert_eq!(shapes.as_array().unwrap().len(), 5);
    assert_eq!(shapes[4]["name"], "ellipsoid-4");
}

#[tokio::test]
async fn a_model_in_use_cannot_be_deleted_and_an_unused_one_can() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(1, 2)).await;
    let path = format!("/v1/models/{MODEL}");
    assert_eq!(
        app.request(Method::DELETE, &path, &[], "").await.status,
        StatusCode::CONFLICT
    );
    app.run_pending_jobs().await;
    app.request(Method::DELETE, &format!("/v1/cohorts/{id}"), &[], "")
        .await;
    assert_eq!(
        app.request(Method::DELETE, &path, &[], "").await.status,
        StatusCode::NO_CONTENT
    );
    assert_eq!(app.get(&path).await.status, StatusCode::NOT_FOUND);
}

fn stl() -> Vec<u8> {
    write_mesh(&uv_sphere(6, 8), MeshFormat::Stl, &MeshMetadata::new("mm")).unwrap()
}

#[tokio::test]
async fn a_deleted_models_id_trains_only_on_its_new_upload() {
    let app = spawn_app().await;
    let upload = |files: usize| {
        let mut parts = vec![("id", None, b"reused".to_vec())];
        for k in 0..files {
            parts.push((
                "files",
                Some(["a.stl", "b.stl", "c.stl", "d.stl"][k]),
                stl(),
            ));
        }
        parts
    };
    assert_eq!(
        app.upload_model(&upload(4)).await.status,
        StatusCode::ACCEPTED
    );
    app.run_pending_jobs().await;
    let dir = app.state.config.storage.models_dir.join("reused");
    assert!(dir.join("input").is_dir());
    assert_eq!(
        app.request(Method::DELETE, "/v1/models/reused", &[], "")
            .await
            .status,
        StatusCode::NO_CONTENT
    );
    // The deleted model's files go with it.
    assert!(!dir.exists(), "{} is left behind", dir.display());
    // A new model under the same id trains on its own two meshes, not on the four of the
    // deleted one.
    assert_eq!(
        app.upload_model(&upload(2)).await.status,
        StatusCode::ACCEPTED
    );
    app.run_pending_jobs().await;
    let m = app.get("/v1/models/reused").await.json();
    assert_eq!(
        (m["status"].as_str(), m["training_shapes"].as_u64()),
        (Some("ready"), Some(2)),
        "{m}"
    );
    assert_eq!(std::fs::read_dir(dir.join("input")).unwrap().count(), 2);
}

#[tokio::test]
async fn uploaded_meshes_train_a_new_model_as_a_job() {
    let app = spawn_app().await;
    let parts = [
        ("id", None, b"aortas-2".to_vec()),
        ("files", Some("a.stl"), stl()),
        ("files", Some("b.stl"), stl()),
    ];
    let r = app.upload_model(&parts).await;
    assert_eq!(
        r.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    assert_eq!(
        app.get("/v1/models/aortas-2").await.json()["status"],
        "training"
    );
    app.run_pending_jobs().await;
    let m = app.get("/v1/models/aortas-2").await.json();
    assert_eq!(
        (m["status"].as_str(), m["training_shapes"].as_u64()),
        (Some("ready"), Some(2))
    );
    let job = app
        .get(&format!("/v1/jobs/{}", r.json()["job_id"]))
        .await
        .json();
    assert_eq!(
        (job["kind"].as_str(), job["status"].as_str()),
        (Some("training"), Some("succeeded"))
    );
}

#[tokio::test]
async fn a_bad_upload_is_refused_naming_the_file_and_nothing_is_stored() {
    let app = spawn_app().await;
    let broken = app
        .upload_model(&[
            ("files", Some("good.stl"), stl()),
            ("files", Some("broken.ply"), b"ply\nnonsense".to_vec()),
        ])
        .await;
    assert_eq!(broken.status, StatusCode::UNPROCESSABLE_ENTITY);
    let p = broken.json();
    assert_eq!(p["field"], "files[broken.ply]");
    assert!(p["detail"].as_str().unwrap().contains("broken.ply"));

    let big = app
        .upload_model(&[
            ("files", Some("a.stl"), vec![0; MAX_UPLOAD + 1]),
            ("files", Some("b.stl"), stl()),
        ])
        .await;
    assert_eq!(big.status, StatusCode::PAYLOAD_TOO_LARGE);
    let one = app.upload_model(&[("files", Some("a.stl"), stl())]).await;
    assert_eq!(
        (one.status, one.json()["field"].as_str()),
        (StatusCode::UNPROCESSABLE_ENTITY, Some("files"))
    );
    let json = app.post_json("/v1/models", &serde_json::json!({})).await;
    assert_eq!(json.status, StatusCode::UNSUPPORTED_MEDIA_TYPE);
    assert_eq!(app.count("model").await, 1);
    assert_eq!(app.count("job").await, 0);
}

fn ply() -> Vec<u8> {
    write_mesh(&uv_sphere(6, 8), MeshFormat::Ply, &MeshMetadata::new("mm")).unwrap()
}

#[tokio::test]
async fn meshes_recognised_by_content_are_stored_so_training_reads_every_one() {
    let app = spawn_app().await;
    let parts = [
        ("id", None, b"sniffed".to_vec()),
        ("files", Some("no-extension"), ply()),
        ("files", Some("scan.mesh"), ply()),
        ("files", Some("c.STL"), stl()),
    ];
    let r = app.upload_model(&parts).await;
    assert_eq!(
        r.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    assert_eq!(r.json()["shapes"], 3);
    let input = app
        .state
        .config
        .storage
        .models_dir
        .join("sniffed")
        .join("input");
    let mut stored: Vec<String> = std::fs::read_dir(&input)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    stored.sort();
    assert_eq!(stored, ["0000.ply", "0001.ply", "0002.stl"]);
    // What the training job reads: every accepted mesh, none left behind.
    let read = aortagen::sdf::data::read_mesh_directory(&input).unwrap();
    assert_eq!(read.len(), 3);
}

/// A zip archive of `(name, bytes)` members, deflated, with a directory and macOS metadata
/// that the service must skip.
pub fn zip_of(members: &[(&str, Vec<u8>)]) -> Vec<u8> {
    use std::io::Write;
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    zip.add_directory("meshes/", options).unwrap();
    for (name, bytes) in members {
        zip.start_file(*name, options).unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.start_file("__MACOSX/meshes/._a.stl", options).unwrap();
    zip.write_all(b"resource fork").unwrap();
    zip.finish().unwrap().into_inner()
}

async fn post_zip(app: &TestApp, query: &str, body: Vec<u8>) -> crate::helpers::TestResponse {
    let path = format!("/v1/models{query}");
    app.request(
        Method::POST,
        &path,
        &[("content-type", "application/zip")],
        body,
    )
    .await
}

#[tokio::test]
async fn a_zip_archive_of_meshes_trains_a_model() {
    let app = spawn_app().await;
    let archive = zip_of(&[
        ("meshes/a.stl", stl()),
        ("meshes/b.stl", stl()),
        ("meshes/c.stl", stl()),
    ]);
    let r = post_zip(&app, "?id=zipped&epochs=3", archive.clone()).await;
    assert_eq!(
        r.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    assert_eq!(
        r.json()["shapes"],
        3,
        "directory and __MACOSX entries are skipped"
    );
    let job = app.get(r.header("location").unwrap()).await.json();
    assert_eq!(job["progress"]["total"], 3, "the requested epochs");
    app.run_pending_jobs().await;
    let m = app.get("/v1/models/zipped").await.json();
    assert_eq!(
        (m["status"].as_str(), m["training_shapes"].as_u64()),
        (Some("ready"), Some(3))
    );

    // The same archive as one part of a multipart upload, next to a plain file.
    let parts = [
        ("id", None, b"zipped-part".to_vec()),
        ("files", Some("set.zip"), archive),
        ("files", Some("d.stl"), stl()),
    ];
    let r = app.upload_model(&parts).await;
    assert_eq!(
        r.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    assert_eq!(r.json()["shapes"], 4);
}

#[tokio::test]
async fn a_zip_member_that_is_not_a_mesh_is_named_in_a_422() {
    let app = spawn_app().await;
    let archive = zip_of(&[
        ("meshes/a.stl", stl()),
        ("meshes/broken.obj", b"v 1 2\nf 9 9 9\n".to_vec()),
    ]);
    let r = post_zip(&app, "?id=broken", archive).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
    let problem = r.json();
    assert_eq!(
        problem["field"], "files[upload.zip/meshes/broken.obj]",
        "{problem}"
    );
    assert!(
        problem["detail"].as_str().unwrap().contains("broken.obj"),
        "{problem}"
    );
    assert_eq!(
        app.get("/v1/models/broken").await.status,
        StatusCode::NOT_FOUND
    );
}

#[tokio::test]
async fn bytes_that_are_not_a_zip_are_refused_with_a_reason() {
    let app = spawn_app().await;
    let r = post_zip(&app, "", b"this is not an archive".to_vec()).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
    let problem = r.json();
    assert_eq!(problem["field"], "files[upload.zip]");
    assert!(
        problem["detail"]
            .as_str()
            .unwrap()
            .contains("not a readable zip archive"),
        "{problem}"
    );
}

#[tokio::test]
async fn archives_with_too_many_entries_or_too_many_bytes_are_413() {
    use crate::helpers::{MAX_ARCHIVE_BYTES, MAX_ARCHIVE_ENTRIES};
    let app = spawn_app().await;
    let many: Vec<(String, Vec<u8>)> = (0..MAX_ARCHIVE_ENTRIES)
        .map(|i| (format!("m{i}.stl"), stl()))
        .collect();
    let members: Vec<(&str, Vec<u8>)> = many.iter().map(|(n, b)| (n.as_str(), b.clone())).collect();
    let r = post_zip(&app, "", zip_of(&members)).await;
    assert_eq!(
        r.status,
        StatusCode::PAYLOAD_TOO_LARGE,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    assert!(r.detail().contains("entries"));

    // A bomb: a few kilobytes that expand past the limit.
    let zeros = vec![b' '; MAX_ARCHIVE_BYTES + 1];
    let bomb = zip_of(&[("a.obj", zeros)]);
    assert!(bomb.len() < MAX_UPLOAD, "the archive itself is small");
    let r = post_zip(&app, "", bomb).await;
    assert_eq!(
        r.status,
        StatusCode::PAYLOAD_TOO_LARGE,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    assert!(r.detail().contains("expands to more than"));
}

#[tokio::test]
async fn zip_members_whose_path_leaves_the_archive_are_refused() {
    let app = spawn_app().await;
    let archive = zip_of(&[("a.stl", stl()), ("../../etc/b.stl", stl())]);
    let r = post_zip(&app, "", archive).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(r.json()["field"], "files[upload.zip/../../etc/b.stl]");
}

/// An OBJ sphere padded with comment lines to `size` bytes (comments are ignored by readers,
/// and deflate to almost nothing inside an archive).
fn padded_obj(size: usize) -> Vec<u8> {
    let mut obj = write_mesh(&uv_sphere(6, 8), MeshFormat::Obj, &MeshMetadata::new("mm")).unwrap();
    let line = b"# padding padding padding padding padding padding padding padding\n";
    while obj.len() + line.len() <= size {
        obj.extend_from_slice(line);
    }
    obj
}

#[tokio::test]
async fn the_expanded_size_bound_covers_all_archives_of_one_request() {
    use crate::helpers::MAX_ARCHIVE_BYTES;
    let app = spawn_app().await;
    // Each archive alone is within the bound; together they expand past it.
    let part = || zip_of(&[("m.obj", padded_obj(MAX_ARCHIVE_BYTES * 6 / 10))]);
    let within = app
        .upload_model(&[
            ("id", None, b"one-archive".to_vec()),
            ("files", Some("a.zip"), part()),
            ("files", Some("b.stl"), stl()),
        ])
        .await;
    assert_eq!(
        within.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&within.body)
    );
    let r = app
        .upload_model(&[
            ("id", None, b"two-archives".to_vec()),
            ("files", Some("a.zip"), part()),
            ("files", Some("b.zip"), part()),
        ])
        .await;
    assert_eq!(
        r.status,
        StatusCode::PAYLOAD_TOO_LARGE,
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    let detail = r.detail();
    assert!(
        detail.contains("b.zip and the archives before it"),
        "{detail}"
    );
    assert_eq!(
        app.get("/v1/models/two-archives").await.status,
        StatusCode::NOT_FOUND
    );
}
