//! `aortagen synth`: writes a cohort of parametric aortic roots with their ground-truth
//! parameters and a manifest.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, bail};
use rayon::prelude::*;
use serde::Serialize;

use crate::geometry::TriMesh;
use crate::synth::{AorticRootParams, generate_root};

/// Mesh file formats the command can be asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SynthFormat {
    /// Binary little-endian PLY.
    Ply,
    /// Binary STL.
    Stl,
    /// Wavefront OBJ.
    Obj,
    /// Binary glTF.
    Glb,
}

impl SynthFormat {
    /// File extension without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            Self::Ply => "ply",
            Self::Stl => "stl",
            Self::Obj => "obj",
            Self::Glb => "glb",
        }
    }
}

/// Generate parametric aortic roots (millimetres) drawn from published adult ranges.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Number of shapes.
    #[arg(long, default_value_t = 10)]
    pub count: usize,
    /// Random seed; shape i depends only on (seed, i).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Leave both ends open (non-watertight surfaces).
    #[arg(long, conflicts_with = "closed")]
    pub open: bool,
    /// Close both ends with flat caps (the default).
    #[arg(long)]
    pub closed: bool,
    /// Mesh file format.
    #[arg(long, value_enum, default_value_t = SynthFormat::Ply)]
    pub format: SynthFormat,
}

/// Ground truth written beside each mesh.
#[derive(Debug, Serialize)]
struct RootRecord<'a> {
    seed: u64,
    index: u64,
    closed: bool,
    units: &'static str,
    frame: &'static str,
    annulus_major_mm: f64,
    annulus_minor_mm: f64,
    vertices: usize,
    triangles: usize,
    params: &'a AorticRootParams,
}

/// Provenance of the whole cohort.
#[derive(Debug, Serialize)]
struct Manifest {
    generator: &'static str,
    version: &'static str,
    seed: u64,
    count: usize,
    closed: bool,
    format: SynthFormat,
    units: &'static str,
    files: Vec<String>,
}

const FRAME: &str = "annulus centre at the origin, outflow axis +z, annulus major axis +x";

/// Writes `mesh` to `path` in `format`, in millimetres.
pub fn write_mesh(path: &Path, mesh: &TriMesh, format: SynthFormat) -> anyhow::Result<()> {
    let format: crate::formats::MeshFormat = format.extension().parse()?;
    let mut meta = crate::formats::MeshMetadata::new("mm");
    meta.extras = serde_json::json!({ "source": "aortagen parametric aortic root" });
    let bytes = crate::formats::write_mesh(mesh, format, &meta)?;
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

/// Runs the command.
pub fn run(args: SynthArgs) -> anyhow::Result<()> {
    if args.count == 0 {
        bail!("--count must be at least 1");
    }
    let closed = !args.open;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output directory {}", args.out.display()))?;
    let digits = (args.count - 1).to_string().len().max(3);
    let name = |i: usize, ext: &str| format!("root_{i:0digits$}.{ext}");
    let progress = Progress::new(args.count);
    (0..args.count)
        .into_par_iter()
        .try_for_each(|i| -> anyhow::Result<()> {
            let (params, mesh) = generate_root(args.seed, i as u64, closed);
            let (major, minor) = params.annulus_axes_mm();
            let record = RootRecord {
                seed: args.seed,
                index: i as u64,
                closed,
                units: "mm",
                frame: FRAME,
                annulus_major_mm: major,
                annulus_minor_mm: minor,
                vertices: mesh.vertex_count(),
                triangles: mesh.triangle_count(),
                params: &params,
            };
            write_mesh(
                &args.out.join(name(i, args.format.extension())),
                &mesh,
                args.format,
            )?;
            let json_path = args.out.join(name(i, "json"));
            std::fs::write(&json_path, serde_json::to_vec_pretty(&record)?)
                .with_context(|| format!("writing {}", json_path.display()))?;
            progress.tick();
            Ok(())
        })?;
    progress.finish();

    let manifest = Manifest {
        generator: "aortagen synth",
        version: crate::VERSION,
        seed: args.seed,
        count: args.count,
        closed,
        format: args.format,
        units: "mm",
        files: (0..args.count)
            .map(|i| name(i, args.format.extension()))
            .collect(),
    };
    let path = args.out.join("manifest.json");
    std::fs::write(&path, serde_json::to_vec_pretty(&manifest)?)
        .with_context(|| format!("writing {}", path.display()))?;
    tracing::info!(count = args.count, seed = args.seed, out = %args.out.display(), "synthetic roots written");
    Ok(())
}

/// A progress bar on a terminal, periodic log lines otherwise.
struct Progress {
    total: usize,
    done: AtomicUsize,
    bar: Option<indicatif::ProgressBar>,
}

impl Progress {
    fn new(total: usize) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = indicatif::ProgressBar::new(total as u64);
            bar.set_style(
                indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} roots ({eta})")
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            bar
        });
        Self {
            total,
            done: AtomicUsize::new(0),
            bar,
        }
    }

    fn tick(&self) {
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        match &self.bar {
            Some(bar) => bar.inc(1),
            None if done.is_multiple_of((self.total / 10).max(1)) || done == self.total => {
                tracing::info!(done, total = self.total, "synth progress");
            }
            None => {}
        }
    }

    fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish();
        }
    }
}
