//! Training end to end on tiny settings: train → save → load → evaluate, bit-exact resume,
//! every way a model directory can be broken, and the cohort-mixing rules.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use aortagen::geometry::normalize::normalize_to_unit_ball;
use aortagen::sdf::backend::Backend;
use aortagen::sdf::data::{DataSource, load_source_meshes};
use aortagen::sdf::inference::evaluation::{EvaluationSettings, evaluate_model};
use aortagen::sdf::inference::reconstruct::ExtractionMethod;
use aortagen::sdf::model::decoder::SdfAutoDecoder;
use aortagen::sdf::store::{LoadedModel, ModelLoadError};
use aortagen::sdf::training::{
    Preset, Silent, StepReport, TrainingObserver, TrainingOutcome, TrainingRequest, TrainingSetup,
    train,
};

const SHAPES: usize = 3;

/// A network and sampling small enough for a debug build (well under a second per run).
fn tiny_setup(epochs: u64) -> TrainingSetup {
    let mut setup = Preset::Cpu.setup(11);
    setup.network = setup.network.with_latent_dim(8).with_hidden(32);
    setup.sampling.points_per_shape = 1000;
    let t = &mut setup.training;
    (t.epochs, t.batch_shapes, t.surface_points, t.eikonal_points) = (epochs, 2, 128, 128);
    (t.checkpoint_every, t.lr_halving_epochs) = (3, 4);
    setup
}

fn request<'a>(
    dir: &Path,
    epochs: u64,
    resume: bool,
    stop: Option<&'a AtomicBool>,
) -> TrainingRequest<'a> {
    TrainingRequest {
        out_dir: dir.to_path_buf(),
        source: DataSource::Synth {
            count: SHAPES,
            seed: 5,
        },
        holdout: None,
        setup: tiny_setup(epochs),
        backend: Backend::Flex,
        resume,
        stop,
    }
}

fn train_tiny(dir: &Path, epochs: u64) -> TrainingOutcome {
    train(&request(dir, epochs, false, None), &mut Silent).unwrap()
}

/// Every parameter value (network weights, biases, latents) in a fixed order.
fn parameters(decoder: &SdfAutoDecoder) -> Vec<f32> {
    let mut out: Vec<f32> = Vec::new();
    for layer in &decoder.network.layers {
        out.extend(layer.weight.val().into_data().iter::<f32>());
        if let Some(b) = &layer.bias {
            out.extend(b.val().into_data().iter::<f32>());
        }
    }
    out.extend(decoder.latents.val().into_data().iter::<f32>());
    out
}

fn load(dir: &Path) -> LoadedModel {
    LoadedModel::load(dir, Backend::Flex).unwrap()
}

#[test]
fn a_tiny_run_trains_saves_loads_and_evaluates() {
    let dir = tempfile::tempdir().unwrap();
    let outcome = train_tiny(dir.path(), 6);
    assert!(outcome.finished && outcome.manifest.progress.complete);
    let model = load(dir.path());
    let m = &model.manifest;
    assert_eq!(
        m.loss_history.iter().map(|l| l.epoch).collect::<Vec<_>>(),
        [1, 2, 3, 4, 5, 6]
    );
    let (first, last) = (m.loss_history[0].total, m.loss_history[5].total);
    assert!(last < 0.8 * first, "loss falls: {first} → {last}");
    assert_eq!((m.architecture.latent_dim, m.architecture.hidden), (8, 32));
    assert_eq!(
        (m.backend.as_str(), m.software_version.as_str()),
        ("flex", aortagen::VERSION)
    );
    // The stored transforms are the shapes' unit-ball normalisations.
    let meshes = load_source_meshes(&m.data.source).unwrap();
    for ((name, mesh), record) in meshes.iter().zip(&m.shapes) {
        assert_eq!(name, &record.name);
        assert_eq!(normalize_to_unit_ball(mesh).1, record.transform);
    }
    let originals: Vec<_> = meshes.into_iter().map(|(_, mesh)| mesh).collect();
    let settings = EvaluationSettings {
        resolution: 24,
        chamfer_points: 1500,
        seed: 1,
        extraction: ExtractionMethod::Fast,
    };
    let mut seen = 0;
    let report = evaluate_model(&model, &originals, &settings, &mut |_| seen += 1).unwrap();
    assert_eq!(
        (seen, report.failures, report.shapes.len()),
        (SHAPES, 0, SHAPES)
    );
    for shape in &report.shapes {
        let cd = shape.chamfer.unwrap();
        assert!(
            cd.is_finite() && cd > shape.sampling_floor,
            "{}: {cd}",
            shape.name
        );
        assert!(cd < 0.5, "a reconstruction inside the unit ball: {cd}");
    }
    let summary = report.summary.unwrap();
    assert!(summary.min <= summary.median && summary.median <= summary.max);
    assert!(report.sampling_floor_median > 0.0 && report.sampling_floor_median < summary.min);
}

