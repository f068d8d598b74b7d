//! The training loop: epochs of reproducible batches, Adam steps, checkpoints, resume.
//!
//! A run is fully determined by its setup, its data and its seed: the initial weights come
//! from the seed, and every batch from `(seed, epoch, batch)` ([`crate::sdf::data::batch`]). A checkpoint
//! stores the weights, the Adam state, the loss sums of the unfinished epoch and the position
//! (epoch, next batch), so `resume` continues exactly where the run stopped and ends with the
//! same weights as an uninterrupted run. A stop request (Ctrl-C in the CLI) is honoured after
//! the current step, with a checkpoint.

pub mod config;
pub mod fit;
pub mod heldout;
pub mod loss;
pub mod refit;
pub mod step;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, bail, ensure};

use crate::sdf::backend::Backend;
use crate::sdf::data::batch::{draw_batch, epoch_batches};
use crate::sdf::data::cache::prepare_cached;
use crate::sdf::data::holdout::{HoldoutSpec, load_split, split};
use crate::sdf::data::{DataSource, PreparedDataset, load_source_meshes};
use crate::sdf::model::decoder::SdfAutoDecoder;
use crate::sdf::store::manifest::{
    DataRecord, EpochLoss, FileRecord, MANIFEST_FILE, MANIFEST_FORMAT, MANIFEST_VERSION,
    ModelManifest, SIGN_CONVENTION, ShapeRecord, TrainingProgress,
};
use crate::sdf::store::{load_decoder, load_optimizer, read_manifest, save_model};
pub use crate::sdf::training::config::{
    Preset, TrainingConfig, TrainingConfigError, TrainingSetup,
};
use crate::sdf::training::step::{SdfTrainer, TrainStepOutput};

/// One finished optimisation step, for progress display.
#[derive(Debug, Clone, Copy)]
pub struct StepReport {
    /// 0-based epoch.
    pub epoch: u64,
    /// 0-based batch within the epoch.
    pub batch: u64,
    /// Batches per epoch.
    pub batches_per_epoch: u64,
    /// Loss terms of the step.
    pub loss: TrainStepOutput,
    /// Surface points processed by the step (B·N).
    pub surface_points: usize,
    /// Seconds the step took.
    pub seconds: f64,
}

/// Receives progress while training; every method has a do-nothing default.
pub trait TrainingObserver {
    /// Training is about to start at `(first_epoch, first_batch)` of `epochs`.
    fn on_start(&mut self, _epochs: u64, _first_epoch: u64, _batches_per_epoch: u64) {}
    /// A step finished.
    fn on_step(&mut self, _step: &StepReport) {}
    /// An epoch finished with these mean losses.
    fn on_epoch(&mut self, _loss: &EpochLoss) {}
    /// A checkpoint was written after `epochs_completed` epochs.
    fn on_checkpoint(&mut self, _epochs_completed: u64) {}
}

/// An observer that ignores everything (tests, services with their own logging).
pub struct Silent;
impl TrainingObserver for Silent {}

/// What to train and where.
pub struct TrainingRequest<'a> {
    /// Model directory (created; also holds the sample cache).
    pub out_dir: PathBuf,
    /// The shapes.
    pub source: DataSource,
    /// Source shapes to keep out of training (a fresh run only: a resumed run keeps the
    /// split its manifest records).
    pub holdout: Option<HoldoutSpec>,
    /// Hyper-parameters (ignored except `epochs` when resuming: the saved ones rule).
    pub setup: TrainingSetup,
    /// Compute backend.
    pub backend: Backend,
    /// Continue the checkpoint in `out_dir` instead of starting fresh.
    pub resume: bool,
    /// Set by another thread (Ctrl-C) to stop after the current step with a checkpoint.
    pub stop: Option<&'a AtomicBool>,
}

/// How a run ended.
#[derive(Debug, Clone)]
pub struct TrainingOutcome {
    /// The final (or checkpoint) manifest.
    pub manifest: ModelManifest,
    /// False when stopped early by the stop flag.
    pub finished: bool,
}

