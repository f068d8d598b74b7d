//! New shapes as convex combinations of learned latents (DESIGN §4).
//!
//! A cohort shape picks `k` distinct training indices uniformly (the arity), weights them
//! (given, equal, or Dirichlet(1) drawn from the seed), and decodes
//! `z = Σ αᵢ z_{iᵢ}`; its mesh-units transform is the same convex combination of the chosen
//! shapes' transforms. Shape `j` of a cohort draws from its own stream `(seed, j)`, so a
//! cohort is reproducible shape by shape whatever its size or the order of the work.
//! The CLI and the HTTP service share this validation and mixing.

use rand::RngExt;
use rand::seq::index;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::manifest::SIGN_CONVENTION;
use super::reconstruct::{ExtractionMethod, ReconstructError, reconstruct};
use super::store::LoadedModel;
use crate::geometry::TriMesh;
use crate::geometry::normalize::{BlendError, UnitBallTransform};

/// Allowed deviation of the weights' sum from 1.
pub const WEIGHT_SUM_TOLERANCE: f64 = 1e-6;

/// How weights are chosen when they are not given.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Weighting {
    /// αᵢ = 1/k.
    Equal,
    /// α ~ Dirichlet(1, …, 1), uniform on the simplex, drawn from the seed.
    Dirichlet,
}

/// The mixing part of a cohort request.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MixSpec {
    /// Number of training shapes combined per generated shape, `k`.
    pub arity: usize,
    /// Fixed weights (length `k`); when absent `weighting` decides.
    pub weights: Option<Vec<f64>>,
    /// Strategy used when `weights` is absent.
    pub weighting: Weighting,
}

/// A rule of the cohort request that the input breaks; the message names the field and rule.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CohortSpecError {
    /// Fewer than two shapes combined.
    #[error("arity must be at least 2 (got {arity})")]
    ArityTooSmall {
        /// The requested arity.
        arity: usize,
    },
    /// More shapes combined than the model was trained on.
    #[error("arity must not exceed the model's {shapes} training shapes (got {arity})")]
    ArityTooLarge {
        /// The requested arity.
        arity: usize,
        /// Training shapes in the model.
        shapes: usize,
    },
    /// Weights list of the wrong length.
    #[error("weights must have exactly arity = {arity} entries (got {found})")]
    WeightCount {
        /// The requested arity.
        arity: usize,
        /// Number of weights given.
        found: usize,
    },
    /// A weight that is NaN or infinite.
    #[error("weights must be finite numbers (weight {index} is {value})")]
    NonFiniteWeight {
        /// Zero-based position in the list.
        index: usize,
        /// The value.
        value: f64,
    },
    /// A negative weight.
    #[error("weights must each be ≥ 0 (weight {index} is {value})")]
    NegativeWeight {
        /// Zero-based position in the list.
        index: usize,
        /// The value.
        value: f64,
    },
    /// Weights that do not sum to one.
    #[error("weights must sum to 1 within 1e-6 (they sum to {sum})")]
    WeightSum {
        /// The sum.
        sum: f64,
    },
}

impl CohortSpecError {
    /// The request field the error is about (`arity` or `weights`), for API error bodies.
    pub fn field(&self) -> &'static str {
        match self {
            Self::ArityTooSmall { .. } | Self::ArityTooLarge { .. } => "arity",
            _ => "weights",
        }
    }
}

impl MixSpec {
    /// Checks the spec against a model with `num_shapes` training shapes.
    pub fn validate(&self, num_shapes: usize) -> Result<(), CohortSpecError> {
        let arity = self.arity;
        if arity < 2 {
            return Err(CohortSpecError::ArityTooSmall { arity });
        }
        if arity > num_shapes {
            let shapes = num_shapes;
            return Err(CohortSpecError::ArityTooLarge { arity, shapes });
        }
        let Some(weights) = &self.weights else {
            return Ok(());
        };
        if weights.len() != arity {
            let found = weights.len();
            return Err(CohortSpecError::WeightCount { arity, found });
        }
        for (index, &value) in weights.iter().enumerate() {
            if !value.is_finite() {
                return Err(CohortSpecError::NonFiniteWeight { index, value });
            }
            if value < 0.0 {
                return Err(CohortSpecError::NegativeWeight { index, value });
            }
        }
        let sum: f64 = weights.iter().sum();
        if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
            return Err(CohortSpecError::WeightSum { sum });
        }
        Ok(())
    }

    /// The mixture of cohort shape `shape` (validates first).
    pub fn mixture(
        &self,
        num_shapes: usize,
        seed: u64,
        shape: u64,
    ) -> Result<Mixture, CohortSpecError> {
        self.validate(num_shapes)?;
        let mut rng = mixture_rng(seed, shape);
        let indices = index::sample(&mut rng, num_shapes, self.arity).into_vec();
        let weights = match (&self.weights, self.weighting) {
            (Some(w), _) => w.clone(),
            (None, Weighting::Equal) => vec![1.0 / self.arity as f64; self.arity],
            (None, Weighting::Dirichlet) => dirichlet_ones(&mut rng, self.arity),
        };
        Ok(Mixture { indices, weights })
    }
}

/// Which training shapes a generated shape combines, and how much of each.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mixture {
    /// Distinct training indices.
    pub indices: Vec<usize>,
    /// Convex weights, one per index.
    pub weights: Vec<f64>,
}

