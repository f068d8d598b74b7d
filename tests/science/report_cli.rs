//! `aortagen report` on a directory of meshes and on the bundled model.

use std::path::Path;

use aortagen::cli::compare::CompareArgs;
use aortagen::cli::generate::{GenerateArgs, Units};
use aortagen::cli::report::{ReportArgs, run};
use aortagen::cohort::{Selection, Weighting};
use aortagen::formats::MeshFormat;
use aortagen::formats::{MeshMetadata, write_mesh_file};
use aortagen::sdf::backend::Backend;
use aortagen::sdf::inference::reconstruct::ExtractionMethod;
use aortagen::synth::generate_root;

fn args(out: &Path) -> ReportArgs {
    ReportArgs {
        model: None,
        evaluation: None,
        meshes: None,
        points: 2_000,
        seed: 0,
        out: out.to_path_buf(),
        svg_dir: None,
    }
}

#[test]
fn a_mesh_directory_report_has_every_pair_and_writes_the_svgs() {
    let dir = tempfile::tempdir().unwrap();
    let meshes = dir.path().join("meshes");
    std::fs::create_dir(&meshes).unwrap();
    for i in 0..4 {
        let (_, mesh) = generate_root(3, i, true);
        let path = meshes.join(format!("root_{i}.ply"));
        write_mesh_file(&path, &mesh, &MeshMetadata::default()).unwrap();
    }
    let out = dir.path().join("report.html");
    let svgs = dir.path().join("svg");
    run(ReportArgs {
        meshes: Some(meshes),
        svg_dir: Some(svgs.clone()),
        ..args(&out)
    })
    .unwrap();
    let html = std::fs::read_to_string(&out).unwrap();
    assert!(html.contains("(n = 6)"), "4 meshes have 6 pairs");
    assert!(html.contains("Surface area (n = 4)"));
    let mut written: Vec<String> = std::fs::read_dir(&svgs)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    written.sort();
    assert_eq!(
        written,
        [
            "enclosed-volume.svg",
            "pairwise-chamfer-distance-within-the-cohort.svg",
            "surface-area.svg"
        ]
    );
}

#[test]
fn the_bundled_model_report_shows_its_stored_evaluation() {
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/default");
    let eval: serde_json::Value =
        serde_json::from_slice(&std::fs::read(model.join("evaluation.json")).unwrap()).unwrap();
    let n = eval["shapes"].as_array().unwrap().len();
    let floor = eval["sampling_floor_median"].as_f64().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("model.html");
    run(ReportArgs {
        model: Some(model),
        ..args(&out)
    })
    .unwrap();
    let html = std::fs::read_to_string(&out).unwrap();
    assert!(html.contains(&format!("<td>training shapes</td><td>{n}</td>")));
    assert!(html.contains(&format!("(n = {n})")));
    let floor_text = aortagen::report::plot::tick(floor);
    assert!(
        html.contains(&format!("sampling floor (median) = {floor_text}")),
        "{floor_text}"
    );
}

#[test]
fn a_model_without_evaluation_says_how_to_make_one() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.html");
    let err = run(ReportArgs {
        model: Some(dir.path().to_path_buf()),
        ..args(&out)
    })
    .unwrap_err();
    assert!(format!("{err:#}").contains("aortagen evaluate"), "{err:#}");
    assert!(!out.exists());
}

fn generate(model: &Path, out: &Path, units: Units) {
    aortagen::cli::generate::run(GenerateArgs {
        model: model.to_path_buf(),
        arity: Some(2),
        sampler: Default::default(),
        weights: None,
        weighting: Weighting::Dirichlet,
        selection: Selection::Uniform,
        anchors: Vec::new(),
        latent_noise: 0.0,
        min_novelty: None,
        targets: Vec::new(),
        max_candidates: 1,
        novelty_points: 2_000,
        count: 3,
        seed: 11,
        resolution: 32,
        format: MeshFormat::Ply,
        units,
        out: out.to_path_buf(),
        backend: Backend::default(),
        extraction: ExtractionMethod::Fast,
        simulation: Default::default(),
    })
    .unwrap();
}

/// The same cohort written in mm and in unit-ball coordinates has the same pairwise
/// distances (the comparison brings both into the model's unit ball), and the novelty it
/// reports is the one recorded beside each shape.
#[test]
fn compare_reads_cohorts_in_either_units_and_their_recorded_novelty() {
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/default");
    let dir = tempfile::tempdir().unwrap();
    let (mm, unit) = (dir.path().join("mm"), dir.path().join("unit"));
    generate(&model, &mm, Units::Mm);
    generate(&model, &unit, Units::Unit);
    let (out, json) = (dir.path().join("c.html"), dir.path().join("c.json"));
    aortagen::cli::compare::run(CompareArgs {
        cohorts: vec![("in mm".into(), mm), ("in unit".into(), unit.clone())],
        training_model: Some(model.clone()),
        resolution: 32,
        points: 3_000,
        seed: 5,
        out: out.clone(),
        json: Some(json.clone()),
        svg_dir: None,
    })
    .unwrap();
    let numbers: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let (training, cohorts) = numbers.as_array().unwrap().split_first().unwrap();
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(model.join("manifest.json")).unwrap()).unwrap();
    let shapes = manifest["shapes"].as_array().unwrap().len();
    assert_eq!(
        training["shapes"], shapes,
        "one reconstruction per training shape"
    );
    assert_eq!(training["pairwise"]["n"], shapes * (shapes - 1) / 2);
    assert!(
        training["novelty"].is_null(),
        "training shapes have no novelty"
    );
    assert_eq!(cohorts.len(), 2);
    for c in cohorts {
        assert_eq!(c["shapes"], 3);
        assert_eq!(c["pairwise"]["n"], 3, "3 shapes have 3 pairs");
        assert_eq!(c["novelty"]["n"], 3);
    }
    let median = |i: usize, what: &str| cohorts[i][what]["median"].as_f64().unwrap();
    assert!(median(0, "pairwise") > 0.0);
    let pairwise = (median(0, "pairwise"), median(1, "pairwise"));
    assert!(
        (pairwise.0 - pairwise.1).abs() <= 1e-4 * pairwise.1,
        "{pairwise:?}"
    );
    let mut recorded: Vec<f64> = (0..3)
        .map(|i| {
            let path = unit.join(format!("shape_{i:04}.json"));
            let p: serde_json::Value =
                serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
            p["novelty"]["chamfer"].as_f64().unwrap()
        })
        .collect();
    recorded.sort_by(f64::total_cmp);
    assert_eq!(median(1, "novelty"), recorded[1]);
    let html = std::fs::read_to_string(&out).unwrap();
    assert!(
        html.contains("Pairwise Chamfer distance within each cohort") && html.contains("in unit")
    );
}
