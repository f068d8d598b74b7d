//! The science engine: what cohorts, jobs and the command line need from a trained model.
//! Everything above this module depends only on the [`Engine`] trait, so the neural model
//! ([`SdfEngine`]) plugs in behind it and tests can run the whole service on an analytic
//! stand-in.

mod cache;
mod neural;

pub use neural::{EVALUATION_FILE, SdfEngine, read_evaluation};

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64};

use serde::{Deserialize, Serialize};

use crate::geometry::TriMesh;
use crate::geometry::normalize::UnitBallTransform;
use crate::sdf::inference::novelty::NoveltyReference;

/// Facts about a registered model, reported by the engine and stored as its manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelInfo {
    /// Latent code dimension d.
    pub latent_dim: usize,
    /// Free-form description of the network (layers, width, activation …).
    pub architecture: serde_json::Value,
    /// The training shapes, in latent order.
    pub training_shapes: Vec<TrainingShapeInfo>,
    /// Whether every training shape was re-fitted with the network frozen (density
    /// samplers may then draw from the re-fitted latents).
    #[serde(default)]
    pub refitted_latents: bool,
}

impl ModelInfo {
    /// A model of `latent_dim` with training shapes named by `names` (in latent order), no
    /// reconstruction figures, no re-fitted latents and no architecture description: what
    /// the request checks look at.
    pub fn with_shapes(latent_dim: usize, names: impl IntoIterator<Item = String>) -> Self {
        Self {
            latent_dim,
            architecture: serde_json::Value::Null,
            training_shapes: names
                .into_iter()
                .enumerate()
                .map(|(index, name)| TrainingShapeInfo {
                    index,
                    name,
                    reconstruction_cd: None,
                })
                .collect(),
            refitted_latents: false,
        }
    }

    /// Number of training shapes (the upper bound of a cohort's arity).
    pub fn training_shape_count(&self) -> usize {
        self.training_shapes.len()
    }
}

/// One training shape of a model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingShapeInfo {
    /// Index of its latent vector.
    pub index: usize,
    /// Source file name or label.
    pub name: String,
    /// Chamfer distance of its reconstruction to the original (unit-ball coordinates), if
    /// measured.
    pub reconstruction_cd: Option<f64>,
}

/// What to generate: a convex combination of training latents, or of a latent drawn from a
/// density sampler, and of fitted anchors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShapeSpec {
    /// Training shapes mixed (distinct; empty when the latent is sampled).
    pub training_indices: Vec<usize>,
    /// Weights of the training shapes, then of the sampled latent (if any), then of the
    /// anchors (non-negative, summing to 1).
    pub weights: Vec<f64>,
    /// Seed for any randomness inside generation.
    pub seed: u64,
    /// Marching-cubes grid resolution per axis.
    pub resolution: usize,
    /// Gaussian noise added to the mixed latent, in training standard deviations per
    /// dimension, drawn from `seed` (0 = the plain convex combination).
    #[serde(default)]
    pub latent_noise: f64,
    /// Fitted latents mixed as well; their weights come last in `weights`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub anchors: Vec<AnchorLatent>,
    /// A latent drawn from a density sampler with its transform (instead of training
    /// shapes); its weight follows the training shapes' in `weights`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampled: Option<SampledLatent>,
}

/// A latent drawn from a density sampler, with the unit-ball transform drawn with it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampledLatent {
    /// The latent code (the model's latent dimension).
    pub latent: Vec<f32>,
    /// Unit ball → mm of the drawn shape.
    pub transform: UnitBallTransform,
}

impl ShapeSpec {
    /// Members of the mixture before the anchors: the training shapes, or the sampled latent.
    pub fn drawn_members(&self) -> usize {
        self.training_indices.len() + usize::from(self.sampled.is_some())
    }
}

impl ShapeSpec {
    /// Training shape `index` alone (weight 1, no noise), meshed at `resolution`.
    pub fn single(index: usize, resolution: usize) -> Self {
        Self {
            training_indices: vec![index],
            weights: vec![1.0],
            seed: 0,
            resolution,
            latent_noise: 0.0,
            anchors: Vec::new(),
            sampled: None,
        }
    }
}

/// A fitted latent (an anchor) taking part in a mixture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnchorLatent {
    /// The anchor's name (unique per model).
    pub name: String,
    /// Its latent code.
    pub latent: Vec<f32>,
    /// Its mesh's unit-ball transform (blended like the training shapes').
    pub transform: UnitBallTransform,
}

/// One generated shape.
#[derive(Debug, Clone)]
pub struct GeneratedShape {
    /// The mesh in unit-ball coordinates (what is stored).
    pub mesh_unit: TriMesh,
    /// Unit ball → millimetres.
    pub transform: UnitBallTransform,
    /// Surface area in mm².
    pub area_mm2: f64,
    /// Enclosed volume in mm³.
    pub volume_mm3: f64,
}