impl Mixture {
    /// `Σ αᵢ z_{iᵢ}` over rows of `latents` (each of the latent dimension), accumulated in f64.
    pub fn mix_latents(&self, latents: &[Vec<f32>]) -> Vec<f32> {
        let dim = latents.first().map_or(0, Vec::len);
        let mut z = vec![0.0f64; dim];
        for (&i, &w) in self.indices.iter().zip(&self.weights) {
            for (acc, &v) in z.iter_mut().zip(&latents[i]) {
                *acc += w * f64::from(v);
            }
        }
        z.into_iter().map(|v| v as f32).collect()
    }

    /// The same convex combination of the shapes' unit-ball transforms.
    pub fn mix_transforms(
        &self,
        transforms: &[UnitBallTransform],
    ) -> Result<UnitBallTransform, BlendError> {
        let parts: Vec<(f64, &UnitBallTransform)> = self
            .indices
            .iter()
            .zip(&self.weights)
            .map(|(&i, &w)| (w, &transforms[i]))
            .collect();
        UnitBallTransform::blend(&parts)
    }
}

fn mixture_rng(seed: u64, shape: u64) -> ChaCha8Rng {
    super::batch::stream_rng(seed, shape, 0, 0x4d49_5845)
}

/// Dirichlet(1,…,1): normalised standard exponentials, −ln(1−U).
fn dirichlet_ones(rng: &mut ChaCha8Rng, k: usize) -> Vec<f64> {
    let draws: Vec<f64> = (0..k).map(|_| -(1.0 - rng.random::<f64>()).ln()).collect();
    let sum: f64 = draws.iter().sum();
    if sum > 0.0 {
        draws.into_iter().map(|e| e / sum).collect()
    } else {
        vec![1.0 / k as f64; k]
    }
}

/// Parses `"0.5,0.25,0.25"` into weights (whitespace allowed), naming a bad entry.
pub fn parse_weights(text: &str) -> Result<Vec<f64>, String> {
    text.split(',')
        .enumerate()
        .map(|(i, s)| {
            s.trim()
                .parse::<f64>()
                .map_err(|e| format!("weight {i} ({:?}) is not a number: {e}", s.trim()))
        })
        .collect()
}

/// Why a shape could not be generated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GenerateError {
    /// The request breaks a rule.
    #[error(transparent)]
    Spec(#[from] CohortSpecError),
    /// The stored transforms cannot be blended (a damaged manifest).
    #[error("cannot blend the shapes' transforms: {0}")]
    Blend(#[from] BlendError),
    /// The mixed latent gave no mesh.
    #[error(transparent)]
    Reconstruct(#[from] ReconstructError),
}

/// One generated shape before it is written anywhere.
#[derive(Debug, Clone)]
pub struct GeneratedShape {
    /// Which training shapes, with which weights.
    pub mixture: Mixture,
    /// Blended unit-ball transform (to return the mesh in mesh units).
    pub transform: UnitBallTransform,
    /// The mesh in unit-ball coordinates, with normals.
    pub mesh: TriMesh,
}

impl GeneratedShape {
    /// The mesh in the training meshes' units (mm for SynthAorta and the parametric roots).
    pub fn mesh_in_mesh_units(&self) -> TriMesh {
        self.transform.mesh_to_mesh_units(&self.mesh)
    }
}

/// Generates cohort shape `shape` of `seed`: mixture, blended latent and transform, mesh.
pub fn generate_shape(
    model: &LoadedModel,
    latents: &[Vec<f32>],
    spec: &MixSpec,
    seed: u64,
    shape: u64,
    resolution: usize,
    extraction: ExtractionMethod,
) -> Result<GeneratedShape, GenerateError> {
    let mixture = spec.mixture(latents.len(), seed, shape)?;
    let transform = mixture.mix_transforms(&model.manifest.transforms())?;
    let field = model
        .field(&mixture.mix_latents(latents))
        .map_err(ReconstructError::from)?;
    let mesh = reconstruct(&field, resolution, extraction)?.mesh;
    Ok(GeneratedShape {
        mixture,
        transform,
        mesh,
    })
}

/// Where a generated mesh comes from; written beside every mesh (and stored by the service).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// Model identity (weights hash prefix).
    pub model_id: String,
    /// Full SHA-256 of the model's weights.
    pub model_sha256: String,
    /// Position of the shape in its cohort.
    pub shape_index: u64,
    /// Training indices combined.
    pub indices: Vec<usize>,
    /// Names of those training shapes.
    pub names: Vec<String>,
    /// Their weights.
    pub weights: Vec<f64>,
    /// Cohort seed.
    pub seed: u64,
    /// Grid resolution of the reconstruction.
    pub resolution: usize,
    /// Software version.
    pub software_version: String,
    /// Units of the mesh coordinates (`mm` or `unit`).
    pub units: String,
    /// Field sign convention.
    pub sign_convention: String,
    /// Blended unit-ball transform.
    pub transform: UnitBallTransform,
}

impl Provenance {
    /// The provenance of `shape` generated from `model`.
    pub fn new(
        model: &LoadedModel,
        generated: &GeneratedShape,
        seed: u64,
        shape_index: u64,
        resolution: usize,
        units: &str,
    ) -> Self {
        let names = &model.manifest.shapes;
        Self {
            model_id: model.manifest.model_id().to_string(),
            model_sha256: model.manifest.weights.sha256.clone(),
            shape_index,
            indices: generated.mixture.indices.clone(),
            names: generated
                .mixture
                .indices
                .iter()
                .map(|&i| names[i].name.clone())
                .collect(),
            weights: generated.mixture.weights.clone(),
            seed,
            resolution,
            software_version: crate::VERSION.to_string(),
            units: units.to_string(),
            sign_convention: SIGN_CONVENTION.to_string(),
            transform: generated.transform,
        }
    }
}
