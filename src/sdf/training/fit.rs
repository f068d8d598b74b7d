//! Fitting a new shape to a trained model: DeepSDF-style latent optimisation.
//!
//! The mesh is normalised and sampled exactly as a training shape is ([`prepare_shapes`] with
//! the model's sampling settings), then only a fresh latent z (starting near 0, N(0, 0.01²)) is optimised with
//! Adam on the training loss (eq. 4, [`crate::sdf::training::loss::igr_loss`] through [`SdfTrainer`]) while the
//! network weights stay frozen. The result is scored with the reconstruction Chamfer distance
//! that `aortagen evaluate` reports ([`reconstruction_chamfer`]), so a fitted shape and a
//! training shape are directly comparable. The run is determined by the mesh, the model and
//! the seed (batches come from `(seed, iteration)`).

use std::sync::atomic::{AtomicBool, Ordering};

use burn::module::{Module, Param};
use burn::store::{BurnpackStore, ModuleSnapshot};
use burn::tensor::{Tensor, TensorData};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::geometry::TriMesh;
use crate::geometry::chamfer::DEFAULT_CHAMFER_POINTS;
use crate::geometry::normalize::UnitBallTransform;
use crate::sdf::data::batch::{BatchSize, draw_batch};
use crate::sdf::data::{PreparedDataset, SamplingSettings, prepare_shapes};
use crate::sdf::inference::evaluation::{EvaluationSettings, reconstruction_chamfer};
use crate::sdf::inference::reconstruct::{
    EVALUATION_RESOLUTION, ExtractionMethod, ReconstructError,
};
use crate::sdf::model::decoder::{LATENT_INIT_STD, SdfAutoDecoder};
use crate::sdf::model::network::{SdfNetwork, SdfNetworkConfig};
use crate::sdf::store::LoadedModel;
use crate::sdf::training::TrainingConfig;
use crate::sdf::training::step::{SdfTrainer, TrainStepOutput};

/// Adam steps when the caller does not choose (DeepSDF's latent optimisation uses 800).
pub const DEFAULT_FIT_ITERATIONS: usize = 800;
/// Most Adam steps accepted: bounds the work a single request can ask for.
pub const MAX_FIT_ITERATIONS: usize = 10_000;
/// Adam learning rate on the latent (DeepSDF: 5e-3), divided by 10 for the last quarter.
pub const DEFAULT_FIT_LEARNING_RATE: f64 = 5e-3;

/// How to fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FitSettings {
    /// Adam steps on the latent, 1..=[`MAX_FIT_ITERATIONS`].
    pub iterations: usize,
    /// Initial learning rate.
    pub learning_rate: f64,
    /// Seed of the surface sampling and of every batch.
    pub seed: u64,
    /// How the fitted latent is meshed and scored (seed included).
    pub evaluation: EvaluationSettings,
}

impl FitSettings {
    /// Defaults with `seed`: 800 steps, 128³ fast extraction, 30 000-point Chamfer.
    pub fn new(seed: u64) -> Self {
        Self {
            iterations: DEFAULT_FIT_ITERATIONS,
            learning_rate: DEFAULT_FIT_LEARNING_RATE,
            seed,
            evaluation: EvaluationSettings {
                resolution: EVALUATION_RESOLUTION,
                chamfer_points: DEFAULT_CHAMFER_POINTS,
                seed,
                extraction: ExtractionMethod::Fast,
            },
        }
    }

    /// Learning rate of step `iteration` (0-based): a tenth for the last quarter.
    pub fn learning_rate_at(&self, iteration: usize) -> f64 {
        if iteration * 4 >= self.iterations * 3 {
            self.learning_rate * 0.1
        } else {
            self.learning_rate
        }
    }
}

/// One finished step, for progress display.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitProgress {
    /// Steps done (1-based).
    pub iteration: usize,
    /// Steps in the run.
    pub iterations: usize,
    /// The step's loss terms.
    pub loss: TrainStepOutput,
}

/// A fitted latent and how well it reconstructs the mesh.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FittedLatent {
    /// The latent code, of the model's latent dimension.
    pub latent: Vec<f32>,
    /// Mesh units ↔ unit ball of the fitted mesh (as training computes it).
    pub transform: UnitBallTransform,
    /// Reconstruction Chamfer distance (unit-ball coordinates, as `aortagen evaluate`).
    pub chamfer: f64,
    /// Triangles of the reconstruction that was scored.
    pub triangles: usize,
    /// The loss terms of every step, in order.
    pub loss_history: Vec<TrainStepOutput>,
    /// The settings used.
    pub settings: FitSettings,
}

