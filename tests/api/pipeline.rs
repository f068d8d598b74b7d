//! One request, one cohort: `aortagen generate` and `POST /v1/cohorts` on the bundled model
//! give the same shapes, byte for byte, with the same provenance — plain mixtures, latent
//! noise with spread selection and anatomical targets, a minimum novelty that forces
//! redraws, a fitted anchor, and the density samplers (a truncated PCA Gaussian with
//! redraws, a PCA mixture with targets, a sampled latent mixed with an anchor).

use std::path::Path;

use aortagen::cli::generate::{GenerateArgs, SamplerArgs, Units, run};
use aortagen::cli::refit::RefitArgs;
use aortagen::cohort::targets::TargetRange;
use aortagen::cohort::{
    CovarianceEstimate, LatentSource, SamplerKind, Selection, ShapeProvenance, ShapeRecord,
    Weighting,
};
use aortagen::formats::{MeshFormat, read_mesh_bytes};
use aortagen::geometry::TriMesh;
use aortagen::geometry::normalize::UnitBallTransform;
use aortagen::sdf::backend::Backend;
use aortagen::sdf::inference::reconstruct::ExtractionMethod;
use aortagen::sdf::store::anchors::{Anchor, AnchorSet};
use aortagen::sdf::store::read_manifest;
use aortagen::sdf::store::refits::RefitSet;
use axum::http::StatusCode;
use serde_json::{Value, json};

use crate::helpers::{TestApp, copy_dir, multipart, spawn_neural};
use aortagen::engine::SdfEngine;

/// Surface samples of the novelty measure, the same on both sides.
const NOVELTY_POINTS: usize = 2_000;
/// The smallest cohort resolution: cheap, and every path still meshes.
const RESOLUTION: usize = 32;

/// A request in both forms: the API body and the command-line flags.
struct Request {
    count: u64,
    arity: usize,
    seed: u64,
    weighting: Weighting,
    selection: Selection,
    latent_noise: f64,
    min_novelty: Option<f64>,
    targets: Vec<(String, TargetRange)>,
    max_candidates: u32,
    /// Anchors: (id in the service, name in `anchors.json`).
    anchors: Vec<(i64, String)>,
    /// A density sampler (none: convex combinations of `arity` training shapes).
    sampler: Option<SamplerArgs>,
}

impl Request {
    fn plain(count: u64, arity: usize, seed: u64) -> Self {
        Self {
            count,
            arity,
            seed,
            weighting: Weighting::Dirichlet,
            selection: Selection::Uniform,
            latent_noise: 0.0,
            min_novelty: None,
            targets: Vec::new(),
            max_candidates: 20,
            anchors: Vec::new(),
            sampler: None,
        }
    }

    fn body(&self) -> Value {
        let mut body = json!({
            "model_id": "default",
            "count": self.count,
            "arity": self.arity,
            "seed": self.seed,
            "resolution": RESOLUTION,
            "weighting": self.weighting,
            "selection": self.selection,
            "latent_noise": self.latent_noise,
        });
        if let Some(m) = self.min_novelty {
            body["min_novelty"] = json!(m);
        }
        if !self.targets.is_empty() {
            let targets: serde_json::Map<String, Value> = self
                .targets
                .iter()
                .map(|(name, range)| (name.clone(), json!(range)))
                .collect();
            body["targets"] = Value::Object(targets);
            body["max_candidates"] = json!(self.max_candidates);
        }
        if !self.anchors.is_empty() {
            body["anchors"] = json!(self.anchors.iter().map(|a| a.0).collect::<Vec<_>>());
        }
        if let Some(sampler) = &self.sampler {
            body["sampler"] = json!(sampler.fields());
            body.as_object_mut().unwrap().remove("arity");
        }
        body
    }

    fn args(&self, model: &Path, out: &Path) -> GenerateArgs {
        GenerateArgs {
            model: model.to_path_buf(),
            arity: self.sampler.is_none().then_some(self.arity),
            sampler: self.sampler.clone().unwrap_or_default(),
            weights: None,
            weighting: self.weighting,
            selection: self.selection,
            anchors: self.anchors.iter().map(|a| a.1.clone()).collect(),
            latent_noise: self.latent_noise,
            min_novelty: self.min_novelty,
            targets: self.targets.clone(),
            max_candidates: self.max_candidates,
            novelty_points: NOVELTY_POINTS,
            count: self.count,
            seed: self.seed,
            resolution: RESOLUTION,
            format: MeshFormat::Glb,
            units: Units::Mm,
            out: out.to_path_buf(),
            backend: Backend::default(),
            extraction: ExtractionMethod::Fast,
            simulation: Default::default(),
        }
    }
}

