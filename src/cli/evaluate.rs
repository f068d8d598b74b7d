//! `aortagen evaluate`: reconstruction fidelity of every training shape (Chamfer distance).

use std::path::{Path, PathBuf};

use anyhow::{Context, ensure};

use super::progress::{init_logging, terminal_bar};
use crate::formats::{MeshMetadata, write_mesh_file};
use crate::geometry::TriMesh;
use crate::geometry::chamfer::DEFAULT_CHAMFER_POINTS;
use crate::render::{MAX_SIDE, View, encode_png, render_meshes};
use crate::sdf::backend::Backend;
use crate::sdf::data::DataSource;
use crate::sdf::data::holdout::load_split;
use crate::sdf::inference::evaluation::{
    CHAMFER_UNITS, EvaluationReport, EvaluationSettings, HeldOutEvaluation, evaluate_model,
};
use crate::sdf::inference::reconstruct::{EVALUATION_RESOLUTION, reconstruct};
use crate::sdf::inference::reconstruct::{ExtractionMethod, MAX_RESOLUTION, MIN_RESOLUTION};
use crate::sdf::store::LoadedModel;
use crate::sdf::training::fit::DEFAULT_FIT_ITERATIONS;
use crate::sdf::training::heldout::evaluate_heldout;

/// Reconstruct each training shape from its latent and compare it with the original.
#[derive(Debug, clap::Args)]
pub struct EvaluateArgs {
    /// Model directory written by `aortagen train`.
    #[arg(long)]
    pub model: PathBuf,
    /// Directory of the original meshes (default: the training source in the manifest).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Grid samples per axis over [-1,1]³.
    #[arg(long, default_value_t = EVALUATION_RESOLUTION)]
    pub resolution: usize,
    /// Points sampled on each surface for the Chamfer distance.
    #[arg(long, default_value_t = DEFAULT_CHAMFER_POINTS)]
    pub points: usize,
    /// Seed of the Chamfer samplings.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Also write the full report (per-shape CD, quantiles, histogram, floor) as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also write the worst-reconstructed shapes here: each original and its reconstruction
    /// as PLY in mesh units, and `worst.png` with the originals above their reconstructions.
    #[arg(long)]
    pub worst: Option<PathBuf>,
    /// How many of the worst shapes --worst shows (1–256, checked with --worst; the
    /// picture's cells shrink below 480 px when more than 17 are shown).
    #[arg(long, default_value_t = 3)]
    pub worst_count: usize,
    /// Adam steps of each held-out shape's fit (models trained with --holdout; 0 skips
    /// the held-out shapes).
    #[arg(long, default_value_t = DEFAULT_FIT_ITERATIONS)]
    pub heldout_iterations: usize,
    /// Compute backend.
    #[arg(long, default_value = "flex")]
    pub backend: Backend,
    /// Surface extraction: `fast` evaluates the network only near the surface, `dense` on
    /// every grid sample (the reference; both give the same mesh).
    #[arg(long, value_enum, default_value = "fast")]
    pub extraction: ExtractionMethod,
}

/// Runs `aortagen evaluate`.
pub fn run(args: EvaluateArgs) -> anyhow::Result<()> {
    init_logging();
    ensure!(
        (MIN_RESOLUTION..=MAX_RESOLUTION).contains(&args.resolution),
        "--resolution must be between {MIN_RESOLUTION} and {MAX_RESOLUTION}"
    );
    ensure!(args.points >= 1, "--points must be at least 1");
    ensure!(
        args.worst.is_none() || (1..=MAX_WORST_COUNT).contains(&args.worst_count),
        "--worst-count must be between 1 and {MAX_WORST_COUNT}, got {}",
        args.worst_count
    );
    let model = LoadedModel::load(&args.model, args.backend)?;
    let source = match &args.data {
        Some(path) => DataSource::Directory { path: path.clone() },
        None => model.manifest.data.source.clone(),
    };
    let split = load_split(&source, model.manifest.data.holdout.as_ref())?;
    let originals: Vec<_> = split.training.into_iter().map(|(_, mesh)| mesh).collect();
    let settings = EvaluationSettings {
        resolution: args.resolution,
        chamfer_points: args.points,
        seed: args.seed,
        extraction: args.extraction,
    };
    let bar = terminal_bar(originals.len() as u64, "shapes");
    let report = evaluate_model(&model, &originals, &settings, &mut |shape| match (
        &bar,
        shape.chamfer,
    ) {
        (Some(bar), _) => bar.inc(1),
        (None, Some(cd)) => tracing::info!(shape = %shape.name, chamfer = cd, "reconstructed"),
        (None, None) => {
            tracing::warn!(shape = %shape.name, error = ?shape.error, "reconstruction failed");
        }
    })?;
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    let mut report = report;
    if !split.heldout.is_empty() && args.heldout_iterations > 0 {
        report.heldout = Some(fit_heldout(&model, &split.heldout, &args, &settings));
    }
    print_summary(&report);
    if let Some(path) = &args.json {
        let json = serde_json::to_vec_pretty(&report)?;
        std::fs::write(path, json).with_context(|| format!("cannot write {}", path.display()))?;
        println!("report written to {}", path.display());
    }
    if let Some(dir) = &args.worst {
        write_worst(
            dir,
            args.worst_count,
            &model,
            &originals,
            &report,
            &settings,
        )?;
        println!(
            "worst {} reconstructions written to {}",
            args.worst_count.min(report.shapes.len() - report.failures),
            dir.display()
        );
    }
    Ok(())
}

