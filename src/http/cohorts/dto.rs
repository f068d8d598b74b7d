//! Cohort request and response bodies, and the request rules of DESIGN §4.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::cohort::targets::TargetRange;
use crate::cohort::{CohortFields, SamplerFields, Selection, Weighting};
use crate::db::cohorts::CohortRow;
use crate::db::shapes::MeasureSummary;
use crate::db::states::JobStatus;
use crate::http::jobs::Progress;
use crate::jobs::stats::PairwiseSummary;

/// Body of `POST /v1/cohorts`.
#[derive(Debug, Clone, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateCohort {
    /// Model to sample from (see `GET /v1/models`).
    pub model_id: String,
    /// Number of shapes, 1 to the configured maximum.
    pub count: i64,
    /// Training shapes mixed per generated shape: 2 ≤ arity ≤ training shapes (required
    /// by the convex sampler). With a density `sampler` each shape mixes its sampled latent
    /// and the anchors, so arity is 1 + len(anchors) and may be left out.
    #[serde(default)]
    pub arity: Option<i64>,
    /// Explicit weights (length = arity, each ≥ 0, summing to 1 within 1e-6), used for every
    /// shape; when absent, `weighting` draws them.
    #[serde(default)]
    pub weights: Option<Vec<f64>>,
    /// Weight strategy when `weights` is absent (default `dirichlet`).
    #[serde(default)]
    pub weighting: Option<Weighting>,
    /// Seed; a fixed seed reproduces the cohort bit for bit. Drawn and recorded when absent.
    #[serde(default)]
    pub seed: Option<u64>,
    /// Marching-cubes resolution per axis, 32–1024 (default 256).
    #[serde(default)]
    pub resolution: Option<i64>,
    /// Gaussian noise added to each mixed latent, in units of the training latents'
    /// per-dimension standard deviation; ≥ 0, default 0 (plain convex combinations).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latent_noise: Option<f64>,
    /// How the `arity` training latents are picked: `uniform` (default) or `spread`
    /// (k-means++ style: far from the mean and from each other).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub selection: Option<Selection>,
    /// Smallest accepted Chamfer distance (unit-ball coordinates) to the nearest training
    /// shape, ≥ 0. A closer shape is redrawn up to 10 times; if no draw reaches it the most
    /// novel draw is kept and flagged `novelty_met: false`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_novelty: Option<f64>,
    /// Target ranges (mm) of anatomical measurements, keyed by name: `annulus_mm`,
    /// `sinus_mm`, `stj_mm`, `sinus_height_mm`, `ascending_mm`, `length_mm`,
    /// `max_diameter_mm`; each `{"min": …, "max": …}` with at least one bound, both ≥ 0.
    /// Each shape then searches up to `max_candidates` mixtures for one inside every range:
    /// fresh draws, and (when the weights are drawn, not given or `equal`) refinements of a
    /// missing draw's weights predicted from the training shapes' measurements. When none
    /// is inside, the closest is kept and flagged `targets_met: false`. A target outside
    /// what the model's training shapes reach (their range widened by 5 % of the largest
    /// value) is refused with the achievable range.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(example = json!({"annulus_mm": {"min": 23.0, "max": 27.0}}))]
    pub targets: Option<BTreeMap<String, TargetRange>>,
    /// Most candidates drawn per shape when `targets` is set: 1–100, default 20.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_candidates: Option<i64>,
    /// Fitted anchors (ids from `POST /v1/models/{id}/fit`, ready, of the same model) forced
    /// into every shape: each shape mixes all of them plus `arity − len(anchors)` training
    /// shapes drawn as usual, so `arity` counts the anchors (1 ≤ len ≤ arity, distinct).
    /// Weights (explicit or drawn) list the training shapes first, then the anchors in this
    /// order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anchors: Option<Vec<i64>>,
    /// How latents are drawn (default: `{"kind": "convex"}`, combinations of `arity`
    /// training latents). `pca_gaussian` draws from a Gaussian in the training latents'
    /// principal components (`truncation` c: each mode within ±c σ; `sigma_scale`;
    /// `covariance: ledoit_wolf` or a fixed `shrinkage` pulls the covariance towards a
    /// multiple of the identity; `variance_share`), `pca_mixture` from a Gaussian mixture on the leading whitened
    /// components (`components`, or `max_components` chosen by BIC; `mixture_modes`;
    /// `variance_share`). Both model the unit-ball transform (size and position in mm)
    /// jointly with the latent. `selection: spread` and `latent_noise` apply to the convex
    /// sampler only; `min_novelty` redraws and `targets` candidates are further draws from
    /// the sampler.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(example = json!({"kind": "pca_gaussian", "truncation": 3.0}))]
    pub sampler: Option<SamplerFields>,
}

impl CreateCohort {
    /// The request's fields as the cohort pipeline parses them.
    pub fn fields(&self) -> CohortFields<i64> {
        CohortFields {
            count: self.count,
            arity: self.arity,
            weights: self.weights.clone(),
            weighting: self.weighting,
            seed: self.seed,
            resolution: self.resolution,
            latent_noise: self.latent_noise,
            selection: self.selection,
            min_novelty: self.min_novelty,
            targets: self.targets.clone(),
            max_candidates: self.max_candidates,
            anchors: self.anchors.clone(),
            sampler: self.sampler.clone(),
        }
    }