/// A model-training request: meshes already written to `input_dir`, weights to go to
/// `model_dir`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingSpec {
    /// Directory holding the uploaded mesh files.
    pub input_dir: std::path::PathBuf,
    /// Directory to write the trained model into.
    pub model_dir: std::path::PathBuf,
    /// Seed for initialisation and sampling.
    pub seed: u64,
    /// Epochs to train (the engine's default when absent).
    #[serde(default)]
    pub epochs: Option<u64>,
    /// Uploaded shapes to keep out of training, chosen from `seed` (none: train on all).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout: Option<usize>,
    /// Digest of the input files' bundle in the object store: a worker on a machine
    /// without `input_dir` fetches them from there.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_digest: Option<String>,
}

/// A request to fit a latent to a new mesh for a trained model (network frozen).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitSpec {
    /// The uploaded mesh file (its extension or content tells the format).
    pub mesh_path: std::path::PathBuf,
    /// Adam steps on the latent.
    pub iterations: usize,
    /// Seed of the sampling and the batches.
    pub seed: u64,
    /// SHA-256 of the mesh file, kept in the object store: a worker on a machine without
    /// `mesh_path` fetches it from there.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh_sha256: Option<String>,
}

/// How a model's training shapes are fitted again with the network frozen (a refit).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RefitSpec {
    /// Adam steps of every fit.
    pub iterations: usize,
    /// Seed of training shape 0's fit; shape i uses `seed + 2 i` (as `aortagen refit`).
    pub seed: u64,
}

/// A fitted latent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FittedAnchor {
    /// The latent code (the model's latent dimension).
    pub latent: Vec<f32>,
    /// Mesh units ↔ unit ball of the fitted mesh.
    pub transform: UnitBallTransform,
    /// Reconstruction Chamfer distance (unit-ball coordinates, as for training shapes).
    pub chamfer: f64,
}

impl FittedAnchor {
    /// Refuses a fit whose latent or Chamfer distance is not finite (nothing such is stored).
    pub fn check_finite(&self) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.chamfer.is_finite() && self.latent.iter().all(|v| v.is_finite()),
            "the engine returned a non-finite latent or Chamfer distance"
        );
        Ok(())
    }
}

