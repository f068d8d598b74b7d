//! The neural signed-distance auto-decoder (burn), split by role as burn's own examples split
//! model, data, training and inference:
//!
//! - [`backend`]: the only place a compute backend / device is chosen;
//! - [`model`]: the network with its explicit ∇ₓf, as one burn operation with its own backward;
//! - [`kernels`]: the host passes and loops behind those operations;
//! - [`data`]: training shapes, their one-off samples and reproducible batches;
//! - [`training`]: the IGR loss, the Adam step, presets, the training loop and latent fitting;
//! - [`store`]: saved model directories (weights, manifest, fitted anchors);
//! - [`inference`]: fields, meshes, fidelity, novelty and mixed latents of a trained model.
//!
//! Sign convention: f < 0 inside, f > 0 outside (forced by the loss with outward normals).

pub mod backend;
pub mod data;
pub mod inference;
pub mod kernels;
pub mod model;
pub mod store;
pub mod training;

pub use backend::{Backend, BackendError};
pub use inference::field::SdfField;
pub use model::decoder::SdfAutoDecoder;
pub use model::network::{
    LatentOffsets, NetworkConfigError, SdfNetwork, SdfNetworkConfig, SdfOutput,
};
pub use training::loss::{BatchError, IgrLossConfig, LossTerms, TrainingBatch, igr_loss};
pub use training::step::{SdfTrainer, TrainStepConfig, TrainStepOutput};