#[test]
fn a_holdout_trains_on_the_rest_resumes_with_the_same_split_and_is_fitted_by_evaluate() {
    use aortagen::cli::evaluate::{EvaluateArgs, run};
    use aortagen::sdf::data::holdout::HoldoutSpec;
    let dir = tempfile::tempdir().unwrap();
    let source = DataSource::Synth { count: 5, seed: 5 };
    let with_holdout = |epochs, resume| TrainingRequest {
        source: source.clone(),
        holdout: Some(HoldoutSpec { count: 2, seed: 9 }),
        ..request(dir.path(), epochs, resume, None)
    };
    train(&with_holdout(2, false), &mut Silent).unwrap();
    // Resuming re-applies the recorded split (the spec of the resumed request is ignored).
    let outcome = train(&with_holdout(3, true), &mut Silent).unwrap();
    let m = &outcome.manifest;
    let holdout = m
        .data
        .holdout
        .as_ref()
        .expect("the manifest records the holdout");
    assert_eq!((m.shapes.len(), holdout.shapes.len()), (3, 2));
    let all: Vec<String> = load_source_meshes(&source)
        .unwrap()
        .into_iter()
        .map(|(name, _)| name)
        .collect();
    let mut names: Vec<&str> = m.shapes.iter().map(|s| s.name.as_str()).collect();
    names.extend(holdout.shapes.iter().map(|s| s.name.as_str()));
    names.sort_unstable();
    assert_eq!(names, all.iter().map(String::as_str).collect::<Vec<_>>());
    for h in &holdout.shapes {
        assert_eq!(all[h.source_index], h.name);
    }

    let out = tempfile::tempdir().unwrap();
    let json = out.path().join("evaluation.json");
    run(EvaluateArgs {
        model: dir.path().to_path_buf(),
        data: None,
        resolution: 20,
        points: 800,
        seed: 1,
        json: Some(json.clone()),
        worst: None,
        worst_count: 0,
        heldout_iterations: 5,
        backend: Backend::Flex,
        extraction: ExtractionMethod::Fast,
    })
    .unwrap();
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(report["shapes"].as_array().unwrap().len(), 3);
    let heldout = &report["heldout"];
    assert_eq!(heldout["iterations"], 5);
    let fitted = heldout["shapes"].as_array().unwrap();
    assert_eq!(fitted.len(), 2);
    for (shape, h) in fitted.iter().zip(&holdout.shapes) {
        assert_eq!(shape["name"], h.name.as_str());
        let cd = shape["chamfer"].as_f64().unwrap();
        assert!(
            cd > shape["sampling_floor"].as_f64().unwrap() && cd < 0.5,
            "{shape}"
        );
    }
}

