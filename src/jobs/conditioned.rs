//! Conditioned cohorts in the service: the model's training-shape measurements (computed
//! once per model, stored with it) and the per-shape candidate search of
//! [`crate::anatomy::targets`].

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, ensure};
use serde::{Deserialize, Serialize};
use sqlx::SqlitePool;

use super::cohort::{Candidate, draw};
use super::engine::{AnchorLatent, CohortEngine, GeneratedShape, ShapeSpec};
use super::join_error;
use super::plan::{CohortPlan, Weighting, force_anchors};
use super::priority::spawn_background;
use crate::anatomy::shape::{ShapeAnatomy, measure_shape};
use crate::anatomy::targets::{
    CandidateSource, Measured, SCREEN_RESOLUTION, SearchOutcome, Targets, guided_indices,
    guided_pool, is_guided, refine_weights, search,
};
use crate::db;
use crate::sdf::novelty::NoveltyReference;

/// The measurements of a model's training shapes, each meshed alone (weight 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingAnatomy {
    /// Grid resolution they were meshed at.
    pub resolution: usize,
    /// One entry per training shape; null where the shape could not be measured.
    pub shapes: Vec<Option<ShapeAnatomy>>,
}

/// Meshes and measures each of the `count` training shapes of the model in `model_dir`.
/// Blocking; stops early once `cancel` is set.
pub fn measure_training_shapes(
    engine: &dyn CohortEngine,
    model_dir: &Path,
    count: usize,
    cancel: &AtomicBool,
) -> anyhow::Result<TrainingAnatomy> {
    let shapes = (0..count)
        .map(|index| {
            ensure!(!cancel.load(Ordering::Relaxed), "cancelled");
            let spec = ShapeSpec {
                training_indices: vec![index],
                weights: vec![1.0],
                seed: 0,
                resolution: SCREEN_RESOLUTION,
                latent_noise: 0.0,
                anchors: Vec::new(),
            };
            let shape = engine
                .generate_shape(model_dir, &spec, cancel)
                .with_context(|| format!("training shape {index}"))?;
            Ok(measure_mm(&shape).ok())
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(TrainingAnatomy {
        resolution: SCREEN_RESOLUTION,
        shapes,
    })
}

/// One measurement of training shapes at a time: a request and the job it queued (or two
/// first uses) wait for the same result instead of computing it twice.
static MEASURING: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// The model's stored training-shape measurements, when they cover all `count` shapes.
pub async fn stored_training_anatomy(
    pool: &SqlitePool,
    model_id: &str,
    count: usize,
) -> anyhow::Result<Option<TrainingAnatomy>> {
    let Some(json) = db::models::training_anatomy(pool, model_id).await? else {
        return Ok(None);
    };
    let stored: TrainingAnatomy =
        serde_json::from_str(&json).context("stored training measurements are not JSON")?;
    Ok((stored.shapes.len() == count).then_some(stored))
}

/// The model's training-shape measurements: stored ones, or computed off the executor and
/// stored. The computation runs as its own task, so a caller that stops waiting for it
/// (a request past its wait budget) still leaves the result stored for the next one.
pub async fn training_anatomy(
    pool: &SqlitePool,
    engine: Arc<dyn CohortEngine>,
    model_id: &str,
    model_dir: &Path,
    count: usize,
) -> anyhow::Result<TrainingAnatomy> {
    if let Some(stored) = stored_training_anatomy(pool, model_id, count).await? {
        return Ok(stored);
    }
    let (pool, model_id, dir) = (pool.clone(), model_id.to_owned(), model_dir.to_path_buf());
    let task = async move {
        let _one_at_a_time = MEASURING.lock().await;
        if let Some(stored) = stored_training_anatomy(&pool, &model_id, count).await? {
            return Ok(stored);
        }
        let measured = spawn_background(move || {
            measure_training_shapes(&*engine, &dir, count, &AtomicBool::new(false))
        })
        .await
        .map_err(join_error)??;
        let json = serde_json::to_string(&measured)?;
        db::models::set_training_anatomy(&pool, &model_id, &json).await?;
        tracing::info!(model_id, count, "training shapes measured");
        Ok(measured)
    };
    tokio::spawn(tracing::Instrument::in_current_span(task))
        .await
        .map_err(join_error)?
}

/// Measures a generated shape in mm.
pub fn measure_mm(shape: &GeneratedShape) -> Result<ShapeAnatomy, String> {
    let mesh_mm = shape.transform.mesh_to_mesh_units(&shape.mesh_unit);
    measure_shape(&mesh_mm).map_err(|e| e.to_string())
}

/// A targeted cohort's search settings.
#[derive(Debug, Clone)]
pub struct Targeting {
    /// The validated targets.
    pub targets: Targets,
    /// Most candidates per shape.
    pub max_candidates: u32,
    /// Training shapes that guided candidates mix ([`guided_pool`]).
    pub pool: Vec<usize>,
    /// The training shapes' measurements, which weight refinement predicts from.
    pub training: Vec<Option<ShapeAnatomy>>,
}

impl Targeting {
    /// The settings of a cohort drawn from a model whose training shapes measure `training`.
    pub fn new(
        targets: Targets,
        max_candidates: u32,
        training: &TrainingAnatomy,
        arity: usize,
    ) -> Self {
        let pool = guided_pool(&targets, &training.shapes, arity);
        Self {
            targets,
            max_candidates,
            pool,
            training: training.shapes.clone(),
        }
    }

    /// Candidate `attempt` of shape `index`: the plan's draw of that attempt, with its
    /// training shapes taken from the guided pool on guided attempts.
    pub fn spec(&self, plan: &CohortPlan, index: u64, attempt: u32) -> ShapeSpec {
        let mut spec = plan.shape_spec_attempt(index, attempt);
        if is_guided(attempt) && self.pool.len() >= plan.arity {
            spec.training_indices = guided_indices(spec.seed, &self.pool, plan.arity);
        }
        spec
    }

    /// `spec` with weights refined towards the targets from what it measured, when the plan
    /// draws its weights (fixed or equal weights asked for are kept).
    pub fn refine(
        &self,
        plan: &CohortPlan,
        spec: &ShapeSpec,
        measured: &ShapeAnatomy,
    ) -> Option<ShapeSpec> {
        if plan.weights.is_some() || plan.weighting != Weighting::Dirichlet {
            return None;
        }
        let weights = refine_weights(
            &self.targets,
            &self.training,
            &spec.training_indices,
            &spec.weights,
            measured,
        )?;
        Some(ShapeSpec {
            weights,
            ..spec.clone()
        })
    }
}

/// Everything one shape's search needs, moved into the blocking task.
pub(super) struct ShapeSearch {
    pub engine: Arc<dyn CohortEngine>,
    pub model_dir: std::path::PathBuf,
    pub plan: CohortPlan,
    pub targeting: Arc<Targeting>,
    pub reference: Arc<NoveltyReference>,
    pub min_novelty: Option<f64>,
    pub cancel: Arc<AtomicBool>,
    /// Fitted anchors forced into every candidate.
    pub anchors: Vec<AnchorLatent>,
}

/// Searches shape `index`'s candidates off the executor.
pub(super) async fn search_shape(
    s: ShapeSearch,
    index: u64,
) -> anyhow::Result<SearchOutcome<Candidate>> {
    spawn_background(move || {
        let t = s.targeting.clone();
        let screening = SCREEN_RESOLUTION.min(s.plan.resolution) < s.plan.resolution;
        search(
            &t.targets,
            t.max_candidates,
            screening,
            &mut ShapeCandidates { s: &s, index },
        )
    })
    .await
    .map_err(join_error)?
}

/// The candidates of one shape of a targeted cohort.
struct ShapeCandidates<'a> {
    s: &'a ShapeSearch,
    index: u64,
}

impl CandidateSource for ShapeCandidates<'_> {
    type Spec = ShapeSpec;
    type Kept = Candidate;
    type Error = anyhow::Error;

    fn draw(&mut self, attempt: u32) -> anyhow::Result<ShapeSpec> {
        let s = self.s;
        let spec = s.targeting.spec(&s.plan, self.index, attempt);
        Ok(force_anchors(spec, &s.anchors))
    }

    fn refine(&mut self, spec: &ShapeSpec, measured: &ShapeAnatomy) -> Option<ShapeSpec> {
        self.s.targeting.refine(&self.s.plan, spec, measured)
    }

    fn screen(&mut self, spec: &ShapeSpec) -> anyhow::Result<Result<ShapeAnatomy, String>> {
        let s = self.s;
        ensure!(!s.cancel.load(Ordering::Relaxed), "cancelled");
        let spec = ShapeSpec {
            resolution: SCREEN_RESOLUTION.min(s.plan.resolution),
            ..spec.clone()
        };
        let shape = s.engine.generate_shape(&s.model_dir, &spec, &s.cancel)?;
        Ok(measure_mm(&shape))
    }

    fn finalize(&mut self, attempt: u32, spec: &ShapeSpec) -> anyhow::Result<Measured<Candidate>> {
        let s = self.s;
        ensure!(!s.cancel.load(Ordering::Relaxed), "cancelled");
        let candidate = Candidate {
            attempt,
            ..draw(
                &*s.engine,
                &s.model_dir,
                spec.clone(),
                &s.reference,
                &s.cancel,
            )?
        };
        let anatomy = measure_mm(&candidate.shape);
        let novelty = candidate.novelty.chamfer;
        Ok(Measured {
            candidate,
            anatomy,
            accept: s.min_novelty.is_none_or(|m| novelty >= m),
            rank: novelty,
        })
    }
}
