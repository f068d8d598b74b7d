//! `aortagen fit`: fits a latent to a new mesh for a trained model (network frozen) and keeps
//! it beside the model as an anchor (`anchors.json`).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context;

use super::progress::{init_logging, terminal_bar};
use crate::geometry::chamfer::DEFAULT_CHAMFER_POINTS;
use crate::sdf::backend::Backend;
use crate::sdf::inference::evaluation::CHAMFER_UNITS;
use crate::sdf::inference::reconstruct::EVALUATION_RESOLUTION;
use crate::sdf::store::LoadedModel;
use crate::sdf::store::anchors::{ANCHORS_FILE, Anchor, AnchorSet};
use crate::sdf::training::fit::{DEFAULT_FIT_ITERATIONS, FitSettings, fit_mesh};

/// Fit a latent code to a new mesh with the network frozen; store it as an anchor.
#[derive(Debug, clap::Args)]
pub struct FitArgs {
    /// Model directory written by `aortagen train`.
    #[arg(long)]
    pub model: PathBuf,
    /// The mesh to fit (STL, OBJ, PLY, glTF/GLB), in its own units.
    #[arg(long)]
    pub mesh: PathBuf,
    /// Adam steps on the latent.
    #[arg(long, default_value_t = DEFAULT_FIT_ITERATIONS)]
    pub iterations: usize,
    /// Seed of the surface sampling and of every batch.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Anchor name (default: the mesh file's stem); unique within the model.
    #[arg(long)]
    pub name: Option<String>,
    /// Also write the anchor, the settings and the loss history as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Grid samples per axis for the reconstruction that is scored.
    #[arg(long, default_value_t = EVALUATION_RESOLUTION)]
    pub resolution: usize,
    /// Points sampled on each surface for the Chamfer distance.
    #[arg(long, default_value_t = DEFAULT_CHAMFER_POINTS)]
    pub points: usize,
    /// Compute backend.
    #[arg(long, default_value = "flex")]
    pub backend: Backend,
}

/// Runs `aortagen fit`.
pub fn run(args: FitArgs) -> anyhow::Result<()> {
    init_logging();
    let model = LoadedModel::load(&args.model, args.backend)?;
    let mut anchors = AnchorSet::load(&args.model, &model.manifest)?;
    let mesh = crate::formats::read_mesh_file(&args.mesh)
        .with_context(|| format!("cannot read mesh {}", args.mesh.display()))?;
    mesh.validate()
        .with_context(|| format!("unusable mesh {}", args.mesh.display()))?;
    let name = match &args.name {
        Some(n) => n.clone(),
        None => args
            .mesh
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "anchor".into()),
    };
    anyhow::ensure!(
        !anchors.anchors.iter().any(|a| a.name == name),
        "the model already has an anchor named {name:?}; pass another --name"
    );
    let mut settings = FitSettings::new(args.seed);
    settings.iterations = args.iterations;
    settings.evaluation.resolution = args.resolution;
    settings.evaluation.chamfer_points = args.points;

    let stop = Arc::new(AtomicBool::new(false));
    let handler_stop = stop.clone();
    let _ = ctrlc::set_handler(move || handler_stop.store(true, Ordering::SeqCst));
    let bar = terminal_bar(args.iterations as u64, "steps");
    let log_every = (args.iterations / 20).max(1);
    let started = Instant::now();
    let fitted = fit_mesh(
        &model,
        &mesh,
        &settings,
        &mut |p| match &bar {
            Some(bar) => {
                bar.set_position(p.iteration as u64);
                bar.set_message(format!("loss {:.4}", p.loss.loss));
            }
            None if p.iteration % log_every == 0 || p.iteration == p.iterations => {
                tracing::info!(
                    step = p.iteration,
                    of = p.iterations,
                    loss = p.loss.loss,
                    "fitting"
                );
            }
            None => {}
        },
        Some(&stop),
    )?;
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    let seconds = started.elapsed().as_secs_f64();
    let anchor = Anchor {
        name: name.clone(),
        latent: fitted.latent.clone(),
        transform: fitted.transform,
        chamfer: fitted.chamfer,
        source: args
            .mesh
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        iterations: settings.iterations,
        seed: settings.seed,
        created_unix: SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
    };
    anchors.add(anchor.clone(), model.manifest.architecture.latent_dim)?;
    anchors.save(&args.model)?;
    println!(
        "fitted {name:?} to model {} in {seconds:.1} s ({} steps, final loss {:.4})",
        model.manifest.model_id(),
        settings.iterations,
        fitted.loss_history.last().map_or(f32::NAN, |l| l.loss)
    );
    println!(
        "reconstruction Chamfer distance {:.3e} in {CHAMFER_UNITS}",
        fitted.chamfer
    );
    println!(
        "anchor {name:?} stored in {}",
        args.model.join(ANCHORS_FILE).display()
    );
    if let Some(path) = &args.json {
        let json = serde_json::json!({
            "model_id": model.manifest.model_id(),
            "anchor": anchor,
            "chamfer_units": CHAMFER_UNITS,
            "triangles": fitted.triangles,
            "settings": fitted.settings,
            "seconds": seconds,
            "loss_history": fitted.loss_history,
        });
        std::fs::write(path, serde_json::to_vec_pretty(&json)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("report written to {}", path.display());
    }
    Ok(())
}
