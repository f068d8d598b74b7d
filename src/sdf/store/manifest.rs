//! `manifest.json`: what a saved model is, how it was trained, and how to check its weights.
//!
//! A model directory holds `manifest.json`, the weights (`weights.bpk`, burn's burnpack
//! format) and, while training can still be resumed, the Adam state (`optimizer.bpk`). The
//! manifest records the architecture, the training configuration, every training shape's name
//! and unit-ball transform, the per-epoch loss history, the software version, the backend and
//! the SHA-256 of the weights file, which is both the integrity check and the model's identity.

use serde::{Deserialize, Serialize};

use crate::geometry::normalize::UnitBallTransform;
use crate::sdf::data::holdout::Holdout;
use crate::sdf::data::{DataSource, SamplingSettings};
use crate::sdf::model::network::SdfNetworkConfig;
use crate::sdf::training::config::TrainingConfig;

/// Value of the `format` field: identifies a file as an aortagen model manifest.
pub const MANIFEST_FORMAT: &str = "aortagen-sdf-model";
/// The manifest layout this build reads and writes.
pub const MANIFEST_VERSION: u32 = 1;
/// File name of the manifest inside a model directory.
pub const MANIFEST_FILE: &str = "manifest.json";
/// File name of the weights inside a model directory.
pub const WEIGHTS_FILE: &str = "weights.bpk";
/// File name of the optimizer state inside a model directory.
pub const OPTIMIZER_FILE: &str = "optimizer.bpk";
/// The sign convention of every model's field, recorded for readers of the files.
pub const SIGN_CONVENTION: &str = "f < 0 inside, f > 0 outside (outward normals)";

/// One training shape as recorded in the manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShapeRecord {
    /// Display name (file stem or generated name).
    pub name: String,
    /// Mesh units ↔ unit ball.
    pub transform: UnitBallTransform,
}

/// Mean loss terms over one epoch's steps, each already weighted as in the total (eq. 4).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct EpochLoss {
    /// Epoch number, 1-based.
    pub epoch: u64,
    /// Total loss.
    pub total: f64,
    /// mean |f| on surface points.
    pub surface: f64,
    /// mean ‖∇f − n‖² on surface points.
    pub normal: f64,
    /// τ · mean (‖∇f‖ − 1)² on eikonal points.
    pub eikonal: f64,
    /// λ · mean ‖z‖ over the batch's shapes.
    pub latent: f64,
}

/// Where training stands; lets `--resume` continue from the exact next step.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainingProgress {
    /// Epochs fully done.
    pub epochs_completed: u64,
    /// Batches of the current (unfinished) epoch already done; 0 at an epoch boundary.
    pub next_batch: u64,
    /// Loss sums of the unfinished epoch's done batches (to finish its mean on resume).
    pub partial_sums: EpochLoss,
    /// True once all configured epochs ran.
    pub complete: bool,
}

/// Identity and checksum of a stored file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileRecord {
    /// File name inside the model directory.
    pub file: String,
    /// Lower-case hex SHA-256 of its bytes.
    pub sha256: String,
    /// Its length in bytes.
    pub bytes: u64,
}

/// Which data the model was trained on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DataRecord {
    /// Directory or parametric generator.
    pub source: DataSource,
    /// How each shape was sampled once.
    pub sampling: SamplingSettings,
    /// Hash of the inputs and settings (names the sample cache).
    pub dataset_key: String,
    /// Source shapes kept out of training (none: every source shape trained).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout: Option<Holdout>,
}

/// The whole manifest.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelManifest {
    /// Always [`MANIFEST_FORMAT`].
    pub format: String,
    /// Layout version, [`MANIFEST_VERSION`] when written by this build.
    pub format_version: u32,
    /// Version of the software that wrote it.
    pub software_version: String,
    /// burn backend used for training (`flex`, `ndarray`).
    pub backend: String,
    /// Field sign convention.
    pub sign_convention: String,
    /// Network shape (d, H, layers, skip layer, β, initial sphere radius); checked against
    /// the stored tensor shapes on load.
    pub architecture: SdfNetworkConfig,
    /// Training hyper-parameters.
    pub training: TrainingConfig,
    /// Training data.
    pub data: DataRecord,
    /// Training shapes, in latent-row order.
    pub shapes: Vec<ShapeRecord>,
    /// Where training stands.
    pub progress: TrainingProgress,
    /// Mean losses of every completed epoch.
    pub loss_history: Vec<EpochLoss>,
    /// The weights file.
    pub weights: FileRecord,
    /// The optimizer state file (present while training can resume).
    pub optimizer: Option<FileRecord>,
}

impl ModelManifest {
    /// Short identity of the trained weights: the first 16 hex digits of their SHA-256.
    pub fn model_id(&self) -> &str {
        &self.weights.sha256[..16.min(self.weights.sha256.len())]
    }

    /// The unit-ball transforms in latent-row order.
    pub fn transforms(&self) -> Vec<UnitBallTransform> {
        self.shapes.iter().map(|s| s.transform).collect()
    }
}
