//! `aortagen mesh --capped|--open` end to end on a synthetic root in a temporary
//! directory: the labelled file and its sidecar, the face table against the library's
//! pipeline on the same surface, and flags refused with their names.

use aortagen::cli::mesh::{MeshArgs, run};
use aortagen::cli::simulate::SimulationFlags;
use aortagen::formats::{MeshFormat, MeshMetadata, load_mesh_file, write_mesh};
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
