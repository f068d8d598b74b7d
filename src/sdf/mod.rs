//! The neural signed-distance auto-decoder (burn): model, loss, training step and inference.
//!
//! - [`backend`]: the only place a compute backend / device is chosen.
//! - [`network`]: the DeepSDF/IGR MLP and its explicit input gradient ∇ₓf.
//! - [`fused`], [`softplus`]: the fused softplus and reverse-pass gate of a hidden layer, with
//!   their own backward (a burn backend extension over host loops).
//! - [`kernel`], [`network_op`]: the whole network (f, ∇ₓf and the backward of a loss on
//!   them) as one burn operation over host passes that keep chunks of points in cache.
//! - [`product`]: matrix products through gemm into caller-owned buffers; [`buffers`]: host
//!   buffers those passes reuse from step to step.
//! - [`decoder`]: network + per-shape latent table.
//! - [`loss`]: the IGR loss over a [`TrainingBatch`].
//! - [`step`]: one Adam step ([`SdfTrainer`]).
//! - [`field`]: fast evaluation of f and ∇f for one latent over many points.
//! - [`data`], [`cache`], [`batch`]: training shapes, their one-off samples, reproducible batches.
//! - [`config`], [`training`], [`manifest`], [`store`]: the training loop and saved models.
//! - [`reconstruct`], [`evaluation`], [`mixing`]: meshes, fidelity and mixed latents.
//!
//! Sign convention: f < 0 inside, f > 0 outside (forced by the loss with outward normals).

pub mod backend;
pub mod buffers;
pub mod decoder;
pub mod field;
pub mod fused;
pub mod kernel;
pub mod loss;
pub mod network;
pub mod network_op;
pub mod product;
pub mod softplus;
pub mod step;

pub use backend::{Backend, BackendError};
pub use decoder::SdfAutoDecoder;
pub use field::SdfField;
pub use loss::{BatchError, IgrLossConfig, LossTerms, TrainingBatch, igr_loss};
pub use network::{LatentOffsets, NetworkConfigError, SdfNetwork, SdfNetworkConfig, SdfOutput};
pub use step::{SdfTrainer, TrainStepConfig, TrainStepOutput};

pub mod anchors;
pub mod batch;
pub mod cache;
pub mod config;
pub mod data;
pub mod evaluation;
pub mod fit;
pub mod manifest;
pub mod mixing;
pub mod novelty;
pub mod reconstruct;
pub mod store;
pub mod training;
