//! Simulation meshes through the service: a generated root downloaded capped and open in
//! the labelled formats, its face table in the sidecar and in the shape's detail, one
//! stored computation per set of options, and every bad parameter or shape answered with a
//! problem naming the field.

use axum::http::{Method, StatusCode};
use serde_json::{Value, json};

use crate::helpers::{TestApp, cohort_body, spawn_app, spawn_neural};

/// One shape of the bundled model (parametric roots, which have an inlet and an outlet).
async fn root_shape<E>(app: &TestApp<E>) -> i64 {
    let body = json!({"model_id": "default", "count": 1, "arity": 2, "seed": 5,
        "resolution": 64});
    let cohort = app.create_cohort_ok(&body).await;
    app.run_pending_jobs().await;
    app.shape_details(cohort).await[0]["id"].as_i64().unwrap()
}

fn problem_field(r: &crate::helpers::TestResponse) -> (StatusCode, String) {
    let field = r.json()["field"].as_str().unwrap_or_default().to_owned();
    (r.status, field)
}

/// The files of a zip archive in order: name and bytes.
fn unzip(bytes: &[u8]) -> Vec<(String, Vec<u8>)> {
    use std::io::Read as _;
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(bytes)).unwrap();
    (0..archive.len())
        .map(|i| {
            let mut file = archive.by_index(i).unwrap();
            let mut data = Vec::new();
            file.read_to_end(&mut data).unwrap();
            (file.name().unwrap().into_owned(), data)
        })
        .collect()
}

fn faces_named<'a>(sidecar: &'a Value, name: &str) -> Vec<&'a Value> {
    sidecar["faces"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|f| f["name"].as_str().unwrap().starts_with(name))
        .collect()
}

