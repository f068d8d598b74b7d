//! `aortagen validate` on files: a cohort directory against a directory of meshes (both
//! levels, JSON, HTML and SVGs written), against a SIMCor-style measurements table (the
//! measurement level only, the table's values read exactly, unmeasured columns set aside)
//! and against a table whose units are wrong (refused, naming the column).

use std::path::{Path, PathBuf};

use aortagen::cli::validate::{ValidateArgs, run};
use aortagen::formats::{MeshMetadata, write_mesh_file};
use aortagen::synth::generate_root;
use aortagen::validation::ValidationReport;

/// Writes `n` parametric roots of draw `seed` into `dir` as PLY meshes in mm.
fn mesh_dir(dir: &Path, seed: u64, n: u64) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    for i in 0..n {
        let (_, mesh) = generate_root(seed, i, true);
        let path = dir.join(format!("root_{i:02}.ply"));
        write_mesh_file(&path, &mesh, &MeshMetadata::default()).unwrap();
    }
    dir.to_path_buf()
}

fn args(cohort: PathBuf, reference: &Path, json: PathBuf) -> ValidateArgs {
    ValidateArgs {
        cohort,
        reference: reference.display().to_string(),
        model: None,
        data: None,
        criteria: None,
        context_of_use: Some("device sizing".into()),
        question: None,
        points: 500,
        scale_mm: Some(40.0),
        subsets: 20,
        resamples: 100,
        discount: "0.8".into(),
        seed: 1,
        json: Some(json),
        out: None,
        svg_dir: None,
    }
}

fn read_report(path: &Path) -> ValidationReport {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn a_cohort_directory_against_reference_meshes_writes_both_levels() {
    let dir = tempfile::tempdir().unwrap();
    let cohort = mesh_dir(&dir.path().join("cohort"), 1, 8);
    let reference = mesh_dir(&dir.path().join("reference"), 2, 6);
    let (json, html, svgs) = (
        dir.path().join("report.json"),
        dir.path().join("report.html"),
        dir.path().join("svg"),
    );
    run(ValidateArgs {
        criteria: Some(r#"{"nna_max": 0.9}"#.into()),
        out: Some(html.clone()),
        svg_dir: Some(svgs.clone()),
        ..args(cohort, &reference, json.clone())
    })
    .unwrap();
    let report = read_report(&json);
    assert_eq!(report.dossier.cohort.shapes, 8);
    assert_eq!(report.dossier.reference.shapes, 6);
    assert_eq!(
        report.dossier.context_of_use.as_deref(),
        Some("device sizing")
    );
    let shapes = report.shapes.as_ref().expect("meshes give the shape level");
    let pairwise = shapes.pairwise.as_ref().unwrap();
    // 8 cohort shapes have 28 pairs, 6 reference shapes 15.
    assert_eq!((pairwise.cohort.count, pairwise.reference.count), (28, 15));
    assert!(shapes.nna.is_some());
    assert!(report.checks.iter().any(|c| c.criterion == "nna_max"));
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(page.contains("device sizing"));
    let written = std::fs::read_dir(&svgs).unwrap().count();
    assert!(written >= report.features.len(), "{written} SVG files");
}

#[test]
fn a_simcor_table_is_compared_at_the_measurement_level_with_its_exact_values() {
    let dir = tempfile::tempdir().unwrap();
    let cohort = mesh_dir(&dir.path().join("cohort"), 1, 6);
    let table = dir.path().join("patients.csv");
    // R's write.csv2: semicolons, decimal commas; D_lvot is SIMCor's, not measured here.
    std::fs::write(
        &table,
        "patient;D_an [mm];D_lvot\nP1;22,5;20\nP2;24,0;21\nP3;NA;19\nP4;25,5;22\n",
    )
    .unwrap();
    let json = dir.path().join("report.json");
    run(args(cohort, &table, json.clone())).unwrap();
    let report = read_report(&json);
    assert!(report.shapes.is_none());
    assert!(report.not_computed.contains_key("shapes"));
    assert_eq!(report.dossier.reference.kind, "measurements");
    assert_eq!(report.features.len(), 1, "only the annulus is in both");
    let annulus = &report.features[0];
    assert_eq!(annulus.feature.name(), "annulus_mm");
    // P3's missing value is left out: (22.5 + 24 + 25.5) / 3.
    let reference = annulus.reference.as_ref().unwrap();
    assert_eq!(reference.count, 3);
    assert!((reference.mean - 24.0).abs() < 1e-12, "{}", reference.mean);
    assert!(
        report.not_compared.contains_key("D_lvot"),
        "{:?}",
        report.not_compared
    );
}

#[test]
fn a_table_in_the_wrong_unit_is_refused_naming_the_column() {
    let dir = tempfile::tempdir().unwrap();
    let cohort = mesh_dir(&dir.path().join("cohort"), 1, 3);
    let table = dir.path().join("patients.csv");
    std::fs::write(&table, "id,D_an [cm]\na,2.2\nb,2.4\n").unwrap();
    let err = run(args(cohort, &table, dir.path().join("r.json"))).unwrap_err();
    let message = format!("{err:#}");
    assert!(message.contains("columns[D_an [cm]]"), "{message}");
    assert!(message.contains("mm"), "{message}");
}