#[test]
fn evaluate_writes_the_worst_reconstructions_worst_first_with_a_picture() {
    use aortagen::cli::evaluate::{EvaluateArgs, run};
    let dir = tempfile::tempdir().unwrap();
    train_tiny(dir.path(), 2);
    let out = tempfile::tempdir().unwrap();
    let json = out.path().join("evaluation.json");
    let worst = out.path().join("worst");
    run(EvaluateArgs {
        model: dir.path().to_path_buf(),
        data: None,
        resolution: 20,
        points: 800,
        seed: 1,
        json: Some(json.clone()),
        worst: Some(worst.clone()),
        worst_count: 2,
        heldout_iterations: 0,
        backend: Backend::Flex,
        extraction: ExtractionMethod::Fast,
    })
    .unwrap();
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let mut ranked: Vec<(f64, usize, String)> = report["shapes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            let name = s["name"].as_str().unwrap();
            let stem = name.rsplit_once('.').map_or(name, |(stem, _)| stem);
            (
                s["chamfer"].as_f64().unwrap(),
                s["index"].as_u64().unwrap() as usize,
                stem.to_string(),
            )
        })
        .collect();
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
    let model = load(dir.path());
    let originals = load_source_meshes(&model.manifest.data.source).unwrap();
    for (rank, (_, index, stem)) in ranked.iter().take(2).enumerate() {
        let path = |kind: &str| worst.join(format!("{}_{stem}_{kind}.ply", rank + 1));
        let original = aortagen::formats::read_mesh_file(&path("original")).unwrap();
        assert_eq!(
            original.positions, originals[*index].1.positions,
            "rank {rank}"
        );
        let reconstruction = aortagen::formats::read_mesh_file(&path("reconstruction")).unwrap();
        // In mesh units: the reconstruction's centroid is near the original's, well inside
        // the shape's own radius.
        let centroid = |m: &aortagen::geometry::TriMesh| {
            let n = m.positions.len() as f64;
            [0, 1, 2].map(|c| m.positions.iter().map(|p| f64::from(p[c])).sum::<f64>() / n)
        };
        let (a, b) = (centroid(&original), centroid(&reconstruction));
        let gap = (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt();
        let radius = model.manifest.shapes[*index].transform.radius;
        assert!(
            gap < 0.5 * radius,
            "rank {rank}: centroids {gap} apart, radius {radius}"
        );
    }
    assert!(
        !worst
            .join(format!("3_{}_original.ply", ranked[2].2))
            .exists()
    );
    let png = std::fs::read(worst.join("worst.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let side = |at: usize| u32::from_be_bytes(png[at..at + 4].try_into().unwrap());
    assert_eq!(
        (side(16), side(20)),
        (960, 960),
        "two columns, originals above reconstructions"
    );
}

#[test]
fn resuming_after_a_checkpoint_gives_the_uninterrupted_result() {
    let (straight, split) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let full = train_tiny(straight.path(), 6);
    train_tiny(split.path(), 3);
    let resumed = train(&request(split.path(), 6, true, None), &mut Silent).unwrap();
    assert_eq!(resumed.manifest.loss_history, full.manifest.loss_history);
    let (a, b) = (load(straight.path()), load(split.path()));
    assert_eq!(parameters(&a.decoder), parameters(&b.decoder));
}

/// Raises the stop flag after a number of steps, like Ctrl-C during training.
struct StopAfter<'a> {
    steps: usize,
    flag: &'a AtomicBool,
}

impl TrainingObserver for StopAfter<'_> {
    fn on_step(&mut self, _: &StepReport) {
        self.steps = self.steps.saturating_sub(1);
        if self.steps == 0 {
            self.flag.store(true, Ordering::SeqCst);
        }
    }
}

#[test]
fn an_interrupt_mid_epoch_checkpoints_and_resumes_exactly() {
    let (straight, split) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let full = train_tiny(straight.path(), 4);
    let flag = AtomicBool::new(false);
    // 3 shapes in batches of 2: two steps per epoch; step 5 is the first of epoch 3.
    let mut observer = StopAfter {
        steps: 5,
        flag: &flag,
    };
    let stopped = train(&request(split.path(), 4, false, Some(&flag)), &mut observer).unwrap();
    assert!(!stopped.finished);
    assert_eq!(
        (
            stopped.manifest.progress.epochs_completed,
            stopped.manifest.progress.next_batch
        ),
        (2, 1)
    );
    let resumed = train(&request(split.path(), 4, true, None), &mut Silent).unwrap();
    assert!(resumed.finished);
    assert_eq!(resumed.manifest.loss_history, full.manifest.loss_history);
    let (a, b) = (load(straight.path()), load(split.path()));
    assert_eq!(parameters(&a.decoder), parameters(&b.decoder));
}

#[test]
fn starting_over_an_existing_model_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    train_tiny(dir.path(), 1);
    let err = train(&request(dir.path(), 1, false, None), &mut Silent).unwrap_err();
    assert!(err.to_string().contains("--resume"), "{err}");
}

