//! Training hyper-parameters and the two presets.
//!
//! `paper` reproduces the seed paper's setting (DESIGN §2): d = 256, H = 512, 8 softplus
//! layers with the skip at layer 4, β = 100, Adam with lr 1e-3 halved every 500 epochs, 5000
//! epochs, 500 000 cached surface points per shape, τ = 0.5, λ = 1e-4. The paper does not fix
//! the per-step batch; 8 shapes × 16 384 surface + 16 384 eikonal points is chosen here.
//!
//! `cpu` is the CPU preset: a model small enough to train on a 2-core machine in an hour or
//! so for ~100 shapes. d = 64, H = 128 is the smallest of the measured configurations
//! (config c of the benchmarks: ≈ 58 000 surface points per second per training step, 11×
//! config a); 100 000 cached points per shape keep σ_local meaningful at a tenth of the
//! paper's memory; 2 048 + 2 048 points per shape per step and 8 shapes per batch keep one
//! step under half a second. Measured on 100 SynthAorta shapes (release build, 2-core
//! machine, docs/synthaorta-100): 240 epochs in 15 min with nothing else running (≈ 3.6 s per
//! epoch after ≈ 20 s of one-off sampling); reconstruction CD median 5.8e-5 against a sampling
//! floor of 4.9e-5.
//! The learning rate halves every 80 epochs (three halvings, as the paper's schedule has ten
//! over 5000 epochs, scaled to the shorter run); the loss reaches its final value by epoch 180.

use serde::{Deserialize, Serialize};

use crate::sdf::data::SamplingSettings;
use crate::sdf::data::batch::BatchSize;
use crate::sdf::model::network::SdfNetworkConfig;
use crate::sdf::training::loss::IgrLossConfig;
use crate::sdf::training::step::TrainStepConfig;

/// A named starting point for the hyper-parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    /// Small network sized for CPU training (the default).
    Cpu,
    /// The seed paper's values.
    Paper,
}

/// How the optimisation runs (the network shape and the sampling are separate).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingConfig {
    /// The preset these values started from.
    pub preset: Preset,
    /// Passes over all shapes.
    pub epochs: u64,
    /// Shapes per step, `B`.
    pub batch_shapes: usize,
    /// Surface points per shape per step, `N`.
    pub surface_points: usize,
    /// Eikonal points per shape per step, `M` (half Gaussian, half uniform).
    pub eikonal_points: usize,
    /// Initial Adam learning rate.
    pub learning_rate: f64,
    /// The learning rate halves every this many epochs (0: never).
    pub lr_halving_epochs: u64,
    /// Weight of the eikonal term, τ.
    pub tau: f64,
    /// Weight of the latent-norm term, λ.
    pub lambda: f64,
    /// A checkpoint is written every this many epochs (and at the end).
    pub checkpoint_every: u64,
    /// Seed of the initial weights and of every batch draw.
    pub seed: u64,
}

/// Everything a training run needs besides its data.
#[derive(Debug, Clone)]
pub struct TrainingSetup {
    /// Network shape.
    pub network: SdfNetworkConfig,
    /// Optimisation.
    pub training: TrainingConfig,
    /// One-off surface sampling of each shape.
    pub sampling: SamplingSettings,
}

/// A hyper-parameter that cannot work.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("training setting `{field}` {rule}")]
pub struct TrainingConfigError {
    /// The setting.
    pub field: &'static str,
    /// The rule it breaks.
    pub rule: &'static str,
}