#[tokio::test(flavor = "multi_thread")]
async fn a_root_downloads_capped_and_open_from_one_stored_mesh_with_its_face_table() {
    let app = spawn_neural(&["default"], 500).await;
    let id = root_shape(&app).await;
    let detail = app.get(&format!("/v1/shapes/{id}")).await.json();
    assert!(
        detail["faces"].is_null(),
        "no face table before one is made"
    );
    assert_eq!(detail["faces_url"], format!("/v1/shapes/{id}/faces"));

    let vtp = app.get(&format!("/v1/shapes/{id}/mesh?format=vtp")).await;
    assert_eq!(
        vtp.status,
        StatusCode::OK,
        "{}",
        String::from_utf8_lossy(&vtp.body)
    );
    assert_eq!(
        vtp.header("content-type"),
        Some("application/vnd.vtk.vtp+xml")
    );
    let text = String::from_utf8_lossy(&vtp.body);
    assert!(text.contains("<VTKFile") && text.contains("ModelFaceID"));
    assert_eq!(app.count("shape_simulation").await, 1);

    let capped = app.get(&format!("/v1/shapes/{id}/faces")).await;
    assert_eq!(capped.status, StatusCode::OK);
    let capped = capped.json();
    let (inlet, outlet) = (
        faces_named(&capped, "inlet"),
        faces_named(&capped, "outlet"),
    );
    assert_eq!((inlet.len(), outlet.len()), (1, 1), "{capped}");
    for cap in [inlet[0], outlet[0]] {
        let area = cap["area_mm2"].as_f64().unwrap();
        let d = cap["equivalent_diameter_mm"].as_f64().unwrap();
        assert!(area > 50.0, "a root's cap is centimetres wide: {area}");
        assert!((d - (4.0 * area / std::f64::consts::PI).sqrt()).abs() < 1e-9);
    }
    let normal = |f: &Value| -> Vec<f64> {
        f["normal"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let (n_in, n_out) = (normal(inlet[0]), normal(outlet[0]));
    let dot: f64 = n_in.iter().zip(&n_out).map(|(a, b)| a * b).sum();
    assert!(
        dot < -0.5,
        "inlet and outlet face away from each other: {dot}"
    );
    assert_eq!(
        capped["quality"]["self_intersections"], 0,
        "{}",
        capped["quality"]
    );

    let open = app
        .get(&format!("/v1/shapes/{id}/faces?openings=open"))
        .await
        .json();
    assert!(faces_named(&open, "inlet").is_empty() && faces_named(&open, "outlet").is_empty());
    assert_eq!(faces_named(&open, "wall").len(), 1);
    let stl = app
        .get(&format!("/v1/shapes/{id}/mesh?format=stl&openings=open"))
        .await;
    assert_eq!(stl.status, StatusCode::OK);
    let solids = String::from_utf8_lossy(&stl.body)
        .matches("endsolid")
        .count();
    assert_eq!(solids, 1, "the open variant is the wall alone");
    assert_eq!(
        app.count("shape_simulation").await,
        1,
        "both variants from one run"
    );

    let detail = app.get(&format!("/v1/shapes/{id}")).await.json();
    assert_eq!(detail["faces"], capped["faces"]);

    let zip = app
        .get(&format!(
            "/v1/cohorts/{}/meshes.zip?format=vtp",
            detail["cohort_id"]
        ))
        .await;
    assert_eq!(zip.status, StatusCode::OK);
    let files = unzip(&zip.body);
    let name = format!("shape-{id}-capped.vtp");
    assert_eq!(
        files.iter().map(|f| f.0.as_str()).collect::<Vec<_>>(),
        [name.as_str(), "manifest.csv"]
    );
    assert_eq!(
        files[0].1,
        vtp.body.to_vec(),
        "the archive holds the download"
    );
    let manifest = String::from_utf8(files[1].1.clone()).unwrap();
    let row = manifest.lines().nth(1).unwrap();
    assert!(row.starts_with(&format!("{id},0,{name},default,")), "{row}");
    assert!(row.contains("inlet:") && row.contains("outlet:"), "{row}");
    assert_eq!(
        app.count("shape_simulation").await,
        1,
        "the archive reads the stored mesh"
    );

    let etag = vtp.header("etag").unwrap().to_owned();
    let again = app
        .request(
            Method::GET,
            &format!("/v1/shapes/{id}/mesh?format=vtp"),
            &[("if-none-match", &etag)],
            Vec::new(),
        )
        .await;
    assert_eq!(again.status, StatusCode::NOT_MODIFIED);
    let other = app
        .get(&format!("/v1/shapes/{id}/mesh?format=vtp&openings=open"))
        .await;
    assert_ne!(other.header("etag"), Some(etag.as_str()));
}

#[tokio::test(flavor = "multi_thread")]
async fn a_cut_beyond_the_root_is_blamed_on_the_distance_and_kept_as_a_failure() {
    let app = spawn_neural(&["default"], 500).await;
    let id = root_shape(&app).await;
    let url = format!("/v1/shapes/{id}/mesh?format=vtp&outlet_above_stj_mm=190");
    let r = app.get(&url).await;
    assert_eq!(
        problem_field(&r),
        (
            StatusCode::UNPROCESSABLE_ENTITY,
            "outlet_above_stj_mm".into()
        ),
        "{}",
        String::from_utf8_lossy(&r.body)
    );
    assert_eq!(r.header("content-type"), Some("application/problem+json"));
    assert_eq!(app.count("shape_simulation").await, 1);
    assert_eq!(problem_field(&app.get(&url).await).1, "outlet_above_stj_mm");
    assert_eq!(
        app.count("shape_simulation").await,
        1,
        "the failure is read back"
    );
}

#[tokio::test(flavor = "multi_thread")]
async fn bad_parameters_are_refused_before_any_geometry_naming_the_field() {
    let app = spawn_app().await;
    let cohort = app.create_cohort_ok(&cohort_body(1, 2)).await;
    app.run_pending_jobs().await;
    let id = app.shape_details(cohort).await[0]["id"].as_i64().unwrap();
    let cases = [
        ("format=step", "format"),
        ("format=ply&openings=capped", "format"),
        ("format=vtp&openings=closed", "format"),
        ("openings=half", "openings"),
        ("remesh_mm=1", "remesh_mm"),
        ("format=vtp&remesh_mm=50", "remesh_mm"),
        ("format=vtp&extension_diameters=-1", "extension_diameters"),
        ("format=vtp&kind=heart", "kind"),
        ("format=vtp&units=unit", "units"),
    ];
    for (query, field) in cases {
        let r = app.get(&format!("/v1/shapes/{id}/mesh?{query}")).await;
        assert_eq!(
            problem_field(&r),
            (StatusCode::BAD_REQUEST, field.to_owned()),
            "{query}"
        );
    }
    let r = app
        .get(&format!("/v1/shapes/{id}/faces?openings=closed"))
        .await;
    assert_eq!(
        problem_field(&r),
        (StatusCode::BAD_REQUEST, "openings".into())
    );
    let r = app
        .get(&format!(
            "/v1/cohorts/{cohort}/meshes.zip?format=vtp&remesh_mm=50"
        ))
        .await;
    assert_eq!(
        problem_field(&r),
        (StatusCode::BAD_REQUEST, "remesh_mm".into())
    );
    assert_eq!(app.count("shape_simulation").await, 0);

    let zip = app
        .get(&format!("/v1/cohorts/{cohort}/meshes.zip?format=stl"))
        .await;
    assert_eq!(zip.status, StatusCode::OK);
    let files = unzip(&zip.body);
    let plain = app.get(&format!("/v1/shapes/{id}/mesh?format=stl")).await;
    assert_eq!(files[0], (format!("shape-{id}.stl"), plain.body.to_vec()));
    let manifest = String::from_utf8(files[1].1.clone()).unwrap();
    assert_eq!(
        manifest.lines().next(),
        Some(aortagen::http::cohort_meshes::MANIFEST_HEADER)
    );
    assert_eq!(manifest.lines().count(), 2, "{manifest}");
}

/// The finest edge length a budget refusal names ("… use remesh_mm of at least X mm").
fn finest_named(problem: &Value) -> f64 {
    let detail = problem["detail"].as_str().unwrap();
    let (_, tail) = detail
        .split_once("at least ")
        .expect("names the finest edge");
    tail.trim_end_matches(" mm").parse().unwrap()
}

#[tokio::test(flavor = "multi_thread")]
async fn a_remesh_over_the_service_limit_is_refused_before_any_work_naming_remesh_mm() {
    let app = spawn_neural(&["default"], 500).await;
    let id = root_shape(&app).await;
    let cohort = app.get(&format!("/v1/shapes/{id}")).await.json()["cohort_id"]
        .as_i64()
        .unwrap();
    let max = app.state.config.max_remesh_triangles;
    let fine = [
        format!("/v1/shapes/{id}/mesh?format=vtp&remesh_mm=0.1"),
        format!("/v1/shapes/{id}/faces?remesh_mm=0.1"),
        format!("/v1/cohorts/{cohort}/meshes.zip?format=vtp&remesh_mm=0.1"),
    ];
    let mut finest = Vec::new();
    for path in &fine {
        let r = app.get(path).await;
        assert_eq!(
            problem_field(&r),
            (StatusCode::UNPROCESSABLE_ENTITY, "remesh_mm".into())
        );
        assert_eq!(r.json()["rule"], "budget", "{path}");
        finest.push(finest_named(&r.json()));
    }
    assert!(finest.windows(2).all(|w| w[0] == w[1]), "{finest:?}");
    assert_eq!(
        app.count("shape_simulation").await,
        0,
        "nothing made or stored"
    );

    // The named edge is the limit for the shape's surface: the area over an equilateral
    // triangle of that edge is within it, one hundredth of a millimetre finer is not.
    let area = app.get(&format!("/v1/shapes/{id}")).await.json()["area_mm2"]
        .as_f64()
        .unwrap();
    let triangles = |mm: f64| area / (3f64.sqrt() / 4.0 * mm * mm);
    assert!(
        triangles(finest[0]) <= max as f64 + 1.0,
        "{area} {finest:?}"
    );
    assert!(
        triangles(finest[0] - 0.01) > max as f64,
        "{area} {finest:?}"
    );

    // Within the limit on the closed surface, over it once flow extensions are added: the
    // pipeline refuses before remeshing, and the refusal is not kept (it is the service's
    // setting, not the shape's).
    let extended = format!(
        "/v1/shapes/{id}/faces?remesh_mm={}&extension_diameters=20",
        finest[0]
    );
    let r = app.get(&extended).await;
    assert_eq!(
        problem_field(&r),
        (StatusCode::UNPROCESSABLE_ENTITY, "remesh_mm".into())
    );
    let detail = r.detail();
    assert!(detail.contains("over the limit"), "{detail}");
    assert_eq!(app.count("shape_simulation").await, 0);
}