/// A copy of a trained model directory with one damage applied.
fn damaged(model: &Path, damage: impl FnOnce(&Path)) -> tempfile::TempDir {
    let copy = tempfile::tempdir().unwrap();
    for entry in std::fs::read_dir(model).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, copy.path().join(path.file_name().unwrap())).unwrap();
    }
    damage(copy.path());
    copy
}

fn edit_manifest(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let path = dir.join("manifest.json");
    let mut json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    edit(&mut json);
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
}

/// Replaces the weights and records the new bytes' hash, so only the content is wrong.
fn replace_weights(dir: &Path, bytes: &[u8]) {
    std::fs::write(dir.join("weights.bpk"), bytes).unwrap();
    let record = aortagen::sdf::store::file_record("weights.bpk", bytes);
    edit_manifest(dir, |m| {
        m["weights"] = serde_json::to_value(&record).unwrap()
    });
}

#[test]
fn every_kind_of_broken_model_directory_is_a_clear_error() {
    let trained = tempfile::tempdir().unwrap();
    train_tiny(trained.path(), 1);
    let t = trained.path();
    let weights = std::fs::read(t.join("weights.bpk")).unwrap();
    type Check = fn(&ModelLoadError) -> bool;
    let cases: Vec<(&str, tempfile::TempDir, Check)> = vec![
        (
            "no manifest",
            damaged(t, |d| {
                std::fs::remove_file(d.join("manifest.json")).unwrap()
            }),
            |e| matches!(e, ModelLoadError::MissingFile { path } if path.ends_with("manifest.json")),
        ),
        (
            "no weights",
            damaged(t, |d| std::fs::remove_file(d.join("weights.bpk")).unwrap()),
            |e| matches!(e, ModelLoadError::MissingFile { path } if path.ends_with("weights.bpk")),
        ),
        (
            "manifest not JSON",
            damaged(t, |d| {
                std::fs::write(d.join("manifest.json"), "solid x").unwrap()
            }),
            |e| matches!(e, ModelLoadError::NotAManifest { reason, .. } if reason.contains("not JSON")),
        ),
        (
            "foreign JSON",
            damaged(t, |d| {
                std::fs::write(d.join("manifest.json"), r#"{"name":"x"}"#).unwrap()
            }),
            |e| matches!(e, ModelLoadError::NotAManifest { reason, .. } if reason.contains("format")),
        ),
        (
            "future version",
            damaged(t, |d| edit_manifest(d, |m| m["format_version"] = 99.into())),
            |e| {
                matches!(
                    e,
                    ModelLoadError::UnsupportedVersion {
                        found: 99,
                        supported: 1,
                        ..
                    }
                )
            },
        ),
        (
            "missing field",
            damaged(t, |d| {
                edit_manifest(d, |m| {
                    m.as_object_mut().unwrap().remove("shapes");
                })
            }),
            |e| matches!(e, ModelLoadError::NotAManifest { reason, .. } if reason.contains("shapes")),
        ),
        (
            "truncated weights",
            damaged(t, |d| {
                std::fs::write(d.join("weights.bpk"), &weights[..weights.len() - 9]).unwrap()
            }),
            |e| matches!(e, ModelLoadError::Corrupted { reason, .. } if reason.contains("truncated")),
        ),
        (
            "flipped byte",
            damaged(t, |d| {
                let mut w = weights.clone();
                let mid = w.len() / 2;
                w[mid] ^= 1;
                std::fs::write(d.join("weights.bpk"), w).unwrap();
            }),
            |e| matches!(e, ModelLoadError::Corrupted { reason, .. } if reason.contains("SHA-256")),
        ),
        (
            "garbage with a matching hash",
            damaged(t, |d| replace_weights(d, &[7u8; 300])),
            |e| matches!(e, ModelLoadError::Corrupted { reason, .. } if reason.contains("burnpack")),
        ),
        (
            "other width",
            damaged(t, |d| {
                edit_manifest(d, |m| m["architecture"]["hidden"] = 16.into())
            }),
            |e| matches!(e, ModelLoadError::ArchitectureMismatch { .. }),
        ),
        (
            "fewer shapes than latents",
            damaged(t, |d| {
                edit_manifest(d, |m| {
                    m["shapes"].as_array_mut().unwrap().pop();
                })
            }),
            |e| matches!(e, ModelLoadError::ArchitectureMismatch { detail, .. } if detail.contains("latents")),
        ),
        (
            "invalid architecture",
            damaged(t, |d| {
                edit_manifest(d, |m| m["architecture"]["hidden"] = 0.into())
            }),
            |e| matches!(e, ModelLoadError::InvalidArchitecture(_)),
        ),
    ];
    for (name, dir, check) in cases {
        let err = LoadedModel::load(dir.path(), Backend::Flex).expect_err(name);
        assert!(check(&err), "{name}: unexpected error {err:?}");
        assert!(!err.to_string().is_empty());
    }
    let err = LoadedModel::load(&PathBuf::from("/nonexistent/model"), Backend::Flex).unwrap_err();
    assert!(err.to_string().contains("/nonexistent/model"), "{err}");
}

#[test]
fn a_damaged_optimizer_state_stops_a_resume() {
    let dir = tempfile::tempdir().unwrap();
    train_tiny(dir.path(), 1);
    let path = dir.path().join("optimizer.bpk");
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(&path, bytes).unwrap();
    let err = train(&request(dir.path(), 2, true, None), &mut Silent).unwrap_err();
    assert!(format!("{err:#}").contains("optimizer.bpk"), "{err:#}");
}

mod cohort {
    use super::*;
    use aortagen::cohort::{
        CohortFields, CohortPlan, CohortRequest, RequestError, RequestLimits, Weighting,
    };
    use aortagen::engine::{Engine, SdfEngine};
    use aortagen::sdf::inference::mixing::Mixture;

    /// A request of `arity` shapes with equal weights unless `weights` are given, checked
    /// against a model of [`SHAPES`] training shapes.
    fn parse(arity: i64, weights: Option<Vec<f64>>) -> Result<CohortRequest<i64>, RequestError> {
        parse_with(arity, weights, Weighting::Equal, 7)
    }

    fn parse_with(
        arity: i64,
        weights: Option<Vec<f64>>,
        weighting: Weighting,
        seed: u64,
    ) -> Result<CohortRequest<i64>, RequestError> {
        let fields = CohortFields {
            count: 20,
            arity: Some(arity),
            weights,
            weighting: Some(weighting),
            seed: Some(seed),
            resolution: Some(32),
            ..CohortFields::default()
        };
        let request = CohortRequest::parse(fields, RequestLimits::NONE, || seed)?;
        let model =
            aortagen::engine::ModelInfo::with_shapes(4, (0..SHAPES).map(|i| format!("shape-{i}")));
        request.check_model(&model)?;
        Ok(request)
    }

    fn plan(request: &CohortRequest<i64>, training_shapes: usize) -> CohortPlan {
        CohortPlan::new(request, training_shapes, None, Vec::new()).unwrap()
    }

    #[test]
    fn each_broken_rule_is_named() {
        type Case = (
            &'static str,
            i64,
            Option<Vec<f64>>,
            &'static str,
            &'static str,
        );
        let cases: Vec<Case> = vec![
            ("arity 1", 1, None, "arity", "range"),
            ("arity > shapes", 4, None, "arity", "range"),
            (
                "too few weights",
                3,
                Some(vec![0.5, 0.5]),
                "weights",
                "length",
            ),
            (
                "too many weights",
                2,
                Some(vec![0.5, 0.25, 0.25]),
                "weights",
                "length",
            ),
            (
                "negative",
                2,
                Some(vec![1.5, -0.5]),
                "weights",
                "non-negative",
            ),
            (
                "infinite",
                2,
                Some(vec![f64::INFINITY, 0.0]),
                "weights",
                "finite",
            ),
            ("sum 0.9", 2, Some(vec![0.5, 0.4]), "weights", "sum"),
            (
                "sum 1 + 2e-6",
                2,
                Some(vec![0.5, 0.500002]),
                "weights",
                "sum",
            ),
        ];
        for (name, arity, weights, field, rule) in cases {
            let err = parse(arity, weights).expect_err(name);
            assert_eq!((err.field.as_str(), err.rule), (field, rule), "{name}");
            assert!(err.to_string().contains(field), "{name}: {err}");
        }
        let err = parse(2, Some(vec![f64::NAN, 1.0])).unwrap_err();
        assert_eq!(err.rule, "finite", "{err}");
        assert!(err.to_string().contains("entry 0"), "{err}");
        assert!(parse(3, Some(vec![0.2, 0.3, 0.5 + 5e-7])).is_ok());
        assert!(parse(2, Some(vec![1.0, 0.0])).is_ok());
    }

    #[test]
    fn mixtures_are_seeded_distinct_and_convex() {
        let dirichlet = plan(&parse_with(3, None, Weighting::Dirichlet, 42).unwrap(), 10);
        let mut seen = std::collections::HashSet::new();
        for shape in 0..20 {
            let m = dirichlet.shape_spec(shape);
            assert_eq!(m, dirichlet.shape_spec(shape), "same seed, same shape");
            let mut idx = m.training_indices.clone();
            idx.sort_unstable();
            idx.dedup();
            assert_eq!(idx.len(), 3);
            assert!(idx.iter().all(|&i| i < 10));
            assert!(m.weights.iter().all(|&w| w >= 0.0));
            assert!((m.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            seen.insert(format!("{:?}", m.weights));
        }
        assert_eq!(seen.len(), 20, "Dirichlet weights differ between shapes");
        let other_seed = plan(&parse_with(3, None, Weighting::Dirichlet, 43).unwrap(), 10);
        assert_ne!(dirichlet.shape_spec(0), other_seed.shape_spec(0));
        let equal = plan(&parse_with(3, None, Weighting::Equal, 1).unwrap(), 10);
        assert_eq!(equal.shape_spec(0).weights, [1.0 / 3.0; 3]);
        let given = plan(&parse(2, Some(vec![0.3, 0.7])).unwrap(), 10);
        assert_eq!(given.shape_spec(0).weights, [0.3, 0.7]);
    }

    #[test]
    fn latents_and_transforms_mix_with_the_same_weights() {
        use aortagen::geometry::normalize::UnitBallTransform;
        let m = Mixture {
            indices: vec![2, 0],
            weights: vec![0.25, 0.75],
        };
        let latents = vec![vec![1.0, 0.0], vec![9.0, 9.0], vec![0.0, 4.0]];
        assert_eq!(m.mix_latents(&latents), [0.75, 1.0]);
        let t = |c: f64, r: f64| UnitBallTransform {
            centre: [c, 0.0, -c],
            radius: r,
        };
        let mixed = m
            .mix_transforms(&[t(4.0, 10.0), t(0.0, 1.0), t(8.0, 30.0)])
            .unwrap();
        assert!((mixed.radius - (0.25 * 30.0 + 0.75 * 10.0)).abs() < 1e-12);
        assert!((mixed.centre[0] - 5.0).abs() < 1e-12 && (mixed.centre[2] + 5.0).abs() < 1e-12);
    }

    #[test]
    fn generated_shapes_are_meshes_with_blended_transforms() {
        let dir = tempfile::tempdir().unwrap();
        train_tiny(dir.path(), 2);
        let model = load(dir.path());
        let request = parse_with(2, None, Weighting::Dirichlet, 7).unwrap();
        let spec = plan(&request, SHAPES).shape_spec(1);
        let engine = SdfEngine::new(Backend::Flex);
        let shape = engine
            .generate_shape(dir.path(), &spec, &AtomicBool::new(false))
            .unwrap();
        shape.mesh_unit.validate().unwrap();
        let transforms = model.manifest.transforms();
        let mixture = Mixture {
            indices: spec.training_indices.clone(),
            weights: spec.weights.clone(),
        };
        let radius: f64 = mixture
            .indices
            .iter()
            .zip(&mixture.weights)
            .map(|(&i, &w)| w * transforms[i].radius)
            .sum();
        assert!((shape.transform.radius - radius).abs() < 1e-9);
        assert_eq!(
            shape.transform,
            mixture.mix_transforms(&transforms).unwrap()
        );
        let mm = shape.transform.mesh_to_mesh_units(&shape.mesh_unit);
        let p = shape.mesh_unit.positions[0].map(f64::from);
        let q = shape.transform.to_mesh_units(p);
        assert!((0..3).all(|c| (f64::from(mm.positions[0][c]) - q[c]).abs() < 1e-3));
        let err = parse(5, None).unwrap_err();
        assert!(err.to_string().contains("arity"), "{err}");
    }

    /// Runs `aortagen generate` on `model_dir` with `anchors`, fixed `weights`, one shape at
    /// 32³ (the smallest cohort resolution) in unit-ball PLY; returns the output directory.
    fn generate_cli(
        model_dir: &Path,
        anchors: &[&str],
        weights: &str,
    ) -> anyhow::Result<tempfile::TempDir> {
        use aortagen::cli::generate::{GenerateArgs, Units, run};
        let out = tempfile::tempdir().unwrap();
        run(GenerateArgs {
            model: model_dir.to_path_buf(),
            arity: Some(2),
            sampler: Default::default(),
            weights: Some(weights.into()),
            weighting: Weighting::Dirichlet,
            selection: aortagen::cohort::Selection::Uniform,
            anchors: anchors.iter().map(|a| a.to_string()).collect(),
            latent_noise: 0.0,
            min_novelty: None,
            targets: Vec::new(),
            max_candidates: 1,
            novelty_points: 500,
            count: 1,
            seed: 3,
            resolution: 32,
            format: aortagen::formats::MeshFormat::Ply,
            units: Units::Unit,
            out: out.path().to_path_buf(),
            backend: Backend::Flex,
            extraction: ExtractionMethod::Fast,
            simulation: Default::default(),
        })?;
        Ok(out)
    }

    #[test]
    fn generate_mixes_a_fitted_anchor_in_the_last_place_of_every_shape() {
        use aortagen::sdf::inference::reconstruct::reconstruct;
        use aortagen::sdf::store::anchors::{Anchor, AnchorSet};
        let dir = tempfile::tempdir().unwrap();
        train_tiny(dir.path(), 2);
        let model = load(dir.path());
        let latents = model.latents();
        // An anchor that copies training shape 2 but sits elsewhere in mesh units.
        let mut transform = model.manifest.transforms()[2];
        transform.radius *= 2.0;
        let mut set = AnchorSet::empty(&model.manifest);
        let anchor = Anchor {
            name: "patient".into(),
            latent: latents[2].clone(),
            transform,
            chamfer: 1e-4,
            source: "patient.stl".into(),
            iterations: 1,
            seed: 0,
            created_unix: 0,
        };
        set.add(anchor, latents[2].len()).unwrap();
        set.save(dir.path()).unwrap();

        // All the weight on the anchor: the mesh is the anchor latent's own surface.
        let out = generate_cli(dir.path(), &["patient"], "0,1").unwrap();
        let provenance: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.path().join("shape_0000.json")).unwrap())
                .unwrap();
        assert_eq!(
            provenance["anchors"],
            serde_json::json!([{"name": "patient", "weight": 1.0}])
        );
        // One training shape, then the anchor; the weights list both in that order.
        assert_eq!(provenance["training_indices"].as_array().unwrap().len(), 1);
        assert_eq!(provenance["weights"], serde_json::json!([0.0, 1.0]));
        let radius = provenance["transform"]["radius"].as_f64().unwrap();
        assert!((radius - transform.radius).abs() < 1e-9, "{radius}");
        let written =
            aortagen::formats::read_mesh_file(&out.path().join("shape_0000.ply")).unwrap();
        let field = model.field(&latents[2]).unwrap();
        let expected = reconstruct(&field, 32, ExtractionMethod::Fast)
            .unwrap()
            .mesh;
        assert_eq!(written.positions, expected.positions);

        // Half and half: the anchor's weight is the second one and the training part the first.
        let out = generate_cli(dir.path(), &["patient"], "0.5,0.5").unwrap();
        let provenance: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.path().join("shape_0000.json")).unwrap())
                .unwrap();
        assert_eq!(provenance["anchors"][0]["weight"], 0.5);
        assert_eq!(provenance["weights"], serde_json::json!([0.5, 0.5]));

        // A name the model does not have is refused, listing the names it has.
        let err = generate_cli(dir.path(), &["nobody"], "0,1").unwrap_err();
        assert!(
            err.to_string()
                .contains("no such anchor (the model's anchors are patient)"),
            "{err}"
        );
    }
}
