//! `aortagen train`: learn a model from a mesh directory or from parametric roots.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;
use indicatif::ProgressBar;

use super::progress::{init_logging, terminal_bar};
use crate::sdf::backend::Backend;
use crate::sdf::data::DataSource;
use crate::sdf::data::holdout::HoldoutSpec;
use crate::sdf::store::manifest::EpochLoss;
use crate::sdf::training::{
    Preset, StepReport, TrainingObserver, TrainingRequest, TrainingSetup, train,
};

/// Set by Ctrl-C: the loop finishes its step, writes a checkpoint and returns.
static STOP: AtomicBool = AtomicBool::new(false);

/// Train a neural SDF auto-decoder on a set of shapes.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("input").required(true).args(["data", "synth"])))]
pub struct TrainArgs {
    /// Directory of meshes (STL, OBJ, PLY, glTF/GLB), one training shape per file.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Train on N generated parametric aortic roots instead.
    #[arg(long, value_name = "N")]
    pub synth: Option<usize>,
    /// Model directory to write (manifest, weights, optimizer state, sample cache).
    #[arg(long)]
    pub out: PathBuf,
    /// Starting hyper-parameters: `cpu` (small, fast) or `paper` (d=256, H=512, 5000 epochs).
    #[arg(long, value_enum, default_value = "cpu")]
    pub preset: Preset,
    /// Epochs (overrides the preset; with --resume, the new total).
    #[arg(long)]
    pub epochs: Option<u64>,
    /// Surface points sampled once per shape (P).
    #[arg(long)]
    pub points: Option<usize>,
    /// Surface and eikonal points per shape per step (N = M).
    #[arg(long)]
    pub step_points: Option<usize>,
    /// Shapes per step (B).
    #[arg(long)]
    pub batch_shapes: Option<usize>,
    /// Latent size d (overrides the preset).
    #[arg(long)]
    pub latent_dim: Option<usize>,
    /// Hidden width H (overrides the preset).
    #[arg(long)]
    pub hidden: Option<usize>,
    /// Write a checkpoint every K epochs.
    #[arg(long, value_name = "K")]
    pub checkpoint_every: Option<u64>,
    /// Seed of the sampling, the initial weights and every batch.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Keep K of the source shapes out of training (chosen from --holdout-seed), for
    /// held-out evaluation and validation; the manifest records which.
    #[arg(long, value_name = "K")]
    pub holdout: Option<usize>,
    /// Seed of the held-out choice (default: --seed).
    #[arg(long, requires = "holdout")]
    pub holdout_seed: Option<u64>,
    /// Continue the checkpoint in --out.
    #[arg(long)]
    pub resume: bool,
    /// Compute backend.
    #[arg(long, default_value = "flex")]
    pub backend: Backend,
}

impl TrainArgs {
    /// The preset with the command-line overrides applied.
    pub fn setup(&self) -> TrainingSetup {
        let mut setup = self.preset.setup(self.seed);
        let t = &mut setup.training;
        if let Some(e) = self.epochs {
            t.epochs = e;
        }
        if let Some(n) = self.step_points {
            (t.surface_points, t.eikonal_points) = (n, n);
        }
        if let Some(b) = self.batch_shapes {
            t.batch_shapes = b;
        }
        if let Some(k) = self.checkpoint_every {
            t.checkpoint_every = k;
        }
        if let Some(p) = self.points {
            setup.sampling.points_per_shape = p;
        }
        if let Some(d) = self.latent_dim {
            setup.network.latent_dim = d;
        }
        if let Some(h) = self.hidden {
            setup.network.hidden = h;
        }
        setup
    }

    /// The held-out part, if asked for.
    pub fn holdout(&self) -> Option<HoldoutSpec> {
        self.holdout.map(|count| HoldoutSpec {
            count,
            seed: self.holdout_seed.unwrap_or(self.seed),
        })
    }

