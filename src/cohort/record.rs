//! What is recorded about every generated shape: its provenance (model, mixture, seeds,
//! resolution, software version — DESIGN §4), shown by the service under
//! `GET /v1/shapes/{id}` and written by the command line beside every mesh, so one request
//! can be checked to give the same cohort both ways.

use serde::{Deserialize, Serialize};

use super::Selection;
use super::sampler::SamplerFields;
use crate::anatomy::shape::ShapeAnatomy;
use crate::engine::{GeneratedShape, ShapeSpec};
use crate::formats::mesh_blob;
use crate::geometry::normalize::UnitBallTransform;
use crate::sdf::inference::novelty::Novelty;
use crate::sdf::store::manifest::SIGN_CONVENTION;

/// One finished shape of a cohort.
#[derive(Debug, Clone)]
pub struct CohortShape {
    /// Its position in the cohort.
    pub index: u64,
    /// The kept draw's specification.
    pub spec: ShapeSpec,
    /// The engine's mesh (unit ball) with its transform to mesh units.
    pub shape: GeneratedShape,
    /// Distance to the nearest training shape.
    pub novelty: Novelty,
    /// Draws rejected as closer than the minimum novelty.
    pub redraws: u32,
    /// Whether the minimum novelty is met (true without one).
    pub novelty_met: bool,
    /// Its measurements in mm, or why they failed.
    pub anatomy: Result<ShapeAnatomy, String>,
    /// Weight refinements among its candidates (targeted cohorts).
    pub refinements: Option<u32>,
    /// Where it comes from.
    pub provenance: ShapeProvenance,
}

/// Where a generated shape comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ShapeProvenance {
    /// Model id.
    pub model_id: String,
    /// Training shapes mixed.
    pub training_indices: Vec<usize>,
    /// Their weights, followed by the anchors' weights.
    pub weights: Vec<f64>,
    /// Fitted anchors mixed after the training shapes, by name, with their weights.
    #[serde(default)]
    pub anchors: Vec<AnchorShare>,
    /// Per-shape seed: the kept draw's seed.
    pub seed: u64,
    /// The cohort's seed the shape seed derives from.
    #[serde(default)]
    pub cohort_seed: u64,
    /// Version of the seed scheme ([`super::seeds::SEED_SCHEME`]).
    #[serde(default = "first_scheme")]
    pub seed_scheme: u32,
    /// Marching-cubes resolution.
    pub resolution: i64,
    /// aortagen version.
    pub software_version: String,
    /// Latent noise in training standard deviations.
    pub latent_noise: f64,
    /// How the training latents were picked.
    pub selection: Selection,
    /// Which draw was kept (0 = the first); `seed` is that draw's seed.
    pub attempt: i64,
    /// Candidates drawn to meet the cohort's targets (null without targets).
    pub candidates: Option<i64>,
    /// Whether the shape meets every target of its cohort (null without targets); false
    /// when no candidate did and the closest was kept.
    pub targets_met: Option<bool>,
    /// The density sampler that drew the shape's latent, with every default filled in
    /// (absent: a convex combination of training latents).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampler: Option<SamplerFields>,
}

fn first_scheme() -> u32 {
    1
}

/// A fitted anchor's share of a generated shape.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct AnchorShare {
    /// The anchor's name (unique per model).
    pub name: String,
    /// Its weight.
    pub weight: f64,
}

/// Everything the command line writes beside a generated mesh (`shape_NNNN.json`): the
/// provenance, the model's weights hash, the shape's measures and the hash of its canonical
/// unit-ball encoding (the service's `mesh_sha256`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShapeRecord {
    /// Position in the cohort.
    pub shape_index: u64,
    /// Where it comes from.
    #[serde(flatten)]
    pub provenance: ShapeProvenance,
    /// Full SHA-256 of the model's weights.
    pub model_sha256: String,
    /// Names of the mixed training shapes.
    pub names: Vec<String>,
    /// Distance to the nearest training shape (the model's reconstruction of it).
    pub novelty: Novelty,
    /// Draws rejected as closer than the requested minimum novelty.
    pub redraws: u32,
    /// False when no draw reached the requested minimum novelty (the most novel was kept).
    pub novelty_met: bool,
    /// Anatomical measurements in mm, when they succeeded.
    pub anatomy: Option<ShapeAnatomy>,
    /// Why the measurements failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anatomy_error: Option<String>,
    /// Units of the written mesh (`mm` or `unit`).
    pub units: String,
    /// Field sign convention.
    pub sign_convention: String,
    /// Unit ball → mesh units of this shape.
    pub transform: UnitBallTransform,
    /// SHA-256 of the unit-ball mesh in the canonical encoding ([`mesh_blob`]).
    pub mesh_sha256: String,
    /// Vertex count.
    pub vertex_count: usize,
    /// Triangle count.
    pub triangle_count: usize,
    /// Surface area in mm².
    pub area_mm2: f64,
    /// Enclosed volume in mm³.
    pub volume_mm3: f64,
}

impl ShapeRecord {
    /// The record of `shape` from a model whose weights hash `model_sha256` and whose
    /// training shapes are named `names`, written in `units`.
    pub fn new(shape: &CohortShape, model_sha256: &str, names: &[String], units: &str) -> Self {
        let mesh = &shape.shape.mesh_unit;
        Self {
            shape_index: shape.index,
            provenance: shape.provenance.clone(),
            model_sha256: model_sha256.to_owned(),
            names: shape
                .spec
                .training_indices
                .iter()
                .map(|&i| names.get(i).cloned().unwrap_or_default())
                .collect(),
            novelty: shape.novelty,
            redraws: shape.redraws,
            novelty_met: shape.novelty_met,
            anatomy: shape.anatomy.clone().ok(),
            anatomy_error: shape.anatomy.clone().err(),
            units: units.to_owned(),
            sign_convention: SIGN_CONVENTION.to_owned(),
            transform: shape.shape.transform,
            mesh_sha256: mesh_blob::sha256_hex(&mesh_blob::encode(mesh)),
            vertex_count: mesh.vertex_count(),
            triangle_count: mesh.triangle_count(),
            area_mm2: shape.shape.area_mm2,
            volume_mm3: shape.shape.volume_mm3,
        }
    }
}