    /// SHA-256 over the canonical request, to recognise a retried POST.
    pub fn fingerprint(&self) -> String {
        crate::digest::sha256_hex(&serde_json::to_vec(self).expect("requests serialise"))
    }
}

/// A cohort as the API shows it.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct CohortView {
    /// Cohort id.
    pub id: i64,
    /// Model drawn from.
    pub model_id: String,
    /// Where its job stands.
    pub status: JobStatus,
    /// Shapes stored / requested.
    pub progress: Progress,
    /// Number of shapes requested.
    pub count: i64,
    /// Members mixed per shape: training shapes (convex sampler), or the sampled latent
    /// plus the anchors (density sampler).
    pub arity: i64,
    /// The density sampler with its defaults filled in (absent: convex combinations).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sampler: Option<SamplerFields>,
    /// Weight strategy used when `weights` is null.
    pub weighting: Weighting,
    /// Explicit weights, if given.
    pub weights: Option<Vec<f64>>,
    /// The seed used (replay with the same request and this seed).
    pub seed: u64,
    /// Marching-cubes resolution.
    pub resolution: i64,
    /// Latent noise in training standard deviations.
    pub latent_noise: f64,
    /// How the mixed training latents are picked.
    pub selection: Selection,
    /// Smallest accepted Chamfer distance to a training shape, if any.
    pub min_novelty: Option<f64>,
    /// Fitted anchors forced into every shape, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub anchors: Option<Vec<i64>>,
    /// Redraws over the stored shapes (shapes closer than `min_novelty` to a training shape).
    pub redraws_total: i64,
    /// Target ranges of anatomical measurements (mm), if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub targets: Option<BTreeMap<String, TargetRange>>,
    /// Most candidates per shape (targeted cohorts).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_candidates: Option<i64>,
    /// Candidates drawn over the stored shapes (targeted cohorts; 0 otherwise).
    pub candidates_total: i64,
    /// Stored shapes that miss a target: no candidate met every range, the closest was kept.
    pub targets_not_met: i64,
    /// The job generating it.
    pub job_id: i64,
    /// Error chain when failed.
    pub error: Option<String>,
    /// Creation time (UTC, RFC 3339).
    pub created_at: String,
    /// When generation started.
    pub started_at: Option<String>,
    /// When generation ended.
    pub finished_at: Option<String>,
    /// Related resources.
    pub links: CohortLinks,
    /// Statistics over the stored shapes (single-cohort reads only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub summary: Option<CohortSummary>,
}

/// URLs of a cohort's related resources.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct CohortLinks {
    /// This cohort.
    #[serde(rename = "self")]
    pub this: String,
    /// Its job.
    pub job: String,
    /// Its shapes.
    pub shapes: String,
    /// Its pairwise metrics.
    pub metrics: String,
}

/// Summary statistics of a cohort.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct CohortSummary {
    /// Surface area over stored shapes (mm²).
    pub area_mm2: Option<Range>,
    /// Enclosed volume over stored shapes (mm³).
    pub volume_mm3: Option<Range>,
    /// Pairwise Chamfer distances (squared, unit-ball coordinates), once computed.
    pub pairwise_chamfer: Option<PairwiseSummary>,
}

/// Mean and extremes.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct Range {
    /// Mean.
    pub mean: f64,
    /// Minimum.
    pub min: f64,
    /// Maximum.
    pub max: f64,
}

impl CohortView {
    /// Builds the view of a stored cohort (without summary).
    pub fn from_row(c: CohortRow) -> Self {
        let id = c.cohort_id;
        Self {
            id,
            model_id: c.model_id,
            status: c.status,
            progress: Progress {
                done: c.shapes_done,
                total: c.count,
            },
            count: c.count,
            arity: c.arity,
            sampler: c.sampler.map(|s| s.0),
            weighting: c.weighting,
            weights: c.weights.map(|w| w.0),
            seed: c.seed as u64,
            resolution: c.resolution,
            latent_noise: c.latent_noise,
            selection: c.selection,
            min_novelty: c.min_novelty,
            anchors: c.anchors.map(|a| a.0),
            redraws_total: c.redraws_total,
            targets: c.targets.map(|t| t.0),
            max_candidates: c.max_candidates,
            candidates_total: c.candidates_total,
            targets_not_met: c.targets_not_met,
            job_id: c.job_id,
            error: c.error,
            created_at: c.created_at,
            started_at: c.started_at,
            finished_at: c.finished_at,
            links: CohortLinks {
                this: format!("/v1/cohorts/{id}"),
                job: format!("/v1/jobs/{}", c.job_id),
                shapes: format!("/v1/cohorts/{id}/shapes"),
                metrics: format!("/v1/cohorts/{id}/metrics"),
            },
            summary: None,
        }
    }
}

impl CohortSummary {
    /// Combines the measure summary and the stored pairwise summary.
    pub fn new(m: &MeasureSummary, pairwise: Option<PairwiseSummary>) -> Self {
        let range = |mean: Option<f64>, min: Option<f64>, max: Option<f64>| {
            Some(Range {
                mean: mean?,
                min: min?,
                max: max?,
            })
        };
        Self {
            area_mm2: range(m.area_mean, m.area_min, m.area_max),
            volume_mm3: range(m.volume_mean, m.volume_min, m.volume_max),
            pairwise_chamfer: pairwise,
        }
    }
}
