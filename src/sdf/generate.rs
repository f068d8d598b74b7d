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
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::anchors::Anchor;
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

/// How the `k` training latents of a generated shape are picked.
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    Eq,
    Serialize,
    Deserialize,
    clap::ValueEnum,
    utoipa::ToSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Selection {
    /// k distinct training shapes, uniformly at random.
    #[default]
    Uniform,
    /// Variance-aware, k-means++ style: the first with probability ∝ its squared distance
    /// to the mean latent, each next ∝ its smallest squared distance to those already
    /// chosen, so mixtures combine dissimilar shapes and spread over the latent space.
    Spread,
}

impl Selection {
    /// The stored name.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Uniform => "uniform",
            Self::Spread => "spread",
        }
    }

    /// Parses a stored name.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "uniform" => Some(Self::Uniform),
            "spread" => Some(Self::Spread),
            _ => None,
        }
    }

    /// `k` distinct indices of `latents` picked by this strategy.
    pub fn pick(self, rng: &mut ChaCha8Rng, latents: &[Vec<f32>], k: usize) -> Vec<usize> {
        match self {
            Self::Uniform => index::sample(rng, latents.len(), k.min(latents.len())).into_vec(),
            Self::Spread => select_spread(rng, latents, k),
        }
    }
}

fn squared_distance(a: &[f32], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| (f64::from(x) - y).powi(2))
        .sum()
}

/// Draws an index with probability ∝ `weights`; uniform over the `eligible` ones when every
/// weight is zero (all remaining latents coincide with chosen ones).
fn draw_weighted(rng: &mut ChaCha8Rng, weights: &[f64], eligible: &[bool]) -> usize {
    let total: f64 = weights.iter().sum();
    if total > 0.0 && total.is_finite() {
        let mut target = rng.random::<f64>() * total;
        let mut last = 0;
        for (i, &w) in weights.iter().enumerate() {
            if w > 0.0 {
                last = i;
                if target < w {
                    return i;
                }
                target -= w;
            }
        }
        return last;
    }
    let open: Vec<usize> = (0..eligible.len()).filter(|&i| eligible[i]).collect();
    open[rng.random_range(0..open.len())]
}

/// k-means++ style selection of `k` distinct latents (see [`Selection::Spread`]).
pub fn select_spread(rng: &mut ChaCha8Rng, latents: &[Vec<f32>], k: usize) -> Vec<usize> {
    let n = latents.len();
    let k = k.min(n);
    if k == 0 {
        return Vec::new();
    }
    let dim = latents[0].len();
    let mut mean = vec![0.0f64; dim];
    for z in latents {
        for (m, &v) in mean.iter_mut().zip(z) {
            *m += f64::from(v) / n as f64;
        }
    }
    let mut weights: Vec<f64> = latents.iter().map(|z| squared_distance(z, &mean)).collect();
    let mut eligible = vec![true; n];
    let mut chosen = Vec::with_capacity(k);
    while chosen.len() < k {
        let pick = draw_weighted(rng, &weights, &eligible);
        chosen.push(pick);
        eligible[pick] = false;
        let centre: Vec<f64> = latents[pick].iter().map(|&v| f64::from(v)).collect();
        for (i, w) in weights.iter_mut().enumerate() {
            *w = if eligible[i] {
                let d = squared_distance(&latents[i], &centre);
                if chosen.len() == 1 { d } else { w.min(d) }
            } else {
                0.0
            };
        }
    }
    chosen
}

/// Per-dimension sample standard deviation of the training latents (0 for one latent).
pub fn latent_std(latents: &[Vec<f32>]) -> Vec<f64> {
    let n = latents.len();
    let dim = latents.first().map_or(0, Vec::len);
    if n < 2 {
        return vec![0.0; dim];
    }
    (0..dim)
        .map(|d| {
            let mean = latents.iter().map(|z| f64::from(z[d])).sum::<f64>() / n as f64;
            let var = latents
                .iter()
                .map(|z| (f64::from(z[d]) - mean).powi(2))
                .sum::<f64>()
                / (n - 1) as f64;
            var.sqrt()
        })
        .collect()
}

/// Stream tag of the latent-noise draws.
const NOISE_STREAM: u64 = 0x4e4f_4953;

/// The mixed latent of `mixture` plus Gaussian noise of `noise` training standard
/// deviations per dimension, drawn from `seed`. With `noise` = 0 it is exactly
/// [`Mixture::mix_latents`], so cohorts without noise are unchanged.
pub fn noisy_latent(mixture: &Mixture, latents: &[Vec<f32>], noise: f64, seed: u64) -> Vec<f32> {
    if noise == 0.0 {
        return mixture.mix_latents(latents);
    }
    let std = latent_std(latents);
    let mut rng = super::batch::stream_rng(seed, 0, 0, NOISE_STREAM);
    let dim = std.len();
    let mut z = vec![0.0f64; dim];
    for (&i, &w) in mixture.indices.iter().zip(&mixture.weights) {
        for (acc, &v) in z.iter_mut().zip(&latents[i]) {
            *acc += w * f64::from(v);
        }
    }
    for (acc, s) in z.iter_mut().zip(std) {
        let g: f64 = rng.sample(StandardNormal);
        *acc += noise * s * g;
    }
    z.into_iter().map(|v| v as f32).collect()
}

