//! `aortagen mesh --capped|--open` and `aortagen generate --simulation` end to end in a
//! temporary directory: the labelled file and its sidecar, the face table against the
//! library's pipeline on the same surface, and flags refused with their names.

use aortagen::cli::generate::{GenerateArgs, Units};
use aortagen::cli::mesh::{MeshArgs, run};
use aortagen::cli::simulate::{GenerateSimulation, SimulationFlags};
use aortagen::cohort::{Selection, Weighting};
use aortagen::formats::{MeshFormat, MeshMetadata, load_mesh_file, write_mesh};
use aortagen::sdf::backend::Backend;
use aortagen::sdf::inference::reconstruct::ExtractionMethod;
use aortagen::simulation::{SimulationOptions, simulation_mesh};

fn args(file: &std::path::Path, simulation: SimulationFlags) -> MeshArgs {
    MeshArgs {
        file: file.to_path_buf(),
        json: true,
        convert: None,
        units: None,
        simulation,
    }
}

fn root_stl(dir: &std::path::Path) -> std::path::PathBuf {
    let (_, root) = aortagen::synth::generate_root(99, 0, true);
    let path = dir.join("root.stl");
    let stl = write_mesh(&root, MeshFormat::Stl, &MeshMetadata::new("mm")).unwrap();
    std::fs::write(&path, stl).unwrap();
    path
}

#[test]
fn a_capped_vtp_and_its_sidecar_match_the_pipeline_on_the_same_surface() {
    let dir = tempfile::tempdir().unwrap();
    let stl = root_stl(dir.path());
    let flags = SimulationFlags {
        capped: true,
        format: Some("vtp".into()),
        ..Default::default()
    };
    run(args(&stl, flags)).unwrap();
    let vtp = dir.path().join("root_capped.vtp");
    let text = std::fs::read_to_string(&vtp).unwrap();
    assert!(text.contains("ModelFaceID"));
    let sidecar: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("root_capped.vtp.json")).unwrap())
            .unwrap();
    let loaded = load_mesh_file(&stl).unwrap();
    let direct = simulation_mesh(&loaded.mesh, &SimulationOptions::default()).unwrap();
    assert_eq!(sidecar["faces"], serde_json::json!(direct.faces));
    let names: Vec<&str> = direct.faces.iter().map(|f| f.name.as_str()).collect();
    assert!(
        names.contains(&"inlet") && names.contains(&"outlet"),
        "{names:?}"
    );
    assert_eq!(sidecar["variant"], "capped");
}

#[test]
fn an_open_stl_has_one_solid_and_stray_or_bad_flags_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let stl = root_stl(dir.path());
    let out = dir.path().join("wall.stl");
    let flags = SimulationFlags {
        open: true,
        format: Some("stl".into()),
        out: Some(out.clone()),
        ..Default::default()
    };
    run(args(&stl, flags)).unwrap();
    let text = std::fs::read_to_string(&out).unwrap();
    assert_eq!(text.matches("endsolid").count(), 1);
    assert!(dir.path().join("wall.stl.json").exists());

    let stray = SimulationFlags {
        remesh_mm: Some(1.0),
        ..Default::default()
    };
    let e = run(args(&stl, stray)).unwrap_err().to_string();
    assert!(e.contains("--remesh-mm") && e.contains("--capped"), "{e}");
    let out_of_range = SimulationFlags {
        capped: true,
        remesh_mm: Some(50.0),
        ..Default::default()
    };
    let e = run(args(&stl, out_of_range)).unwrap_err().to_string();
    assert!(e.starts_with("--remesh-mm"), "{e}");
    let beyond = SimulationFlags {
        capped: true,
        outlet_above_stj_mm: Some(190.0),
        ..Default::default()
    };
    let e = format!("{:#}", run(args(&stl, beyond)).unwrap_err());
    assert!(e.contains("--outlet-above-stj-mm"), "{e}");
}

fn generate_args(out: &std::path::Path, simulation: GenerateSimulation) -> GenerateArgs {
    GenerateArgs {
        model: std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models/default"),
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
        novelty_points: 500,
        count: 1,
        seed: 5,
        resolution: 64,
        format: MeshFormat::Glb,
        units: Units::Mm,
        out: out.to_path_buf(),
        backend: Backend::default(),
        extraction: ExtractionMethod::Fast,
        simulation,
    }
}

#[test]
fn generate_writes_each_shapes_simulation_mesh_beside_it_and_checks_flags_first() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cohort");
    let simulation = GenerateSimulation {
        simulation: Some("capped".into()),
        simulation_format: Some("obj".into()),
        ..Default::default()
    };
    aortagen::cli::generate::run(generate_args(&out, simulation)).unwrap();
    let sidecar: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("shape_0000_capped.obj.json")).unwrap())
            .unwrap();
    let obj = std::fs::read_to_string(out.join("shape_0000_capped.obj")).unwrap();
    assert_eq!(
        obj.matches("\ng ").count(),
        3,
        "wall, inlet and outlet groups"
    );
    let shape = load_mesh_file(&out.join("shape_0000.glb")).unwrap();
    let direct = simulation_mesh(&shape.mesh, &SimulationOptions::default()).unwrap();
    assert_eq!(sidecar["faces"], serde_json::json!(direct.faces));

    let bad = GenerateSimulation {
        simulation: Some("capped".into()),
        remesh_mm: Some(50.0),
        ..Default::default()
    };
    let elsewhere = dir.path().join("never");
    let e = aortagen::cli::generate::run(generate_args(&elsewhere, bad)).unwrap_err();
    assert!(e.to_string().starts_with("--remesh-mm"), "{e}");
    assert!(!elsewhere.exists(), "refused before generating");
}