    fn source(&self) -> DataSource {
        match (&self.data, self.synth) {
            (Some(path), _) => DataSource::Directory { path: path.clone() },
            (None, count) => DataSource::Synth {
                count: count.unwrap_or(0),
                seed: self.seed,
            },
        }
    }
}

/// Runs `aortagen train`.
pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    init_logging();
    STOP.store(false, Ordering::SeqCst);
    let installed = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            eprintln!("second interrupt: exiting without a checkpoint");
            std::process::exit(130);
        }
        eprintln!("interrupt: finishing the current step, then writing a checkpoint");
    });
    match installed {
        // Already installed by an earlier run in this process: it sets the same flag.
        Ok(()) | Err(ctrlc::Error::MultipleHandlers) => {}
        Err(e) => return Err(e).context("cannot install the Ctrl-C handler"),
    }
    let request = TrainingRequest {
        out_dir: args.out.clone(),
        source: args.source(),
        holdout: args.holdout(),
        setup: args.setup(),
        backend: args.backend,
        resume: args.resume,
        stop: Some(&STOP),
    };
    let mut progress = CliProgress::default();
    let outcome = train(&request, &mut progress)?;
    if let Some(bar) = &progress.bar {
        bar.finish_and_clear();
    }
    let m = &outcome.manifest;
    let last = m.loss_history.last().map_or(f64::NAN, |l| l.total);
    if let Some(h) = &m.data.holdout {
        let names: Vec<&str> = h.shapes.iter().map(|s| s.name.as_str()).collect();
        println!("held out {} shapes: {}", names.len(), names.join(", "));
    }
    if outcome.finished {
        println!(
            "trained {} shapes for {} epochs (final loss {last:.5}); model {} in {}",
            m.shapes.len(),
            m.progress.epochs_completed,
            m.model_id(),
            args.out.display()
        );
    } else {
        println!(
            "stopped after epoch {} batch {}; checkpoint in {} (continue with --resume)",
            m.progress.epochs_completed,
            m.progress.next_batch,
            args.out.display()
        );
    }
    Ok(())
}

/// Bar on a terminal, log lines otherwise.
#[derive(Default)]
struct CliProgress {
    bar: Option<ProgressBar>,
    points: usize,
    seconds: f64,
}

impl TrainingObserver for CliProgress {
    fn on_start(&mut self, epochs: u64, first_epoch: u64, batches_per_epoch: u64) {
        let remaining = epochs.saturating_sub(first_epoch) * batches_per_epoch;
        self.bar = terminal_bar(remaining, "steps");
        tracing::info!(epochs, first_epoch, batches_per_epoch, "training");
    }

    fn on_step(&mut self, step: &StepReport) {
        self.points += step.surface_points;
        self.seconds += step.seconds;
        if let Some(bar) = &self.bar {
            let l = &step.loss;
            bar.inc(1);
            bar.set_message(format!(
                "epoch {} loss {:.4} (|f| {:.4} n {:.4} eik {:.4} z {:.1e}) {:.0} pts/s",
                step.epoch + 1,
                l.loss,
                l.surface,
                l.normal,
                l.eikonal,
                l.latent,
                step.surface_points as f64 / step.seconds.max(1e-9)
            ));
        }
    }

    fn on_epoch(&mut self, loss: &EpochLoss) {
        let points_per_second = self.points as f64 / self.seconds.max(1e-9);
        (self.points, self.seconds) = (0, 0.0);
        if self.bar.is_none() {
            tracing::info!(
                epoch = loss.epoch,
                loss = loss.total,
                surface = loss.surface,
                normal = loss.normal,
                eikonal = loss.eikonal,
                latent = loss.latent,
                points_per_second = points_per_second.round(),
                "epoch done"
            );
        }
    }

    fn on_checkpoint(&mut self, epochs_completed: u64) {
        match &self.bar {
            Some(bar) => bar.println(format!("checkpoint after epoch {epochs_completed}")),
            None => tracing::info!(epochs_completed, "checkpoint written"),
        }
    }
}