impl Preset {
    /// The preset's full setup with the given seed.
    pub fn setup(self, seed: u64) -> TrainingSetup {
        let (network, training, points_per_shape) = match self {
            Preset::Paper => (
                SdfNetworkConfig::new(),
                TrainingConfig {
                    preset: self,
                    epochs: 5000,
                    batch_shapes: 8,
                    surface_points: 16_384,
                    eikonal_points: 16_384,
                    learning_rate: 1e-3,
                    lr_halving_epochs: 500,
                    tau: 0.5,
                    lambda: 1e-4,
                    checkpoint_every: 50,
                    seed,
                },
                500_000,
            ),
            Preset::Cpu => (
                SdfNetworkConfig::new().with_latent_dim(64).with_hidden(128),
                TrainingConfig {
                    preset: self,
                    epochs: 240,
                    batch_shapes: 8,
                    surface_points: 2048,
                    eikonal_points: 2048,
                    learning_rate: 1e-3,
                    lr_halving_epochs: 80,
                    tau: 0.5,
                    lambda: 1e-4,
                    checkpoint_every: 10,
                    seed,
                },
                100_000,
            ),
        };
        TrainingSetup {
            network,
            training,
            sampling: SamplingSettings {
                points_per_shape,
                knn_k: 50,
                seed,
            },
        }
    }
}

impl TrainingConfig {
    /// Learning rate during epoch `epoch` (0-based): halved every `lr_halving_epochs`.
    pub fn learning_rate_at(&self, epoch: u64) -> f64 {
        match self.lr_halving_epochs {
            0 => self.learning_rate,
            h => self.learning_rate * 0.5f64.powi((epoch / h).min(1000) as i32),
        }
    }

    /// Points per step.
    pub fn batch_size(&self) -> BatchSize {
        BatchSize {
            shapes: self.batch_shapes,
            surface: self.surface_points,
            eikonal: self.eikonal_points,
        }
    }

    /// The step configuration for [`crate::sdf::training::step::SdfTrainer`].
    pub fn step_config(&self) -> TrainStepConfig {
        TrainStepConfig::new().with_loss(
            IgrLossConfig::new()
                .with_tau(self.tau)
                .with_lambda(self.lambda),
        )
    }

    /// Rejects settings that cannot train.
    pub fn validate(&self) -> Result<(), TrainingConfigError> {
        let rule = |field, rule| Err(TrainingConfigError { field, rule });
        if self.batch_shapes == 0 {
            return rule("batch_shapes", "must be at least 1");
        }
        if self.surface_points == 0 {
            return rule("surface_points", "must be at least 1");
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return rule("learning_rate", "must be a positive number");
        }
        if !(self.tau.is_finite() && self.tau >= 0.0) {
            return rule("tau", "must be a number ≥ 0");
        }
        if !(self.lambda.is_finite() && self.lambda >= 0.0) {
            return rule("lambda", "must be a number ≥ 0");
        }
        if self.checkpoint_every == 0 {
            return rule("checkpoint_every", "must be at least 1");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_learning_rate_halves_every_interval() {
        let t = Preset::Paper.setup(0).training;
        assert_eq!(t.learning_rate_at(0), 1e-3);
        assert_eq!(t.learning_rate_at(499), 1e-3);
        assert_eq!(t.learning_rate_at(500), 5e-4);
        assert_eq!(t.learning_rate_at(1999), 1.25e-4);
        let never = TrainingConfig {
            lr_halving_epochs: 0,
            ..t
        };
        assert_eq!(never.learning_rate_at(10_000), 1e-3);
    }

    #[test]
    fn the_paper_preset_has_the_papers_values() {
        let s = Preset::Paper.setup(4);
        assert_eq!((s.network.latent_dim, s.network.hidden), (256, 512));
        assert_eq!((s.network.hidden_layers, s.network.skip_layer), (8, 4));
        assert_eq!(s.network.beta, 100.0);
        assert_eq!(
            (s.training.epochs, s.training.tau, s.training.lambda),
            (5000, 0.5, 1e-4)
        );
        assert_eq!(
            (s.sampling.points_per_shape, s.sampling.knn_k),
            (500_000, 50)
        );
        assert_eq!((s.training.seed, s.sampling.seed), (4, 4));
        assert_eq!(Preset::Cpu.setup(0).training.validate(), Ok(()));
    }

    #[test]
    fn unusable_settings_name_the_setting() {
        let t = Preset::Cpu.setup(0).training;
        let bad = TrainingConfig {
            batch_shapes: 0,
            ..t.clone()
        };
        assert_eq!(bad.validate().unwrap_err().field, "batch_shapes");
        let bad = TrainingConfig {
            learning_rate: f64::NAN,
            ..t
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("learning_rate")
        );
    }
}
