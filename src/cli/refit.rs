//! `aortagen refit`: fits every training shape of a model again with the network frozen and
//! keeps the latents beside the model (`refits.json`), for density samplers that should
//! draw the way new patients land in latent space (see [`crate::sdf::store::refits`]).
//!
//! One fit per training shape (about 40 s each at the defaults on two cores). The file is
//! written after every shape, so an interrupted run (Ctrl-C stops after the current fit's
//! step) resumes where it stopped with the same result.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{bail, ensure};

use super::progress::{init_logging, terminal_bar};
use crate::geometry::chamfer::DEFAULT_CHAMFER_POINTS;
use crate::sdf::backend::Backend;
use crate::sdf::data::DataSource;
use crate::sdf::data::holdout::load_split;
use crate::sdf::inference::evaluation::CHAMFER_UNITS;
use crate::sdf::inference::reconstruct::{EVALUATION_RESOLUTION, MAX_RESOLUTION, MIN_RESOLUTION};
use crate::sdf::store::LoadedModel;
use crate::sdf::store::refits::{REFITS_FILE, RefitSet};
use crate::sdf::training::fit::{DEFAULT_FIT_ITERATIONS, FitError, FitSettings};
use crate::sdf::training::refit::{refit_settings, refit_shape};
use crate::stats::descriptive::quantile;

/// Fit every training shape again with the network frozen; keep the latents in refits.json.
#[derive(Debug, clap::Args)]
pub struct RefitArgs {
    /// Model directory written by `aortagen train`.
    #[arg(long)]
    pub model: PathBuf,
    /// Directory of the training meshes (default: the training source in the manifest).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Adam steps of each fit (as `aortagen fit`).
    #[arg(long, default_value_t = DEFAULT_FIT_ITERATIONS)]
    pub iterations: usize,
    /// Seed of shape 0's fit; shape i uses seed + 2 i.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Grid samples per axis for the reconstruction each fit is scored on.
    #[arg(long, default_value_t = EVALUATION_RESOLUTION)]
    pub resolution: usize,
    /// Points sampled on each surface for the Chamfer distance.
    #[arg(long, default_value_t = DEFAULT_CHAMFER_POINTS)]
    pub points: usize,
    /// Compute backend.
    #[arg(long, default_value = "flex")]
    pub backend: Backend,
}

/// Runs `aortagen refit`.
pub fn run(args: RefitArgs) -> anyhow::Result<()> {
    init_logging();
    ensure!(
        (MIN_RESOLUTION..=MAX_RESOLUTION).contains(&args.resolution),
        "--resolution must be between {MIN_RESOLUTION} and {MAX_RESOLUTION}"
    );
    ensure!(args.points >= 1, "--points must be at least 1");
    let model = LoadedModel::load(&args.model, args.backend)?;
    let manifest = &model.manifest;
    let mut set = RefitSet::load(&args.model, manifest)?;
    let mut base = FitSettings::new(args.seed);
    base.iterations = args.iterations;
    base.evaluation.resolution = args.resolution;
    base.evaluation.chamfer_points = args.points;
    for (index, done) in set.shapes.iter().enumerate() {
        let expected = refit_settings(&base, index);
        if (done.iterations, done.seed) != (expected.iterations, expected.seed) {
            bail!(
                "{} was started with other settings (shape {index}: {} steps, seed {}; this \
                 run: {} steps, seed {}); resume with those or delete the file",
                args.model.join(REFITS_FILE).display(),
                done.iterations,
                done.seed,
                expected.iterations,
                expected.seed
            );
        }
    }
    let total = manifest.shapes.len();
    if set.is_complete(manifest) {
        println!("all {total} training shapes are already re-fitted");
        print_summary(&model, &set);
        return Ok(());
    }
    let source = match &args.data {
        Some(path) => DataSource::Directory { path: path.clone() },
        None => manifest.data.source.clone(),
    };
    let training = load_split(&source, manifest.data.holdout.as_ref())?.training;
    ensure!(
        training.len() == total,
        "the data gives {} training shapes, the model has {total}",
        training.len()
    );

    let stop = Arc::new(AtomicBool::new(false));
    let handler_stop = stop.clone();
    let _ = ctrlc::set_handler(move || handler_stop.store(true, Ordering::SeqCst));
    let first = set.shapes.len();
    if first > 0 {
        tracing::info!(done = first, of = total, "resuming");
    }
    let bar = terminal_bar((total - first) as u64, "shapes");
    let started = Instant::now();
    for (index, (name, mesh)) in training.iter().enumerate().skip(first) {
        let record = match refit_shape(&model, index, name, mesh, &base, Some(&stop)) {
            Ok(record) => record,
            Err(FitError::Cancelled(_)) => {
                if let Some(bar) = &bar {
                    bar.abandon();
                }
                println!(
                    "stopped after {index} of {total} shapes; run the same command again to \
                     resume"
                );
                return Ok(());
            }
            Err(e) => bail!("training shape {index} ({name}): {e}"),
        };
        let chamfer = record.chamfer;
        set.push(record, manifest)?;
        set.save(&args.model)?;
        match &bar {
            Some(bar) => bar.inc(1),
            None => tracing::info!(
                shape = %name,
                index,
                of = total,
                chamfer,
                seconds = started.elapsed().as_secs_f64(),
                "re-fitted"
            ),
        }
    }
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    println!(
        "re-fitted {} training shapes of model {} in {:.0} s; stored in {}",
        total - first,
        manifest.model_id(),
        started.elapsed().as_secs_f64(),
        args.model.join(REFITS_FILE).display()
    );
    print_summary(&model, &set);
    Ok(())
}

/// Fidelity of the fits, and how far the re-fitted latents spread against the training ones.
fn print_summary(model: &LoadedModel, set: &RefitSet) {
    let chamfers: Vec<f64> = set.shapes.iter().map(|s| s.chamfer).collect();
    let median = |values: &[f64]| quantile(values, 0.5).unwrap_or(f64::NAN);
    println!(
        "reconstruction Chamfer distance of the fits ({CHAMFER_UNITS}): median {:.3e}",
        median(&chamfers)
    );
    let refitted: Vec<Vec<f32>> = set.shapes.iter().map(|s| s.latent.clone()).collect();
    println!(
        "median latent distance from the mean: re-fitted {:.4}, training {:.4}",
        median(&distances_from_mean(&refitted)),
        median(&distances_from_mean(&model.latents()))
    );
}

/// Euclidean distance of each latent from the latents' mean.
fn distances_from_mean(latents: &[Vec<f32>]) -> Vec<f64> {
    let n = latents.len().max(1) as f64;
    let dim = latents.first().map_or(0, Vec::len);
    let mean: Vec<f64> = (0..dim)
        .map(|k| latents.iter().map(|z| f64::from(z[k])).sum::<f64>() / n)
        .collect();
    latents
        .iter()
        .map(|z| {
            z.iter()
                .zip(&mean)
                .map(|(&v, m)| (f64::from(v) - m).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .collect()
}
