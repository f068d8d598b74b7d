//! `aortagen render`: draws meshes side by side into a PNG.

use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::geometry::TriMesh;
use crate::render::{View, encode_png, render_meshes};

/// Render meshes side by side (orthographic, shaded) into a PNG picture.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// Mesh files, drawn in order (row by row).
    #[arg(required = true)]
    pub meshes: Vec<PathBuf>,
    /// Output PNG path.
    #[arg(long)]
    pub out: PathBuf,
    /// Image width in pixels.
    #[arg(long, default_value_t = 1600)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 600)]
    pub height: u32,
    /// Camera azimuth about the up axis, degrees.
    #[arg(long, default_value_t = View::default().azimuth_deg, allow_negative_numbers = true)]
    pub azimuth: f64,
    /// Camera elevation, degrees.
    #[arg(long, default_value_t = View::default().elevation_deg, allow_negative_numbers = true)]
    pub elevation: f64,
    /// Meshes per row (default: the grid that draws them largest).
    #[arg(long)]
    pub columns: Option<usize>,
}

/// Reads a mesh file. Binary PLY is read natively; other formats need the general readers.
pub fn read_mesh(path: &Path) -> anyhow::Result<TriMesh> {
    Ok(crate::formats::read_mesh_file(path)?)
}

/// Runs the command.
pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    let meshes = args
        .meshes
        .iter()
        .map(|p| read_mesh(p))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let refs: Vec<&TriMesh> = meshes.iter().collect();
    let view = View {
        azimuth_deg: args.azimuth,
        elevation_deg: args.elevation,
        columns: args.columns,
        ..View::default()
    };
    let image = render_meshes(&refs, args.width, args.height, &view).context("rendering")?;
    let png = encode_png(&image)?;
    std::fs::write(&args.out, &png).with_context(|| format!("writing {}", args.out.display()))?;
    tracing::info!(out = %args.out.display(), bytes = png.len(), "picture written");
    Ok(())
}
