//! The `synth` and `render` commands end to end, in a temporary directory.

use aortagen::cli::render::{RenderArgs, read_mesh};
use aortagen::cli::synth::{SynthArgs, SynthFormat};
use aortagen::synth::{AorticRootParams, generate_root};

fn synth_args(out: &std::path::Path, format: SynthFormat) -> SynthArgs {
    SynthArgs {
        count: 2,
        seed: 8,
        out: out.to_path_buf(),
        open: true,
        closed: false,
        format,
    }
}

#[test]
fn synth_writes_meshes_ground_truth_and_manifest() {
    let dir = tempfile::tempdir().unwrap();
    aortagen::cli::synth::run(synth_args(dir.path(), SynthFormat::Ply)).unwrap();
    for i in 0..2 {
        let (params, mesh) = generate_root(8, i, false);
        let read = read_mesh(&dir.path().join(format!("root_00{i}.ply"))).unwrap();
        assert_eq!(read.positions, mesh.positions);
        assert_eq!(read.triangles, mesh.triangles);
        let json: serde_json::Value = serde_json::from_slice(
            &std::fs::read(dir.path().join(format!("root_00{i}.json"))).unwrap(),
        )
        .unwrap();
        let recorded: AorticRootParams = serde_json::from_value(json["params"].clone()).unwrap();
        // serde_json parses floats to within an ulp unless `float_roundtrip` is enabled.
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
        assert!(close(recorded.stj_diameter_mm, params.stj_diameter_mm));
        assert!(close(recorded.sinus_diameter_mm, params.sinus_diameter_mm));
        assert!(close(recorded.bend_radius_mm, params.bend_radius_mm));
        assert_eq!(
            recorded.lobe_scales.map(|x| (x * 1e9).round()),
            params.lobe_scales.map(|x| (x * 1e9).round())
        );
        assert_eq!(json["units"], "mm");
        assert_eq!(json["closed"], false);
    }
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["seed"], 8);
    assert_eq!(manifest["count"], 2);
    assert_eq!(manifest["version"], aortagen::VERSION);
    assert_eq!(manifest["files"][1], "root_001.ply");
}

#[test]
fn every_format_is_written_and_reads_back_with_the_same_triangles() {
    for format in [
        SynthFormat::Ply,
        SynthFormat::Stl,
        SynthFormat::Obj,
        SynthFormat::Glb,
    ] {
        let dir = tempfile::tempdir().unwrap();
        let mut args = synth_args(dir.path(), format);
        (args.open, args.closed) = (false, true);
        aortagen::cli::synth::run(args).unwrap();
        let path = dir.path().join(format!("root_000.{}", format.extension()));
        let mesh = aortagen::formats::read_mesh_file(&path).unwrap();
        assert!(mesh.edge_report().is_closed_and_oriented(), "{path:?}");
        assert!(mesh.triangle_count() >= 20_000, "{path:?}");
    }
}

#[test]
fn a_zero_count_fails_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let mut zero = synth_args(dir.path(), SynthFormat::Ply);
    zero.count = 0;
    assert!(format!("{:#}", aortagen::cli::synth::run(zero).unwrap_err()).contains("--count"));
    assert!(!dir.path().join("manifest.json").exists());
}

#[test]
fn render_draws_written_meshes_into_a_png_of_the_requested_size() {
    let dir = tempfile::tempdir().unwrap();
    aortagen::cli::synth::run(synth_args(dir.path(), SynthFormat::Ply)).unwrap();
    let out = dir.path().join("roots.png");
    aortagen::cli::render::run(RenderArgs {
        meshes: vec![
            dir.path().join("root_000.ply"),
            dir.path().join("root_001.ply"),
        ],
        out: out.clone(),
        width: 120,
        height: 80,
        azimuth: -60.0,
        elevation: 15.0,
        columns: None,
    })
    .unwrap();
    let reader = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&out).unwrap()))
        .read_info()
        .unwrap();
    assert_eq!((reader.info().width, reader.info().height), (120, 80));
    let missing = aortagen::cli::render::run(RenderArgs {
        meshes: vec![dir.path().join("nope.ply")],
        out,
        width: 10,
        height: 10,
        azimuth: 0.0,
        elevation: 0.0,
        columns: None,
    })
    .unwrap_err();
    assert!(format!("{missing:#}").contains("nope.ply"), "{missing:#}");
}
