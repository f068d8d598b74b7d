//! One optimisation step: IGR loss, first-order backward, Adam over network and latents.

use burn::config::Config;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::Tensor;

use crate::sdf::model::decoder::SdfAutoDecoder;
use crate::sdf::training::loss::{BatchError, IgrLossConfig, LossTerms, TrainingBatch, igr_loss};

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
            .try_to_vec::<f32>()
            .map_or(f32::NAN, |v| v[0])
    }
}

/// A model on an autodiff device together with its Adam state.
pub struct SdfTrainer {
    model: Option<SdfAutoDecoder>,
    optimizer: ModuleOptimizer,
    config: TrainStepConfig,
    _buffers: ReleaseBuffersOnDrop,
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
            _buffers: ReleaseBuffersOnDrop,
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
            _buffers: ReleaseBuffersOnDrop,
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

/// Frees the pooled host buffers when the trainer holding it goes: the network operation's
/// saved values and scratch stay pooled between steps, and once a run ends they are freed
/// instead of staying with the process.
#[derive(Debug, Default)]
struct ReleaseBuffersOnDrop;

impl Drop for ReleaseBuffersOnDrop {
    fn drop(&mut self) {
        crate::sdf::kernels::buffers::release_free_buffers();
    }
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    use super::*;
    use crate::sdf::Backend;
    use crate::sdf::model::network::SdfNetworkConfig;

    /// Surface samples of an axis-aligned ellipsoid with outward unit normals.
    fn ellipsoid(axes: [f32; 3], n: usize, rng: &mut ChaCha8Rng) -> Vec<([f32; 3], [f32; 3])> {
        (0..n)
            .map(|_| {
                let u: [f32; 3] = std::array::from_fn(|_| StandardNormal.sample(rng));
                let l = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
                let p: [f32; 3] = std::array::from_fn(|k| u[k] / l * axes[k]);
                let m: [f32; 3] = std::array::from_fn(|k| p[k] / (axes[k] * axes[k]));
                let ml = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
                (p, m.map(|c| c / ml))
            })
            .collect()
    }

    fn batch(shapes: &[[f32; 3]], n: usize, rng: &mut ChaCha8Rng) -> TrainingBatch {
        let mut b = TrainingBatch::default();
        for (k, &axes) in shapes.iter().enumerate() {
            b.shape_indices.push(k);
            for (i, (p, nrm)) in ellipsoid(axes, n, rng).into_iter().enumerate() {
                b.surface_points.push(p);
                b.surface_normals.push(nrm);
                b.eikonal_points.push(if i % 2 == 0 {
                    p.map(|c| c + 0.05 * Distribution::<f32>::sample(&StandardNormal, rng))
                } else {
                    std::array::from_fn(|_| rng.random_range(-1.0f32..1.0))
                });
            }
        }
        b
    }

    #[test]
    fn loss_falls_over_thirty_steps_on_a_sphere_and_an_ellipsoid() {
        let device = Backend::Flex.device(true).unwrap();
        let config = SdfNetworkConfig::new().with_latent_dim(8).with_hidden(64);
        let model = SdfAutoDecoder::new(&config, 2, 3, &device).unwrap();
        let before = model.latents_to_vec();
        let mut trainer = SdfTrainer::new(model, TrainStepConfig::new());
        let shapes = [[0.6, 0.6, 0.6], [0.8, 0.35, 0.5]];
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let losses: Vec<f32> = (0..30)
            .map(|_| {
                trainer
                    .step(&batch(&shapes, 128, &mut rng), 1e-3)
                    .unwrap()
                    .loss
            })
            .collect();
        let first = losses[..3].iter().sum::<f32>() / 3.0;
        let last = losses[27..].iter().sum::<f32>() / 3.0;
        assert!(last < 0.5 * first, "loss did not fall: {losses:?}");
        assert!(losses.iter().all(|l| l.is_finite()));
        let after = trainer.model().latents_to_vec();
        assert!(
            before.iter().zip(&after).all(|(b, a)| b != a),
            "latents were not optimised"
        );
    }

    #[test]
    fn a_bad_batch_is_an_error_and_keeps_the_model() {
        let device = Backend::Flex.device(true).unwrap();
        let config = SdfNetworkConfig::new().with_latent_dim(4).with_hidden(16);
        let model = SdfAutoDecoder::new(&config, 2, 3, &device).unwrap();
        let mut trainer = SdfTrainer::new(model, TrainStepConfig::new());
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut bad = batch(&[[0.5; 3]], 8, &mut rng);
        bad.shape_indices = vec![5];
        assert!(matches!(
            trainer.step(&bad, 1e-3),
            Err(BatchError::ShapeIndex { index: 5, .. })
        ));
        assert_eq!(trainer.model().num_shapes(), 2);
        assert!(
            trainer
                .step(&batch(&[[0.5; 3], [0.4; 3]], 8, &mut rng), 1e-3)
                .is_ok()
        );
    }
}
