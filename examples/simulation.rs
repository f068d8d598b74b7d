//! Writes simulation-ready meshes: a surface (a mesh file in mm, or by default a parametric
//! aortic root) cut open at its labelled openings, capped, optionally flow-extended and
//! remeshed, in every simulation format with sidecar JSON, and prints what each step took.
//!
//! ```text
//! cargo run --release --example simulation -- --out /tmp/sim
//! cargo run --release --example simulation -- --input shape.ply --remesh 1.0 --out /tmp/sim
//! ```
//! `tests/simulation/check_readers.sh` uses it to make the files it reads with VTK and meshio.

use std::path::PathBuf;
use std::time::Instant;

use aortagen::formats::{MeshMetadata, read_mesh_file};
use aortagen::simulation::{ShapeKind, SimulationOptions, simulation_mesh, write_all};
use clap::Parser;

#[derive(Debug, Parser)]
struct Args {
    /// Input surface in mm (default: parametric root 0 of seed 1).
    #[arg(long)]
    input: Option<PathBuf>,
    /// Opening rules: root, aorta or tube (default: decided from the shape).
    #[arg(long)]
    kind: Option<String>,
    /// Target edge length of an isotropic remesh, mm.
    #[arg(long)]
    remesh: Option<f64>,
    /// Flow-extension length in diameters.
    #[arg(long, default_value_t = 0.0)]
    extension: f64,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// File name stem.
    #[arg(long, default_value = "shape")]
    stem: String,
    /// Also draw the capped mesh with its faces coloured by id into this PNG.
    #[arg(long)]
    picture: Option<PathBuf>,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let started = Instant::now();
    let mesh = match &args.input {
        Some(path) => read_mesh_file(path)?,
        None => aortagen::synth::generate_root(1, 0, true).1,
    };
    let read_s = started.elapsed().as_secs_f64();
    let kind = match args.kind.as_deref() {
        None => None,
        Some("root") => Some(ShapeKind::Root),
        Some("aorta") => Some(ShapeKind::Aorta),
        Some("tube") => Some(ShapeKind::Tube),
        Some(other) => anyhow::bail!("unknown kind {other:?} (root, aorta or tube)"),
    };
    let opts = SimulationOptions {
        kind,
        extension_diameters: args.extension,
        remesh_mm: args.remesh,
        ..Default::default()
    };
    let t = Instant::now();
    let sim = simulation_mesh(&mesh, &opts)?;
    let build_s = t.elapsed().as_secs_f64();
    std::fs::create_dir_all(&args.out)?;
    let t = Instant::now();
    let mut meta = MeshMetadata::new("mm");
    meta.extras =
        serde_json::json!({"source": args.input.as_ref().map(|p| p.display().to_string())});
    let files = write_all(&args.out, &args.stem, &sim, &meta)?;
    let write_s = t.elapsed().as_secs_f64();
    if let Some(png) = &args.picture {
        // Seen from above and from below, side by side, so that every cap shows.
        let side = 700;
        let views = [35.0, -35.0].map(|elevation_deg| aortagen::render::View {
            azimuth_deg: -30.0,
            elevation_deg,
            ..Default::default()
        });
        let mut halves = Vec::new();
        for view in &views {
            let m = &sim.capped;
            halves.push(aortagen::render::render_labelled(
                &m.mesh,
                &m.face_ids,
                side,
                side,
                view,
            )?);
        }
        let row = 3 * side as usize;
        let pixels = (0..side as usize)
            .flat_map(|y| {
                halves
                    .iter()
                    .flat_map(move |h| h.pixels[y * row..(y + 1) * row].to_vec())
            })
            .collect();
        let image = aortagen::render::RgbImage {
            width: 2 * side,
            height: side,
            pixels,
        };
        std::fs::write(png, aortagen::render::encode_png(&image)?)?;
    }
    let summary = serde_json::json!({
        "input_triangles": mesh.triangle_count(),
        "kind": sim.kind,
        "faces": sim.faces.iter().map(|f| (&f.name, f.equivalent_diameter_mm)).collect::<Vec<_>>(),
        "triangles": sim.capped.mesh.triangle_count(),
        "watertight": sim.quality.manifold.watertight,
        "self_intersections": sim.quality.self_intersections,
        "share_min_angle_20": sim.quality.share_min_angle_20,
        "remesh": sim.remesh,
        "seconds": {"read": read_s, "simulation_mesh": build_s, "write_all_formats": write_s},
        "files": files.len(),
    });
    println!("{}", serde_json::to_string_pretty(&summary)?);
    Ok(())
}