/// Fits the held-out shapes with the network frozen, with a progress bar or log lines.
fn fit_heldout(
    model: &LoadedModel,
    heldout: &[(String, TriMesh)],
    args: &EvaluateArgs,
    settings: &EvaluationSettings,
) -> HeldOutEvaluation {
    let bar = terminal_bar(heldout.len() as u64, "held-out fits");
    let evaluation = evaluate_heldout(
        model,
        heldout,
        args.heldout_iterations,
        settings,
        None,
        &mut |shape, _| match (&bar, shape.chamfer) {
            (Some(bar), _) => bar.inc(1),
            (None, Some(cd)) => {
                tracing::info!(shape = %shape.name, chamfer = cd, "held-out shape fitted")
            }
            (None, None) => {
                tracing::warn!(shape = %shape.name, error = ?shape.error, "held-out fit failed")
            }
        },
    );
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    evaluation
}

/// Most shapes `worst.png` shows: its width holds one cell of at least 32 px per shape.
pub const MAX_WORST_COUNT: usize = (MAX_SIDE / 32) as usize;

/// Side of one cell of `worst.png`, px, for `count` cells in a row (1..=[`MAX_WORST_COUNT`]):
/// 480, or less so the row fits the largest image the renderer draws.
fn worst_cell_side(count: usize) -> u32 {
    480.min(MAX_SIDE / count as u32)
}

/// Writes the `count` shapes of largest Chamfer distance, worst first, as
/// `{rank}_{name}_original.ply` / `_reconstruction.ply` (mesh units) and `worst.png`.
fn write_worst(
    dir: &Path,
    count: usize,
    model: &LoadedModel,
    originals: &[TriMesh],
    report: &EvaluationReport,
    settings: &EvaluationSettings,
) -> anyhow::Result<()> {
    let mut ranked: Vec<(f64, usize, &str)> = report
        .shapes
        .iter()
        .filter_map(|s| s.chamfer.map(|cd| (cd, s.index, s.name.as_str())))
        .collect();
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
    ranked.truncate(count);
    if ranked.is_empty() {
        return Ok(());
    }
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let latents = model.latents();
    let mut reconstructions = Vec::with_capacity(ranked.len());
    for (rank, &(cd, index, name)) in ranked.iter().enumerate() {
        let transform = &model.manifest.shapes[index].transform;
        let field = model.field(&latents[index])?;
        let unit = reconstruct(&field, settings.resolution, settings.extraction)?.mesh;
        let mesh = transform.mesh_to_mesh_units(&unit);
        let stem = format!("{}_{}", rank + 1, file_stem(name));
        let meta = MeshMetadata {
            extras: serde_json::json!({ "shape": name, "index": index, "chamfer": cd }),
            ..MeshMetadata::new("mm")
        };
        write_mesh_file(
            &dir.join(format!("{stem}_original.ply")),
            &originals[index],
            &meta,
        )?;
        write_mesh_file(
            &dir.join(format!("{stem}_reconstruction.ply")),
            &mesh,
            &meta,
        )?;
        reconstructions.push(mesh);
    }
    let shown: Vec<&TriMesh> = ranked
        .iter()
        .map(|&(_, index, _)| &originals[index])
        .chain(&reconstructions)
        .collect();
    let view = View {
        columns: Some(ranked.len()),
        ..View::default()
    };
    let side = worst_cell_side(ranked.len());
    let image = render_meshes(&shown, side * ranked.len() as u32, 2 * side, &view)?;
    let path = dir.join("worst.png");
    std::fs::write(&path, encode_png(&image)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

/// A shape name usable in a file name (its path separators and dots replaced).
fn file_stem(name: &str) -> String {
    let stem = name.rsplit_once('.').map_or(name, |(stem, _)| stem);
    stem.chars()
        .map(|c| {
            if c.is_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn print_summary(report: &EvaluationReport) {
    let s = &report.settings;
    println!(
        "model {}: {} shapes, grid {}³, {} points per surface",
        report.model_id,
        report.shapes.len(),
        s.resolution,
        s.chamfer_points
    );
    println!("Chamfer distance in {CHAMFER_UNITS}:");
    match &report.summary {
        Some(q) => println!(
            "  median {:.3e}  mean {:.3e}  q25 {:.3e}  q75 {:.3e}  q90 {:.3e}  min {:.3e}  max {:.3e}",
            q.median, q.mean, q.q25, q.q75, q.q90, q.min, q.max
        ),
        None => println!("  no shape could be reconstructed"),
    }
    println!(
        "  sampling floor (two samplings of the same original, median): {:.3e}",
        report.sampling_floor_median
    );
    if let Some(h) = &report.heldout {
        println!(
            "held-out shapes ({}, fitted with the network frozen, {} steps):",
            h.shapes.len(),
            h.iterations
        );
        match &h.summary {
            Some(q) => println!(
                "  median {:.3e}  mean {:.3e}  q25 {:.3e}  q75 {:.3e}  max {:.3e}; floor {:.3e}",
                q.median, q.mean, q.q25, q.q75, q.max, h.sampling_floor_median
            ),
            None => println!("  no held-out shape could be fitted"),
        }
    }
    if report.failures > 0 {
        println!("  {} shapes gave no surface:", report.failures);
        for shape in report.shapes.iter().filter(|s| s.chamfer.is_none()) {
            println!(
                "    {}: {}",
                shape.name,
                shape.error.as_deref().unwrap_or("?")
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_worst_picture_fits_the_renderer_for_every_allowed_count() {
        assert_eq!(worst_cell_side(2), 480);
        for count in 1..=MAX_WORST_COUNT {
            let side = worst_cell_side(count);
            assert!(side >= 32, "{count}: {side} px");
            assert!(
                side as usize * count <= MAX_SIDE as usize,
                "{count}: {side} px"
            );
        }
    }
}