/// The service's shapes of `request`: each shape's detail and its GLB download (mm).
async fn through_the_api(app: &TestApp<SdfEngine>, request: &Request) -> Vec<(Value, TriMesh)> {
    let id = app.create_cohort_ok(&request.body()).await;
    app.run_pending_jobs().await;
    let cohort = app.get(&format!("/v1/cohorts/{id}")).await.json();
    assert_eq!(cohort["status"], "succeeded", "{cohort}");
    let mut shapes = Vec::new();
    for detail in app.shape_details(id).await {
        let glb = app.get(&format!("/v1/shapes/{}/mesh", detail["id"])).await;
        assert_eq!(glb.status, StatusCode::OK);
        let mesh = read_mesh_bytes(&glb.body, MeshFormat::Glb, "api.glb").unwrap();
        shapes.push((detail, mesh));
    }
    shapes
}

/// The command line's shapes of `request`: each shape's record and its GLB (mm).
fn through_the_cli(model: &Path, request: &Request) -> Vec<(ShapeRecord, TriMesh)> {
    let out = tempfile::tempdir().unwrap();
    run(request.args(model, out.path())).unwrap();
    (0..request.count)
        .map(|i| {
            let stem = out.path().join(format!("shape_{i:04}"));
            let json = std::fs::read(stem.with_extension("json")).unwrap();
            let record: ShapeRecord = serde_json::from_slice(&json).unwrap();
            let glb = std::fs::read(stem.with_extension("glb")).unwrap();
            let mesh = read_mesh_bytes(&glb, MeshFormat::Glb, "cli.glb").unwrap();
            (record, mesh)
        })
        .collect()
}

/// Asserts that both sides made the same cohort; returns the API's shape details.
async fn assert_same_cohort(
    app: &TestApp<SdfEngine>,
    model: &Path,
    request: &Request,
) -> Vec<Value> {
    let api = through_the_api(app, request).await;
    let cli = through_the_cli(model, request);
    assert_eq!(api.len(), cli.len());
    for ((detail, api_mesh), (record, cli_mesh)) in api.iter().zip(&cli) {
        let index = record.shape_index;
        assert_eq!(detail["index"], index);
        let mut provenance: ShapeProvenance =
            serde_json::from_value(detail["provenance"].clone()).unwrap();
        // The service names its models by their registered id, the command line by the
        // prefix of the weights' hash; everything else is the same.
        provenance.model_id.clone_from(&record.provenance.model_id);
        assert_eq!(provenance, record.provenance, "shape {index}");
        assert_eq!(detail["mesh_sha256"], record.mesh_sha256, "shape {index}");
        assert_eq!(
            detail["novelty_cd"], record.novelty.chamfer,
            "shape {index}"
        );
        assert_eq!(detail["nearest_training_index"], record.novelty.nearest);
        assert_eq!(detail["redraws"], record.redraws);
        assert_eq!(detail["novelty_met"], record.novelty_met);
        assert_eq!(detail["anatomy"], json!(record.anatomy), "shape {index}");
        assert_eq!(detail["area_mm2"], record.area_mm2);
        assert_eq!(detail["volume_mm3"], record.volume_mm3);
        assert_eq!(api_mesh.positions, cli_mesh.positions, "shape {index}");
        assert_eq!(api_mesh.normals, cli_mesh.normals, "shape {index}");
        assert_eq!(api_mesh.triangles, cli_mesh.triangles, "shape {index}");
    }
    api.into_iter().map(|(detail, _)| detail).collect()
}