/// Trains (or resumes) a model and saves it in `request.out_dir`.
pub fn train(
    request: &TrainingRequest<'_>,
    observer: &mut dyn TrainingObserver,
) -> anyhow::Result<TrainingOutcome> {
    let dir = &request.out_dir;
    let device = request.backend.device(true)?;
    let (mut manifest, trainer, data) = if request.resume {
        resume_state(request, &device)?
    } else {
        if dir.join(MANIFEST_FILE).exists() {
            bail!(
                "{} already holds a model; pass --resume to continue it or choose another --out",
                dir.display()
            );
        }
        fresh_state(request, &device)?
    };
    let config = manifest.training.clone();
    let result = run_epochs(
        dir,
        &mut manifest,
        trainer,
        &data,
        &config,
        request,
        observer,
    )?;
    Ok(result)
}

fn fresh_state(
    request: &TrainingRequest<'_>,
    device: &burn::tensor::Device,
) -> anyhow::Result<(ModelManifest, SdfTrainer, PreparedDataset)> {
    let setup = &request.setup;
    setup.training.validate()?;
    setup.network.validate()?;
    let shapes = split(
        load_source_meshes(&request.source)?,
        request.holdout.as_ref(),
    )?;
    let meshes = shapes.training;
    std::fs::create_dir_all(&request.out_dir)
        .with_context(|| format!("cannot create {}", request.out_dir.display()))?;
    let (data, key) = prepare_cached(&meshes, &setup.sampling, Some(&request.out_dir))?;
    let initial = SdfAutoDecoder::new(
        &setup.network,
        data.shapes.len(),
        setup.training.seed,
        device,
    )?;
    let decoder = as_leaf_parameters(&initial)?;
    let trainer = SdfTrainer::new(decoder, setup.training.step_config());
    let manifest = ModelManifest {
        format: MANIFEST_FORMAT.into(),
        format_version: MANIFEST_VERSION,
        software_version: crate::VERSION.into(),
        backend: request.backend.name().into(),
        sign_convention: SIGN_CONVENTION.into(),
        architecture: setup.network.clone(),
        training: setup.training.clone(),
        data: DataRecord {
            source: request.source.clone(),
            sampling: setup.sampling,
            dataset_key: key,
            holdout: shapes.holdout,
        },
        shapes: data
            .shapes
            .iter()
            .map(|s| ShapeRecord {
                name: s.name.clone(),
                transform: s.transform,
            })
            .collect(),
        progress: TrainingProgress::default(),
        loss_history: Vec::new(),
        weights: FileRecord {
            file: String::new(),
            sha256: String::new(),
            bytes: 0,
        },
        optimizer: None,
    };
    Ok((manifest, trainer, data))
}

/// The same parameter values (and ids) as plain leaf tensors: an initialiser that computes
/// on the autodiff device (for example a bias calibrated from a forward pass) leaves autodiff
/// history on its parameters, which the first backward pass would consume. Going through
/// the checkpoint format gives exactly the tensors a resumed run starts from.
fn as_leaf_parameters(decoder: &SdfAutoDecoder) -> anyhow::Result<SdfAutoDecoder> {
    use burn::store::{BurnpackStore, ModuleSnapshot};
    let mut store = BurnpackStore::from_bytes(None);
    decoder
        .save_into(&mut store)
        .map_err(|e| anyhow::anyhow!("cannot copy the initial weights: {e}"))?;
    let bytes = store
        .get_bytes()
        .map_err(|e| anyhow::anyhow!("cannot copy the initial weights: {e}"))?;
    let mut copy = decoder.clone();
    copy.load_from(&mut BurnpackStore::from_bytes(Some(bytes)))
        .map_err(|e| anyhow::anyhow!("cannot copy the initial weights: {e}"))?;
    Ok(copy)
}

fn resume_state(
    request: &TrainingRequest<'_>,
    device: &burn::tensor::Device,
) -> anyhow::Result<(ModelManifest, SdfTrainer, PreparedDataset)> {
    let dir = &request.out_dir;
    let mut manifest = read_manifest(dir).context("cannot resume")?;
    manifest.training.epochs = request.setup.training.epochs;
    manifest.backend = request.backend.name().into();
    let meshes = load_split(&manifest.data.source, manifest.data.holdout.as_ref())?.training;
    let (data, key) = prepare_cached(&meshes, &manifest.data.sampling, Some(dir))?;
    ensure!(
        key == manifest.data.dataset_key,
        "the training data changed since the checkpoint in {} (dataset hash differs)",
        dir.display()
    );
    let decoder = load_decoder(dir, &manifest, device).context("cannot resume")?;
    let (decoder, fresh) = SdfTrainer::new(decoder, manifest.training.step_config()).into_parts();
    let optimizer = load_optimizer(dir, &manifest, fresh).context("cannot resume")?;
    let trainer = SdfTrainer::with_optimizer(decoder, optimizer, manifest.training.step_config());
    manifest.progress.complete = false;
    Ok((manifest, trainer, data))
}