/// Why a fit did not produce a latent.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// Iterations outside 1..=[`MAX_FIT_ITERATIONS`].
    #[error("iterations must be between 1 and {MAX_FIT_ITERATIONS} (got {0})")]
    Iterations(usize),
    /// The learning rate is not a positive number.
    #[error("the learning rate must be a positive number (got {0})")]
    LearningRate(f64),
    /// The mesh cannot be sampled like a training shape.
    #[error("the mesh cannot be sampled: {0}")]
    Sampling(String),
    /// The cancel flag was raised.
    #[error("fitting was cancelled after {0} steps")]
    Cancelled(usize),
    /// The loss stopped being finite.
    #[error("fitting diverged at step {iteration} (loss {loss})")]
    Diverged {
        /// The step (1-based).
        iteration: usize,
        /// Its loss.
        loss: f32,
    },
    /// The fitted latent gives no usable surface.
    #[error("the fitted latent cannot be meshed: {0}")]
    Reconstruct(#[from] ReconstructError),
    /// The network could not be prepared for optimisation.
    #[error("cannot prepare the network: {0}")]
    Network(String),
}

/// Fits a latent to `mesh` (in its own units) for the frozen network of `model`.
/// `on_step` sees every step; raising `cancel` stops after the current step.
pub fn fit_mesh(
    model: &LoadedModel,
    mesh: &TriMesh,
    settings: &FitSettings,
    on_step: &mut dyn FnMut(&FitProgress),
    cancel: Option<&AtomicBool>,
) -> Result<FittedLatent, FitError> {
    check_settings(settings)?;
    let sampling = SamplingSettings {
        seed: settings.seed,
        ..model.manifest.data.sampling
    };
    let data = prepare_target(mesh, &sampling)?;
    let transform = data.shapes[0].transform;
    let network = frozen_trainable_copy(&model.decoder.network, &model.manifest.architecture)?;
    let (_, latent, loss_history) = optimise_latent(
        network,
        &data,
        &model.manifest.training,
        settings,
        on_step,
        cancel,
    )?;
    let unit = transform.mesh_to_unit(mesh);
    let (chamfer, triangles) = latent_chamfer(model, &latent, &unit, &settings.evaluation)?;
    Ok(FittedLatent {
        latent,
        transform,
        chamfer,
        triangles,
        loss_history,
        settings: *settings,
    })
}

/// The reconstruction Chamfer distance of `latent` against `original_unit` (a mesh already in
/// the unit ball), with the training shapes' measurement.
pub fn latent_chamfer(
    model: &LoadedModel,
    latent: &[f32],
    original_unit: &TriMesh,
    settings: &EvaluationSettings,
) -> Result<(f64, usize), ReconstructError> {
    let field = model.field(latent)?;
    reconstruction_chamfer(&field, original_unit, settings, settings.seed)
}

fn check_settings(settings: &FitSettings) -> Result<(), FitError> {
    if !(1..=MAX_FIT_ITERATIONS).contains(&settings.iterations) {
        return Err(FitError::Iterations(settings.iterations));
    }
    let lr = settings.learning_rate;
    if !(lr.is_finite() && lr > 0.0) {
        return Err(FitError::LearningRate(lr));
    }
    Ok(())
}

/// The mesh as a one-shape training set: normalised and sampled like training data.
fn prepare_target(
    mesh: &TriMesh,
    sampling: &SamplingSettings,
) -> Result<PreparedDataset, FitError> {
    if mesh.triangles.is_empty() {
        return Err(FitError::Sampling("the mesh has no triangles".into()));
    }
    let shapes = prepare_shapes(&[("target".to_string(), mesh.clone())], sampling)
        .map_err(|e| FitError::Sampling(format!("{e:#}")))?;
    Ok(PreparedDataset {
        shapes,
        settings: *sampling,
    })
}