#[tokio::test(flavor = "multi_thread")]
async fn the_command_line_and_the_service_generate_the_same_cohort() {
    let app = spawn_neural(&["default"], NOVELTY_POINTS).await;
    let model = app.dir.path().join("models/default");

    let plain = assert_same_cohort(&app, &model, &Request::plain(2, 3, 7)).await;
    assert_ne!(
        plain[0]["provenance"]["training_indices"], plain[1]["provenance"]["training_indices"],
        "two different shapes"
    );

    let annulus = TargetRange {
        min: Some(22.0),
        max: Some(28.0),
    };
    let targeted = Request {
        selection: Selection::Spread,
        latent_noise: 0.5,
        targets: vec![("annulus_mm".into(), annulus)],
        max_candidates: 4,
        ..Request::plain(2, 2, 11)
    };
    let details = assert_same_cohort(&app, &model, &targeted).await;
    assert!(
        details
            .iter()
            .all(|d| d["provenance"]["candidates"].is_u64())
    );

    // Unreachable novelty: every shape is redrawn the most times and the most novel kept.
    let redrawn = Request {
        min_novelty: Some(1.0),
        ..Request::plain(1, 2, 5)
    };
    let details = assert_same_cohort(&app, &model, &redrawn).await;
    assert_eq!(details[0]["redraws"], 10);
    assert_eq!(details[0]["novelty_met"], false);

    // A truncated PCA Gaussian with a Ledoit–Wolf covariance (drawing also outside the
    // span of the training latents), with forced redraws and with targets: every draw is
    // the sampler's, the provenance names it with its defaults, and both ways agree.
    let gaussian = SamplerArgs {
        kind: SamplerKind::PcaGaussian,
        truncation: Some(2.0),
        covariance: Some(CovarianceEstimate::LedoitWolf),
        ..SamplerArgs::default()
    };
    let sampled = Request {
        sampler: Some(gaussian.clone()),
        min_novelty: Some(1.0),
        ..Request::plain(2, 1, 13)
    };
    let details = assert_same_cohort(&app, &model, &sampled).await;
    for d in &details {
        let p = &d["provenance"];
        assert_eq!(p["sampler"]["kind"], "pca_gaussian");
        assert_eq!(
            (
                p["sampler"]["truncation"].as_f64(),
                p["sampler"]["sigma_scale"].as_f64()
            ),
            (Some(2.0), Some(1.0))
        );
        assert_eq!(p["sampler"]["covariance"], "ledoit_wolf");
        assert_eq!(p["training_indices"], json!([]));
        assert_eq!(p["weights"], json!([1.0]));
        assert_eq!(d["redraws"], 10);
    }
    let mixture = Request {
        sampler: Some(SamplerArgs {
            kind: SamplerKind::PcaMixture,
            components: Some(2),
            mixture_modes: Some(2),
            ..SamplerArgs::default()
        }),
        targets: vec![("annulus_mm".into(), annulus)],
        max_candidates: 3,
        ..Request::plain(2, 1, 17)
    };
    let details = assert_same_cohort(&app, &model, &mixture).await;
    assert!(
        details
            .iter()
            .all(|d| d["provenance"]["candidates"].is_u64())
    );

    // The training shapes re-fitted after the model was registered: the service finds
    // them, and both ways fit the density to them.
    let refitted = Request {
        sampler: Some(SamplerArgs {
            latents: Some(LatentSource::Refitted),
            ..gaussian
        }),
        ..Request::plain(2, 1, 13)
    };
    let refused = app.create_cohort(&refitted.body()).await;
    assert_eq!(
        refused.json()["field"],
        "sampler.latents",
        "not re-fitted yet"
    );
    aortagen::cli::refit::run(RefitArgs {
        model: model.clone(),
        data: None,
        iterations: 20,
        seed: 0,
        resolution: 32,
        points: 500,
        backend: Backend::default(),
    })
    .unwrap();
    let details = assert_same_cohort(&app, &model, &refitted).await;
    let before = Request {
        min_novelty: None,
        ..sampled
    };
    let trained = through_the_cli(&model, &before);
    for (d, (record, _)) in details.iter().zip(&trained) {
        assert_eq!(d["provenance"]["sampler"]["latents"], "refitted");
        assert_ne!(
            d["volume_mm3"].as_f64(),
            Some(record.volume_mm3),
            "another density, another shape"
        );
    }

    // The service re-fits the shapes itself (`POST /v1/models/default/refit`) with the same
    // settings: the same latents and transforms to the bit as `aortagen refit`'s, so its
    // cohorts, now drawn from its own refit, are still the command line's.
    let r = app
        .post_json(
            "/v1/models/default/refit",
            &json!({ "iterations": 20, "seed": 0 }),
        )
        .await;
    assert_eq!(r.status, StatusCode::ACCEPTED, "{}", r.detail());
    app.run_pending_jobs().await;
    let served = app.get("/v1/models/default/refit").await.json();
    assert_eq!(served["status"], "ready", "{served}");
    let manifest = read_manifest(&model).unwrap();
    let file = RefitSet::load(&model, &manifest).unwrap();
    let shapes = served["shapes"].as_array().unwrap();
    assert_eq!(shapes.len(), file.shapes.len());
    for (served, fitted) in shapes.iter().zip(&file.shapes) {
        let latent: Vec<f32> = served["latent"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .collect();
        assert_eq!(latent, fitted.latent, "shape {}", fitted.name);
        assert_eq!(served["name"], fitted.name.as_str());
        assert_eq!(served["transform"]["radius"], fitted.transform.radius);
        assert_eq!(served["seed"], fitted.seed);
    }
    assert_same_cohort(
        &app,
        &model,
        &Request {
            seed: 14,
            ..refitted
        },
    )
    .await;
}

#[tokio::test(flavor = "multi_thread")]
async fn an_anchor_fitted_by_the_service_mixes_in_alike_on_the_command_line() {
    let app = spawn_neural(&["default"], NOVELTY_POINTS).await;
    let (_, root) = aortagen::synth::generate_root(99, 0, true);
    let stl = aortagen::formats::write_mesh(
        &root,
        MeshFormat::Stl,
        &aortagen::formats::MeshMetadata::new("mm"),
    )
    .unwrap();
    let (content_type, body) = multipart(&[
        ("name", None, b"patient".to_vec()),
        ("iterations", None, b"20".to_vec()),
        ("file", Some("patient.stl"), stl),
    ]);
    let fit = app
        .request(
            axum::http::Method::POST,
            "/v1/models/default/fit",
            &[("content-type", &content_type)],
            body,
        )
        .await;
    assert_eq!(fit.status, StatusCode::ACCEPTED, "{:?}", fit.body);
    let anchor_id = fit.json()["anchor_id"].as_i64().unwrap();
    app.run_pending_jobs().await;
    let anchor = app.get(&format!("/v1/anchors/{anchor_id}")).await.json();
    assert_eq!(anchor["status"], "ready", "{anchor}");

    // The command line reads the same fitted latent from the model's anchors.json.
    let model = tempfile::tempdir().unwrap();
    copy_dir(&app.dir.path().join("models/default"), model.path());
    let manifest = read_manifest(model.path()).unwrap();
    let latent: Vec<f32> = serde_json::from_value(anchor["latent"].clone()).unwrap();
    let transform = UnitBallTransform {
        centre: serde_json::from_value(anchor["transform"]["centre"].clone()).unwrap(),
        radius: anchor["transform"]["radius"].as_f64().unwrap(),
    };
    let mut set = AnchorSet::empty(&manifest);
    let fitted = Anchor {
        name: "patient".into(),
        latent: latent.clone(),
        transform,
        chamfer: anchor["chamfer"].as_f64().unwrap(),
        source: "patient.stl".into(),
        iterations: 20,
        seed: 0,
        created_unix: 0,
    };
    set.add(fitted, manifest.architecture.latent_dim).unwrap();
    set.save(model.path()).unwrap();

    // A sampled latent mixed with the anchor: weights list the sampled latent, then it.
    let sampled = Request {
        anchors: vec![(anchor_id, "patient".into())],
        sampler: Some(SamplerArgs {
            kind: SamplerKind::PcaGaussian,
            ..SamplerArgs::default()
        }),
        ..Request::plain(2, 2, 23)
    };
    for d in assert_same_cohort(&app, model.path(), &sampled).await {
        assert_eq!(d["provenance"]["anchors"][0]["name"], "patient");
        assert_eq!(d["provenance"]["weights"].as_array().unwrap().len(), 2);
        assert_eq!(d["provenance"]["training_indices"], json!([]));
    }

    let request = Request {
        anchors: vec![(anchor_id, "patient".into())],
        ..Request::plain(2, 3, 21)
    };
    let details = assert_same_cohort(&app, model.path(), &request).await;
    for d in &details {
        assert_eq!(d["provenance"]["anchor_ids"], json!([anchor_id]));
        assert_eq!(d["provenance"]["anchors"][0]["name"], "patient");
        assert_eq!(
            d["provenance"]["training_indices"]
                .as_array()
                .unwrap()
                .len(),
            2
        );
    }
}