/// Diversity controls of a cohort: how latents are picked and how much noise is added.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Diversity {
    /// Selection of the mixed training latents.
    pub selection: Selection,
    /// Gaussian latent noise in training standard deviations (≥ 0).
    pub latent_noise: f64,
}

/// Most redraws of a shape that is closer than the requested novelty to a training shape.
pub const MAX_REDRAWS: u32 = 10;

/// The seed of draw `attempt` of a shape whose first draw uses `seed`: the seed itself for
/// the first draw, a SplitMix64 mix of both afterwards.
pub fn attempt_seed(seed: u64, attempt: u32) -> u64 {
    if attempt == 0 {
        return seed;
    }
    let mut z = seed ^ u64::from(attempt).wrapping_mul(0xD1B5_4A32_D192_ED03);
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
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

    /// The mixture of draw `attempt` of cohort shape `shape` with `selection`; draw 0 with
    /// uniform selection is exactly [`Self::mixture`].
    pub fn mixture_with(
        &self,
        latents: &[Vec<f32>],
        selection: Selection,
        seed: u64,
        shape: u64,
        attempt: u32,
    ) -> Result<Mixture, CohortSpecError> {
        self.validate(latents.len())?;
        let mut rng = if attempt == 0 {
            mixture_rng(seed, shape)
        } else {
            super::batch::stream_rng(seed, shape, u64::from(attempt), 0x4d49_5845)
        };
        let indices = selection.pick(&mut rng, latents, self.arity);
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

    /// Makes room for `anchors` fitted latents forced into the mixture: they take the places
    /// and the weights of its last `anchors` training shapes (all of them when there are as
    /// many anchors as the arity). Returns the anchors' weights.
    pub fn force_anchors(&mut self, anchors: usize) -> Vec<f64> {
        let keep = self.indices.len().saturating_sub(anchors);
        self.indices.truncate(keep);
        self.weights.split_off(keep)
    }

    /// The same convex combination of the shapes' unit-ball transforms.
    pub fn mix_transforms(
        &self,
        transforms: &[UnitBallTransform],
    ) -> Result<UnitBallTransform, BlendError> {
        UnitBallTransform::blend(&self.transform_parts(transforms))
    }

    /// Each chosen shape's transform with its weight, the parts of the blend.
    fn transform_parts<'t>(
        &self,
        transforms: &'t [UnitBallTransform],
    ) -> Vec<(f64, &'t UnitBallTransform)> {
        self.indices
            .iter()
            .zip(&self.weights)
            .map(|(&i, &w)| (w, &transforms[i]))
            .collect()
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

/// A fitted latent (an anchor) with its weight in a mixture.
#[derive(Debug, Clone, Copy)]
pub struct AnchorPart<'a> {
    /// Its share of the mixture.
    pub weight: f64,
    /// Its latent code (the model's latent dimension).
    pub latent: &'a [f32],
    /// Its mesh's unit-ball transform, blended like the training shapes'.
    pub transform: &'a UnitBallTransform,
}

/// The latent and the blended transform of `mixture` over the training shapes plus `anchors`:
/// the training part with `latent_noise` (scaled by the training latents' spread, drawn from
/// `noise_seed`), then each anchor's weighted latent. The CLI and the service share it.
pub fn anchored_latent(
    mixture: &Mixture,
    latents: &[Vec<f32>],
    transforms: &[UnitBallTransform],
    anchors: &[AnchorPart<'_>],
    latent_noise: f64,
    noise_seed: u64,
) -> Result<(UnitBallTransform, Vec<f32>), GenerateError> {
    let mut latent = noisy_latent(mixture, latents, latent_noise, noise_seed);
    let mut parts = mixture.transform_parts(transforms);
    for (index, anchor) in anchors.iter().enumerate() {
        if anchor.latent.len() != latent.len() {
            return Err(GenerateError::AnchorDimension {
                index,
                found: anchor.latent.len(),
                expected: latent.len(),
            });
        }
        for (acc, &v) in latent.iter_mut().zip(anchor.latent) {
            *acc = (f64::from(*acc) + anchor.weight * f64::from(v)) as f32;
        }
        parts.push((anchor.weight, anchor.transform));
    }
    Ok((UnitBallTransform::blend(&parts)?, latent))
}

/// An anchor's share of a generated shape, as its provenance records it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnchorWeight {
    /// The anchor's name in the model's `anchors.json`.
    pub name: String,
    /// Its weight.
    pub weight: f64,
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
    /// An anchor's latent does not fit the model.
    #[error("anchor {index} has {found} latent values, the model {expected}")]
    AnchorDimension {
        /// Position of the anchor in the mixture's anchor list.
        index: usize,
        /// Its latent length.
        found: usize,
        /// The model's latent dimension.
        expected: usize,
    },
}

/// One generated shape before it is written anywhere.
#[derive(Debug, Clone)]
pub struct GeneratedShape {
    /// Which training shapes, with which weights.
    pub mixture: Mixture,
    /// The fitted anchors mixed in, with their weights (empty without anchors).
    pub anchors: Vec<AnchorWeight>,
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
    generate_shape_with(
        model,
        latents,
        spec,
        Diversity::default(),
        &[],
        (seed, shape, 0),
        resolution,
        extraction,
    )
}

/// [`generate_shape`] with diversity controls and `anchors` forced into the mixture (see
/// [`generate_from_mixture`]), for draw `attempt` of `(seed, shape, attempt)`.
#[allow(clippy::too_many_arguments)]
pub fn generate_shape_with(
    model: &LoadedModel,
    latents: &[Vec<f32>],
    spec: &MixSpec,
    diversity: Diversity,
    anchors: &[Anchor],
    (seed, shape, attempt): (u64, u64, u32),
    resolution: usize,
    extraction: ExtractionMethod,
) -> Result<GeneratedShape, GenerateError> {
    let mixture = spec.mixture_with(latents, diversity.selection, seed, shape, attempt)?;
    generate_from_mixture(
        model,
        latents,
        mixture,
        diversity.latent_noise,
        anchors,
        (seed, shape, attempt),
        resolution,
        extraction,
    )
}

/// Meshes a given mixture of draw `attempt` of `(seed, shape, attempt)` (the latent noise
/// is drawn from the same seed as in [`generate_shape_with`]). `anchors` take the places and
/// weights of the mixture's last entries ([`Mixture::force_anchors`]), as in the service.
#[allow(clippy::too_many_arguments)]
pub fn generate_from_mixture(
    model: &LoadedModel,
    latents: &[Vec<f32>],
    mut mixture: Mixture,
    latent_noise: f64,
    anchors: &[Anchor],
    (seed, shape, attempt): (u64, u64, u32),
    resolution: usize,
    extraction: ExtractionMethod,
) -> Result<GeneratedShape, GenerateError> {
    let anchor_weights = mixture.force_anchors(anchors.len());
    let parts: Vec<AnchorPart<'_>> = anchors
        .iter()
        .zip(&anchor_weights)
        .map(|(a, &weight)| AnchorPart {
            weight,
            latent: &a.latent,
            transform: &a.transform,
        })
        .collect();
    let noise_seed = attempt_seed(seed ^ shape.rotate_left(32), attempt);
    let (transform, latent) = anchored_latent(
        &mixture,
        latents,
        &model.manifest.transforms(),
        &parts,
        latent_noise,
        noise_seed,
    )?;
    let field = model.field(&latent).map_err(ReconstructError::from)?;
    let mesh = reconstruct(&field, resolution, extraction)?.mesh;
    Ok(GeneratedShape {
        mixture,
        anchors: anchors
            .iter()
            .zip(anchor_weights)
            .map(|(a, weight)| AnchorWeight {
                name: a.name.clone(),
                weight,
            })
            .collect(),
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
    /// Fitted anchors mixed in after the training shapes, with their weights.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub anchors: Vec<AnchorWeight>,
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
    /// How the training latents were picked.
    #[serde(default)]
    pub selection: Selection,
    /// Latent noise in training standard deviations.
    #[serde(default)]
    pub latent_noise: f64,
    /// Which draw was kept (0 = the first; later ones replace draws too close to a
    /// training shape).
    #[serde(default)]
    pub attempt: u32,
    /// Distance to the nearest training shape (the model's reconstruction of it), if measured.
    #[serde(default)]
    pub novelty: Option<super::novelty::Novelty>,
    /// Draws rejected as closer than the requested minimum novelty.
    #[serde(default)]
    pub redraws: u32,
    /// False when no draw reached the requested minimum novelty (the most novel was kept).
    #[serde(default)]
    pub novelty_met: Option<bool>,
    /// Candidates drawn to meet the anatomical targets (absent without targets).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub candidates: Option<u32>,
    /// Whether the shape meets every target (false: no candidate did, the closest was kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub targets_met: Option<bool>,
    /// The shape's anatomical measurements in mm, when targets were searched.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anatomy: Option<crate::anatomy::shape::ShapeAnatomy>,
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
            anchors: generated.anchors.clone(),
            seed,
            resolution,
            software_version: crate::VERSION.to_string(),
            units: units.to_string(),
            sign_convention: SIGN_CONVENTION.to_string(),
            transform: generated.transform,
            selection: Selection::Uniform,
            latent_noise: 0.0,
            attempt: 0,
            novelty: None,
            redraws: 0,
            novelty_met: None,
            candidates: None,
            targets_met: None,
            anatomy: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// 20 latents in 4 dimensions: a tight cluster of 16 around the origin and 4 outliers.
    fn clustered_latents() -> Vec<Vec<f32>> {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut latents: Vec<Vec<f32>> = (0..16)
            .map(|_| (0..4).map(|_| rng.random::<f32>() * 0.1).collect())
            .collect();
        for d in 0..4 {
            let mut z = vec![0.0; 4];
            z[d] = 3.0;
            latents.push(z);
        }
        latents
    }

    fn distance(a: &[f32], b: &[f32]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| f64::from(x - y).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    fn mixture() -> Mixture {
        Mixture {
            indices: vec![1, 17, 4],
            weights: vec![0.2, 0.5, 0.3],
        }
    }

    #[test]
    fn zero_noise_reproduces_the_plain_mixed_latent_bit_for_bit() {
        let latents = clustered_latents();
        let m = mixture();
        for seed in 0..20 {
            assert_eq!(
                noisy_latent(&m, &latents, 0.0, seed),
                m.mix_latents(&latents)
            );
        }
        let spec = MixSpec {
            arity: 3,
            weights: None,
            weighting: Weighting::Dirichlet,
        };
        for shape in 0..20 {
            assert_eq!(
                spec.mixture_with(&latents, Selection::Uniform, 9, shape, 0),
                spec.mixture(latents.len(), 9, shape)
            );
        }
    }

    #[test]
    fn noise_has_the_requested_scale_per_dimension() {
        let latents = clustered_latents();
        let std = latent_std(&latents);
        let m = mixture();
        let base = m.mix_latents(&latents);
        let (scale, draws) = (0.5, 4000);
        let mut sum = [0.0f64; 4];
        let mut sum_sq = [0.0f64; 4];
        for seed in 0..draws {
            let z = noisy_latent(&m, &latents, scale, seed);
            assert_eq!(z, noisy_latent(&m, &latents, scale, seed), "deterministic");
            for d in 0..4 {
                let e = f64::from(z[d] - base[d]) / (scale * std[d]);
                sum[d] += e;
                sum_sq[d] += e * e;
            }
        }
        for d in 0..4 {
            let mean = sum[d] / draws as f64;
            let var = sum_sq[d] / draws as f64 - mean * mean;
            // Standard normal: the mean's standard error is 1/√4000 ≈ 0.016, the variance's
            // ≈ √(2/4000) ≈ 0.022.
            assert!(mean.abs() < 0.06, "dimension {d}: mean {mean}");
            assert!((var - 1.0).abs() < 0.09, "dimension {d}: variance {var}");
        }
    }

    #[test]
    fn spread_selection_picks_farther_apart_latents_than_uniform() {
        let latents = clustered_latents();
        let mean_pair_distance = |selection: Selection| {
            let (mut total, mut pairs) = (0.0, 0);
            for seed in 0..500 {
                let mut rng = mixture_rng(seed, 0);
                let picked = selection.pick(&mut rng, &latents, 3);
                let mut sorted = picked.clone();
                sorted.sort_unstable();
                sorted.dedup();
                assert_eq!(
                    sorted.len(),
                    3,
                    "{selection:?} repeated an index: {picked:?}"
                );
                for i in 0..3 {
                    for j in i + 1..3 {
                        total += distance(&latents[picked[i]], &latents[picked[j]]);
                        pairs += 1;
                    }
                }
            }
            total / f64::from(pairs)
        };
        let uniform = mean_pair_distance(Selection::Uniform);
        let spread = mean_pair_distance(Selection::Spread);
        assert!(
            spread > 1.5 * uniform,
            "spread {spread} vs uniform {uniform}"
        );
    }

    #[test]
    fn spread_selection_handles_coincident_latents() {
        let latents = vec![vec![1.0f32, 1.0]; 5];
        let mut rng = mixture_rng(1, 2);
        let mut picked = select_spread(&mut rng, &latents, 4);
        picked.sort_unstable();
        picked.dedup();
        assert_eq!(picked.len(), 4);
    }

    #[test]
    fn attempt_seeds_differ_and_keep_the_first() {
        assert_eq!(attempt_seed(77, 0), 77);
        let seeds: std::collections::HashSet<u64> =
            (0..=MAX_REDRAWS).map(|a| attempt_seed(77, a)).collect();
        assert_eq!(seeds.len(), MAX_REDRAWS as usize + 1);
    }
}