/// The network's weights on an autodiff device with gradients switched off: the optimiser
/// can then only move the latent. A copy, so the loaded model is never touched.
pub fn frozen_trainable_copy(
    network: &SdfNetwork,
    config: &SdfNetworkConfig,
) -> Result<SdfNetwork, FitError> {
    let error = |e: String| FitError::Network(e);
    let device = network.device();
    let device = if device.is_autodiff() {
        device
    } else {
        device.autodiff()
    };
    let mut store = BurnpackStore::from_bytes(None);
    network
        .save_into(&mut store)
        .map_err(|e| error(e.to_string()))?;
    let bytes = store.get_bytes().map_err(|e| error(e.to_string()))?;
    let mut copy = config
        .init_with_dtype(0, &device, network.dtype())
        .map_err(|e| error(e.to_string()))?;
    copy.load_from(&mut BurnpackStore::from_bytes(Some(bytes)))
        .map_err(|e| error(e.to_string()))?;
    Ok(copy.no_grad())
}

/// Adam on a single latent row (starting at [`initial_latent`]) with `network` frozen. Returns the network as
/// it was after the last step (for checking that it did not move), the latent and the losses.
pub fn optimise_latent(
    network: SdfNetwork,
    data: &PreparedDataset,
    training: &TrainingConfig,
    settings: &FitSettings,
    on_step: &mut dyn FnMut(&FitProgress),
    cancel: Option<&AtomicBool>,
) -> Result<(SdfNetwork, Vec<f32>, Vec<TrainStepOutput>), FitError> {
    check_settings(settings)?;
    let d = network.latent_dim;
    let start = Tensor::<2>::from_data(
        TensorData::new(initial_latent(d, settings.seed), [1, d]),
        (&network.device(), network.dtype()),
    );
    let decoder = SdfAutoDecoder {
        network,
        latents: Param::from_tensor(start),
    };
    let mut trainer = SdfTrainer::new(decoder, training.step_config());
    let size = BatchSize {
        shapes: 1,
        surface: training.surface_points,
        eikonal: training.eikonal_points,
    };
    let mut history = Vec::with_capacity(settings.iterations);
    for iteration in 0..settings.iterations {
        if cancel.is_some_and(|c| c.load(Ordering::SeqCst)) {
            return Err(FitError::Cancelled(iteration));
        }
        let batch = draw_batch(data, &[0], &size, settings.seed, iteration as u64, 0);
        let loss = trainer
            .step(&batch, settings.learning_rate_at(iteration))
            .map_err(|e| FitError::Sampling(e.to_string()))?;
        if !loss.loss.is_finite() {
            return Err(FitError::Diverged {
                iteration: iteration + 1,
                loss: loss.loss,
            });
        }
        history.push(loss);
        on_step(&FitProgress {
            iteration: iteration + 1,
            iterations: settings.iterations,
            loss,
        });
    }
    let (decoder, _) = trainer.into_parts();
    let latent = decoder.latents_to_vec().remove(0);
    Ok((decoder.network, latent, history))
}

/// The starting latent: N(0, 0.01²) from `seed`, as training initialises its latents. Not
/// exactly 0, where the gradient of the loss's ‖z‖ term is undefined.
pub fn initial_latent(dim: usize, seed: u64) -> Vec<f32> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6669_745f_6c61_7465);
    let normal = Normal::new(0.0, LATENT_INIT_STD).expect("finite positive std");
    (0..dim).map(|_| normal.sample(&mut rng) as f32).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_learning_rate_drops_for_the_last_quarter() {
        let s = FitSettings {
            iterations: 100,
            ..FitSettings::new(1)
        };
        assert_eq!(s.learning_rate_at(0), DEFAULT_FIT_LEARNING_RATE);
        assert_eq!(s.learning_rate_at(74), DEFAULT_FIT_LEARNING_RATE);
        assert!((s.learning_rate_at(75) - DEFAULT_FIT_LEARNING_RATE * 0.1).abs() < 1e-15);
    }

    #[test]
    fn iterations_and_learning_rate_out_of_range_are_rejected() {
        for iterations in [0, MAX_FIT_ITERATIONS + 1] {
            let s = FitSettings {
                iterations,
                ..FitSettings::new(1)
            };
            assert!(matches!(check_settings(&s), Err(FitError::Iterations(i)) if i == iterations));
        }
        for lr in [0.0, -1.0, f64::NAN] {
            let s = FitSettings {
                learning_rate: lr,
                ..FitSettings::new(1)
            };
            assert!(matches!(check_settings(&s), Err(FitError::LearningRate(_))));
        }
        assert!(check_settings(&FitSettings::new(1)).is_ok());
    }
}