/// The science engine, as the job worker calls it. Every method is blocking CPU work and is
/// called inside `spawn_blocking`.
pub trait Engine: Send + Sync + 'static {
    /// Facts about the model stored in `model_dir` (used for validation and the API).
    fn model_info(&self, model_dir: &Path) -> anyhow::Result<ModelInfo>;

    /// The model's training latents, in index order (for spread selection).
    fn training_latents(&self, model_dir: &Path) -> anyhow::Result<Vec<Vec<f32>>>;

    /// The training shapes re-fitted with the network frozen (`aortagen refit`): latents
    /// and transforms in index order; none unless every training shape has one.
    fn refitted_latents(
        &self,
        model_dir: &Path,
    ) -> anyhow::Result<Option<crate::sdf::store::refits::RefittedLatents>> {
        let _ = model_dir;
        Ok(None)
    }

    /// The training shapes' unit-ball transforms, in index order (density samplers model
    /// them with the latents).
    fn training_transforms(&self, model_dir: &Path) -> anyhow::Result<Vec<UnitBallTransform>> {
        let _ = model_dir;
        anyhow::bail!("this engine keeps no training transforms")
    }

    /// Generates one shape. Returns early with an error once `cancel` becomes true.
    fn generate_shape(
        &self,
        model_dir: &Path,
        spec: &ShapeSpec,
        cancel: &AtomicBool,
    ) -> anyhow::Result<GeneratedShape>;

    /// The model's training surfaces at `resolution` (unit-ball coordinates), sampled and
    /// indexed to measure generated shapes' novelty against. Built once per model and
    /// resolution and cached; returns early with an error once `cancel` becomes true.
    fn novelty_reference(
        &self,
        model_dir: &Path,
        resolution: usize,
        cancel: &AtomicBool,
    ) -> anyhow::Result<Arc<NoveltyReference>>;

    /// Training shape `index` as the model reconstructs it at `resolution` (unit-ball
    /// coordinates): one surface of the novelty reference, which a caller may store and
    /// pass back to [`Engine::novelty_reference_from`] instead of recomputing it. Returns
    /// early with an error once `cancel` becomes true.
    fn training_surface(
        &self,
        model_dir: &Path,
        index: usize,
        resolution: usize,
        cancel: &AtomicBool,
    ) -> anyhow::Result<TriMesh>;

    /// The novelty reference of the model at `resolution` if this engine already holds it
    /// (built by [`Engine::novelty_reference`] or [`Engine::novelty_reference_from`]), so a
    /// caller with stored surfaces need not read and sample them again.
    fn cached_novelty_reference(
        &self,
        _model_dir: &Path,
        _resolution: usize,
    ) -> Option<Arc<NoveltyReference>> {
        None
    }

    /// The novelty reference of the model at `resolution` over `surfaces`, its training
    /// surfaces in index order, sampled exactly as [`Engine::novelty_reference`] samples
    /// them; an engine with a cache keeps it as that model's and resolution's reference.
    fn novelty_reference_from(
        &self,
        model_dir: &Path,
        resolution: usize,
        surfaces: &[TriMesh],
    ) -> anyhow::Result<Arc<NoveltyReference>>;

    /// Chamfer distances (unit-ball coordinates) of `pairs` of a cohort's shapes, named by
    /// their index in the cohort; `meshes` holds each named shape with its index. A shape's
    /// surface sample depends only on `seed` and its index, so a pair's distance is the same
    /// whichever other pairs are computed with it.
    fn pair_chamfer(
        &self,
        meshes: &[(u32, TriMesh)],
        pairs: &[(u32, u32)],
        seed: u64,
    ) -> anyhow::Result<Vec<f64>>;

    /// Trains a model from the meshes in `spec.input_dir`, writes it to `spec.model_dir`
    /// and reports its facts. A run interrupted earlier continues from its last checkpoint
    /// in `spec.model_dir`. `progress` holds the epochs completed and saved so far (what an
    /// interruption cannot lose). Returns early with an error once `cancel` becomes true.
    fn train_model(
        &self,
        spec: &TrainingSpec,
        cancel: &AtomicBool,
        progress: &AtomicU64,
    ) -> anyhow::Result<ModelInfo>;

    /// Fits a latent to the mesh in `spec.mesh_path` for the model in `model_dir`, its
    /// network frozen. `progress` holds the steps done. Returns early with an error once
    /// `cancel` becomes true. Engines without a trainable model refuse.
    fn fit_anchor(
        &self,
        model_dir: &Path,
        spec: &FitSpec,
        cancel: &AtomicBool,
        progress: &AtomicU64,
    ) -> anyhow::Result<FittedAnchor> {
        let _ = (model_dir, spec, cancel, progress);
        anyhow::bail!("this engine cannot fit new shapes")
    }

    /// Fits training shape `index` of the model in `model_dir` again, its network frozen,
    /// exactly as `aortagen refit` fits it (the same latent for the same settings), from the
    /// training data the model's manifest names. `progress` holds the steps done. Returns
    /// early with an error once `cancel` becomes true. Engines without a trainable model
    /// refuse.
    fn refit_training_shape(
        &self,
        model_dir: &Path,
        index: usize,
        spec: &RefitSpec,
        cancel: &AtomicBool,
        progress: &AtomicU64,
    ) -> anyhow::Result<FittedAnchor> {
        let _ = (model_dir, index, spec, cancel, progress);
        anyhow::bail!("this engine cannot re-fit training shapes")
    }
}

/// The text of a panic's payload (the engine's numerics report failures by panicking).
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "non-string panic payload".into())
}

/// An engine that refuses every call: what the service runs on when no science engine is
/// linked in. Jobs fail with a clear message instead of the service refusing to start.
#[derive(Debug, Clone, Copy, Default)]
pub struct UnavailableEngine;

impl UnavailableEngine {
    fn refuse<T>(&self) -> anyhow::Result<T> {
        anyhow::bail!("no science engine is linked into this build of aortagen")
    }
}

impl Engine for UnavailableEngine {
    fn model_info(&self, _: &Path) -> anyhow::Result<ModelInfo> {
        self.refuse()
    }

    fn training_latents(&self, _: &Path) -> anyhow::Result<Vec<Vec<f32>>> {
        self.refuse()
    }

    fn generate_shape(
        &self,
        _: &Path,
        _: &ShapeSpec,
        _: &AtomicBool,
    ) -> anyhow::Result<GeneratedShape> {
        self.refuse()
    }

    fn novelty_reference(
        &self,
        _: &Path,
        _: usize,
        _: &AtomicBool,
    ) -> anyhow::Result<Arc<NoveltyReference>> {
        self.refuse()
    }

    fn training_surface(
        &self,
        _: &Path,
        _: usize,
        _: usize,
        _: &AtomicBool,
    ) -> anyhow::Result<TriMesh> {
        self.refuse()
    }

    fn novelty_reference_from(
        &self,
        _: &Path,
        _: usize,
        _: &[TriMesh],
    ) -> anyhow::Result<Arc<NoveltyReference>> {
        self.refuse()
    }

    fn pair_chamfer(
        &self,
        _: &[(u32, TriMesh)],
        _: &[(u32, u32)],
        _: u64,
    ) -> anyhow::Result<Vec<f64>> {
        self.refuse()
    }

    fn train_model(
        &self,
        _: &TrainingSpec,
        _: &AtomicBool,
        _: &AtomicU64,
    ) -> anyhow::Result<ModelInfo> {
        self.refuse()
    }
}