fn run_epochs(
    dir: &Path,
    manifest: &mut ModelManifest,
    mut trainer: SdfTrainer,
    data: &PreparedDataset,
    config: &TrainingConfig,
    request: &TrainingRequest<'_>,
    observer: &mut dyn TrainingObserver,
) -> anyhow::Result<TrainingOutcome> {
    let shapes = data.shapes.len();
    let size = config.batch_size();
    let batches_per_epoch = shapes.div_ceil(config.batch_shapes) as u64;
    let first_epoch = manifest.progress.epochs_completed;
    observer.on_start(config.epochs, first_epoch, batches_per_epoch);
    for epoch in first_epoch..config.epochs {
        let batches = epoch_batches(shapes, config.batch_shapes, config.seed, epoch);
        let lr = config.learning_rate_at(epoch);
        let mut sums = manifest.progress.partial_sums;
        for b in manifest.progress.next_batch..batches_per_epoch {
            let started = Instant::now();
            let batch = draw_batch(data, &batches[b as usize], &size, config.seed, epoch, b);
            let loss = trainer.step(&batch, lr)?;
            ensure!(
                loss.loss.is_finite(),
                "training diverged at epoch {} batch {b} (loss {})",
                epoch + 1,
                loss.loss
            );
            add_step(&mut sums, &loss);
            observer.on_step(&StepReport {
                epoch,
                batch: b,
                batches_per_epoch,
                loss,
                surface_points: batch.surface_points.len(),
                seconds: started.elapsed().as_secs_f64(),
            });
            let stop = request.stop.is_some_and(|s| s.load(Ordering::SeqCst));
            if stop && b + 1 < batches_per_epoch {
                manifest.progress.next_batch = b + 1;
                manifest.progress.partial_sums = sums;
                save_model(dir, manifest, trainer.model(), Some(trainer.optimizer()))?;
                observer.on_checkpoint(epoch);
                return Ok(TrainingOutcome {
                    manifest: manifest.clone(),
                    finished: false,
                });
            }
        }
        let loss = epoch_mean(&sums, epoch + 1, batches_per_epoch);
        manifest.loss_history.push(loss);
        manifest.progress = TrainingProgress {
            epochs_completed: epoch + 1,
            ..TrainingProgress::default()
        };
        observer.on_epoch(&loss);
        let stop = request.stop.is_some_and(|s| s.load(Ordering::SeqCst));
        let last = epoch + 1 == config.epochs;
        if stop || last || (epoch + 1) % config.checkpoint_every == 0 {
            manifest.progress.complete = last;
            save_model(dir, manifest, trainer.model(), Some(trainer.optimizer()))?;
            observer.on_checkpoint(epoch + 1);
        }
        if stop && !last {
            return Ok(TrainingOutcome {
                manifest: manifest.clone(),
                finished: false,
            });
        }
    }
    if !manifest.progress.complete {
        // Nothing left to run (resumed at or past the last epoch): mark and save.
        manifest.progress.complete = true;
        save_model(dir, manifest, trainer.model(), Some(trainer.optimizer()))?;
    }
    Ok(TrainingOutcome {
        manifest: manifest.clone(),
        finished: true,
    })
}

fn add_step(sums: &mut EpochLoss, step: &TrainStepOutput) {
    sums.total += f64::from(step.loss);
    sums.surface += f64::from(step.surface);
    sums.normal += f64::from(step.normal);
    sums.eikonal += f64::from(step.eikonal);
    sums.latent += f64::from(step.latent);
}

fn epoch_mean(sums: &EpochLoss, epoch: u64, steps: u64) -> EpochLoss {
    let n = steps.max(1) as f64;
    EpochLoss {
        epoch,
        total: sums.total / n,
        surface: sums.surface / n,
        normal: sums.normal / n,
        eikonal: sums.eikonal / n,
        latent: sums.latent / n,
    }
}
