//! `aortagen report` on a directory of meshes and on the bundled model.

use std::path::Path;

use aortagen::cli::report::{ReportArgs, run};
use aortagen::formats::{MeshMetadata, write_mesh_file};
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
