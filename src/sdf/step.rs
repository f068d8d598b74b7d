//! One optimisation step: IGR loss, first-order backward, Adam over network and latents.

use burn::config::Config;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::Tensor;

use super::decoder::SdfAutoDecoder;
use super::loss::{BatchError, IgrLossConfig, LossTerms, TrainingBatch, igr_loss};

/// Optimiser settings of a training step (the learning-rate schedule is the caller's).
#[derive(Config, Debug)]
pub struct TrainStepConfig {
    /// Loss weights.
    #[config(default = "IgrLossConfig::new()")]
    pub loss: IgrLossConfig,
    /// Adam β₁.
    #[config(default = 0.9)]
    pub beta_1: f32,
    /// Adam β₂.
    #[config(default = 0.999)]
    pub beta_2: f32,
    /// Adam ε (PyTorch's default, which the reference trains with).
    #[config(default = 1e-8)]
    pub epsilon: f32,
}

/// The loss terms of one step, read back to the host (values before the update).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrainStepOutput {
    /// Total loss.
    pub loss: f32,
    /// mean |f| on surface points.
    pub surface: f32,
    /// mean ‖∇f − n‖².
    pub normal: f32,
    /// τ · mean (‖∇f‖ − 1)².
    pub eikonal: f32,
    /// λ · mean ‖z‖.
    pub latent: f32,
}

impl TrainStepOutput {
    /// Reads the scalar terms (one host sync).
    pub fn from_terms(terms: &LossTerms) -> Self {
        let read = |t: &Tensor<1>| t.clone().into_scalar_as_f32();
        Self {
            loss: read(&terms.total),
            surface: read(&terms.surface),
            normal: read(&terms.normal),
            eikonal: read(&terms.eikonal),
            latent: read(&terms.latent),
        }
    }
}

/// Extension to read a one-element tensor as f32 whatever its dtype.
trait ScalarF32 {
    fn into_scalar_as_f32(self) -> f32;
}

impl ScalarF32 for Tensor<1> {
    fn into_scalar_as_f32(self) -> f32 {
        self.into_data()
            .convert::<f32>()
            .to_vec::<f32>()
            .map_or(f32::NAN, |v| v[0])
    }
}

/// A model on an autodiff device together with its Adam state.
pub struct SdfTrainer {
    model: Option<SdfAutoDecoder>,
    optimizer: ModuleOptimizer,
    config: TrainStepConfig,
}

impl SdfTrainer {
    /// Starts training `model` (which must live on an autodiff device) with fresh Adam state.
    pub fn new(model: SdfAutoDecoder, config: TrainStepConfig) -> Self {
        let optimizer = AdamConfig::new()
            .with_beta_1(config.beta_1)
            .with_beta_2(config.beta_2)
            .with_epsilon(config.epsilon)
            .init();
        Self {
            model: Some(model),
            optimizer,
            config,
        }
    }

    /// Continues with a previously saved optimiser (e.g. when resuming).
    pub fn with_optimizer(
        model: SdfAutoDecoder,
        optimizer: ModuleOptimizer,
        config: TrainStepConfig,
    ) -> Self {
        Self {
            model: Some(model),
            optimizer,
            config,
        }
    }

    /// The current model.
    pub fn model(&self) -> &SdfAutoDecoder {
        self.model.as_ref().expect("model present between steps")
    }

    /// The Adam state (to save for resuming).
    pub fn optimizer(&self) -> &ModuleOptimizer {
        &self.optimizer
    }

    /// The model and optimiser, ending training.
    pub fn into_parts(self) -> (SdfAutoDecoder, ModuleOptimizer) {
        (
            self.model.expect("model present between steps"),
            self.optimizer,
        )
    }

    /// One step with learning rate `lr`: loss on `batch`, backward, Adam update of the network
    /// and of the latent table. Returns the loss terms before the update. A bad batch is
    /// rejected before anything changes.
    pub fn step(&mut self, batch: &TrainingBatch, lr: f64) -> Result<TrainStepOutput, BatchError> {
        let model = self.model.take().expect("model present between steps");
        let terms = match igr_loss(&model, batch, &self.config.loss) {
            Ok(terms) => terms,
            Err(e) => {
                self.model = Some(model);
                return Err(e);
            }
        };
        let output = TrainStepOutput::from_terms(&terms);
        let grads = GradientsParams::from_grads(terms.total.backward(), &model);
        self.model = Some(self.optimizer.step(lr, model, grads));
        Ok(output)
    }
}
