//! The per-shape pipeline both the command line and the cohort job run: draw a mixture,
//! mesh it with the engine, measure its novelty and anatomy, redraw while it is closer than
//! the minimum novelty, or search candidates for the anatomical targets. Blocking and
//! synchronous: callers run it off the async executor.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;

use super::plan::CohortPlan;
use super::record::{AnchorShare, CohortShape, ShapeProvenance};
use super::request::{CohortRequest, TargetSearch};
use super::sampler::SamplerFields;
use super::seeds::SEED_SCHEME;
use super::targets::feasibility::{
    SCREEN_RESOLUTION, TrainingAnatomy, check_feasible, measure_mm, measure_training_shapes,
};
use super::targets::refine::refine_weights;
use super::targets::search::{
    CandidateSource, Measured, guided_indices, guided_pool, is_guided, search,
};
use super::{CohortError, MAX_REDRAWS, Targets};
use crate::anatomy::shape::ShapeAnatomy;
use crate::engine::{Engine, GeneratedShape, ShapeSpec, panic_message};
use crate::sdf::inference::novelty::{Novelty, NoveltyReference};

/// What a cohort needs before its first shape: the training surfaces to measure novelty
/// against and, for targeted cohorts, the training shapes' measurements.
#[derive(Clone)]
pub struct CohortSetup {
    /// The model's training surfaces at the cohort's resolution, sampled and indexed.
    pub reference: Arc<NoveltyReference>,
    /// The training shapes' measurements (targeted cohorts only).
    pub training: Option<TrainingAnatomy>,
}

impl CohortSetup {
    /// Computes the setup of `request` directly with `engine` (what the command line does;
    /// the service keeps the training measurements with the model instead).
    pub fn compute<A>(
        engine: &dyn Engine,
        model_dir: &std::path::Path,
        request: &CohortRequest<A>,
        training_shapes: usize,
        cancel: &AtomicBool,
    ) -> Result<Self, CohortError> {
        let reference = engine
            .novelty_reference(model_dir, request.resolution, cancel)
            .map_err(|e| stopped_or(cancel, e, CohortError::Reference))?;
        let training = match &request.targets {
            None => None,
            Some(_) => Some(
                measure_training_shapes(engine, model_dir, training_shapes, cancel)
                    .map_err(|e| stopped_or(cancel, e, CohortError::Training))?,
            ),
        };
        Ok(Self {
            reference,
            training,
        })
    }
}

/// What a targeted shape's candidate search did.
#[derive(Debug, Clone, Copy)]
struct Searched {
    candidates: u32,
    refined: u32,
    met: bool,
}

/// Generates the shapes of one cohort (see the module docs).
pub struct CohortGenerator {
    engine: Arc<dyn Engine>,
    model_dir: PathBuf,
    model_id: String,
    plan: CohortPlan,
    min_novelty: Option<f64>,
    sampler: Option<SamplerFields>,
    reference: Arc<NoveltyReference>,
    targeting: Option<Targeting>,
    cancel: Arc<AtomicBool>,
}

/// The engine a generator meshes with and where it stops.
pub struct EngineHandle {
    /// The engine.
    pub engine: Arc<dyn Engine>,
    /// The model's directory.
    pub model_dir: PathBuf,
    /// The model's id as provenance records it.
    pub model_id: String,
    /// Raised to stop generation early.
    pub cancel: Arc<AtomicBool>,
}

impl CohortGenerator {
    /// A generator for `request` drawn by `plan`; fails when its targets cannot be met by
    /// the model's training shapes (or their measurements are missing).
    pub fn new<A>(
        handle: EngineHandle,
        plan: CohortPlan,
        request: &CohortRequest<A>,
        setup: CohortSetup,
    ) -> Result<Self, CohortError> {
        let targeting = match &request.targets {
            None => None,
            Some(search) => {
                let training = setup.training.as_ref().ok_or_else(|| {
                    CohortError::Training(anyhow::anyhow!("the training shapes are not measured"))
                })?;
                Some(Targeting::new(search, training, plan.arity)?)
            }
        };
        Ok(Self {
            engine: handle.engine,
            model_dir: handle.model_dir,
            model_id: handle.model_id,
            plan,
            min_novelty: request.min_novelty,
            sampler: request.sampler.recorded(),
            reference: setup.reference,
            targeting,
            cancel: handle.cancel,
        })
    }

    /// The plan the shapes are drawn from.
    pub fn plan(&self) -> &CohortPlan {
        &self.plan
    }

    /// Generates every shape of `indices` in order and hands each to `sink`; stops at the
    /// first error of either.
    pub fn run<E: From<CohortError>>(
        &self,
        indices: impl IntoIterator<Item = u64>,
        mut sink: impl FnMut(CohortShape) -> Result<(), E>,
    ) -> Result<(), E> {
        for index in indices {
            sink(self.shape(index)?)?;
        }
        Ok(())
    }

    /// Generates shape `index`.
    pub fn shape(&self, index: u64) -> Result<CohortShape, CohortError> {
        match &self.targeting {
            Some(targeting) => self.targeted(index, targeting),
            None => self.plain(index),
        }
    }

    /// The first draw, or with a minimum novelty the first draw that reaches it among at
    /// most [`MAX_REDRAWS`] redraws (else the most novel one).
    fn plain(&self, index: u64) -> Result<CohortShape, CohortError> {
        let attempts = if self.min_novelty.is_some() {
            MAX_REDRAWS + 1
        } else {
            1
        };
        let mut best: Option<Draw> = None;
        let mut redraws = 0;
        for attempt in 0..attempts {
            let draw = self.draw(index, attempt, self.plan.shape_spec_attempt(index, attempt))?;
            redraws = attempt;
            let met = self.novelty_met(&draw.novelty);
            if best
                .as_ref()
                .is_none_or(|b| draw.novelty.chamfer > b.novelty.chamfer)
            {
                best = Some(draw);
            }
            if met {
                break;
            }
            tracing::debug!(index, attempt, "draw too close to a training shape");
        }
        let best = best.expect("at least one draw was made");
        let anatomy = measure_mm(&best.shape);
        Ok(self.finish(index, best, anatomy, redraws, None))
    }

    /// The candidate search of a targeted shape.
    fn targeted(&self, index: u64, targeting: &Targeting) -> Result<CohortShape, CohortError> {
        let screening = SCREEN_RESOLUTION.min(self.plan.resolution) < self.plan.resolution;
        let mut source = ShapeCandidates {
            generator: self,
            targeting,
            index,
        };
        let outcome = search(
            &targeting.targets,
            targeting.max_candidates,
            screening,
            &mut source,
        )?;
        let searched = Some(Searched {
            candidates: outcome.candidates,
            refined: outcome.refined,
            met: outcome.met,
        });
        let kept = outcome.kept;
        Ok(self.finish(index, kept.candidate, kept.anatomy, 0, searched))
    }

    /// Meshes draw `attempt` of shape `index` and measures its novelty.
    fn draw(&self, index: u64, attempt: u32, spec: ShapeSpec) -> Result<Draw, CohortError> {
        self.check_cancel()?;
        let shape_error = |error| CohortError::Shape { index, error };
        let shape = self.mesh(index, &spec)?;
        let checked = shape
            .mesh_unit
            .validate()
            .context("engine returned an invalid mesh")
            .and_then(|()| {
                let novelty = self.reference.novelty(&shape.mesh_unit, spec.seed)?;
                anyhow::ensure!(
                    novelty.chamfer.is_finite() && novelty.nearest < self.reference.len(),
                    "novelty is not a finite distance to a training shape"
                );
                Ok(novelty)
            });
        let novelty = checked.map_err(shape_error)?;
        Ok(Draw {
            spec,
            shape,
            novelty,
            attempt,
        })
    }

    /// Meshes a candidate coarsely (at most [`SCREEN_RESOLUTION`]) and measures it.
    fn screen(
        &self,
        index: u64,
        spec: &ShapeSpec,
    ) -> Result<Result<ShapeAnatomy, String>, CohortError> {
        self.check_cancel()?;
        let coarse = ShapeSpec {
            resolution: SCREEN_RESOLUTION.min(self.plan.resolution),
            ..spec.clone()
        };
        let shape = self.mesh(index, &coarse)?;
        Ok(measure_mm(&shape))
    }

    /// The engine's mesh of `spec`; a panic inside the engine (burn reports failures that
    /// way) becomes this shape's error instead of ending the whole cohort's thread.
    fn mesh(&self, index: u64, spec: &ShapeSpec) -> Result<GeneratedShape, CohortError> {
        let call = || {
            self.engine
                .generate_shape(&self.model_dir, spec, &self.cancel)
        };
        let generated = std::panic::catch_unwind(std::panic::AssertUnwindSafe(call))
            .unwrap_or_else(|panic| {
                Err(anyhow::anyhow!(
                    "engine panicked: {}",
                    panic_message(&*panic)
                ))
            });
        generated
            .map_err(|e| stopped_or(&self.cancel, e, |error| CohortError::Shape { index, error }))
    }

    fn novelty_met(&self, novelty: &Novelty) -> bool {
        self.min_novelty.is_none_or(|m| novelty.chamfer >= m)
    }

    fn check_cancel(&self) -> Result<(), CohortError> {
        match self.cancel.load(Ordering::SeqCst) {
            true => Err(CohortError::Cancelled),
            false => Ok(()),
        }
    }

    /// The finished shape of a kept draw; `searched` says what the candidate search did
    /// (targeted cohorts).
    fn finish(
        &self,
        index: u64,
        draw: Draw,
        anatomy: Result<ShapeAnatomy, String>,
        redraws: u32,
        searched: Option<Searched>,
    ) -> CohortShape {
        let plan = &self.plan;
        let k = draw.spec.drawn_members();
        let provenance = ShapeProvenance {
            model_id: self.model_id.clone(),
            training_indices: draw.spec.training_indices.clone(),
            weights: draw.spec.weights.clone(),
            anchors: draw
                .spec
                .anchors
                .iter()
                .zip(&draw.spec.weights[k..])
                .map(|(a, &weight)| AnchorShare {
                    name: a.name.clone(),
                    weight,
                })
                .collect(),
            seed: draw.spec.seed,
            cohort_seed: plan.seed,
            seed_scheme: SEED_SCHEME,
            resolution: draw.spec.resolution as i64,
            software_version: crate::VERSION.to_string(),
            latent_noise: draw.spec.latent_noise,
            selection: plan.selection,
            attempt: i64::from(draw.attempt),
            candidates: searched.map(|s| i64::from(s.candidates)),
            targets_met: searched.map(|s| s.met),
            sampler: self.sampler.clone(),
        };
        CohortShape {
            index,
            novelty_met: self.novelty_met(&draw.novelty),
            spec: draw.spec,
            shape: draw.shape,
            novelty: draw.novelty,
            redraws,
            anatomy,
            refinements: searched.map(|s| s.refined),
            provenance,
        }
    }
}

/// An engine error, or [`CohortError::Cancelled`] when it came from a raised cancel flag.
fn stopped_or(
    cancel: &AtomicBool,
    error: anyhow::Error,
    wrap: impl FnOnce(anyhow::Error) -> CohortError,
) -> CohortError {
    match cancel.load(Ordering::SeqCst) {
        true => CohortError::Cancelled,
        false => wrap(error),
    }
}

/// One meshed draw with its distance to the training set.
#[derive(Debug, Clone)]
struct Draw {
    spec: ShapeSpec,
    shape: GeneratedShape,
    novelty: Novelty,
    attempt: u32,
}

/// A targeted cohort's search settings.
#[derive(Debug, Clone)]
struct Targeting {
    targets: Targets,
    max_candidates: u32,
    /// Training shapes that guided candidates mix ([`guided_pool`]).
    pool: Vec<usize>,
    /// The training shapes' measurements, which weight refinement predicts from.
    training: Vec<Option<ShapeAnatomy>>,
}

impl Targeting {
    fn new(
        search: &TargetSearch,
        training: &TrainingAnatomy,
        arity: usize,
    ) -> Result<Self, CohortError> {
        check_feasible(&search.targets, &training.shapes)?;
        Ok(Self {
            pool: guided_pool(&search.targets, &training.shapes, arity),
            targets: search.targets.clone(),
            max_candidates: search.max_candidates,
            training: training.shapes.clone(),
        })
    }
}

/// The candidates of one shape of a targeted cohort: the plan's draws, guided on alternate
/// attempts, with their weights refined towards the targets where the plan draws them.
struct ShapeCandidates<'a> {
    generator: &'a CohortGenerator,
    targeting: &'a Targeting,
    index: u64,
}

impl CandidateSource for ShapeCandidates<'_> {
    type Spec = ShapeSpec;
    type Kept = Draw;
    type Error = CohortError;

    /// The plan's draw of that attempt, its training shapes taken from the guided pool on
    /// guided attempts, with the anchors forced in. A density sampler's candidates are all
    /// plain draws: there are no training shapes to guide.
    fn draw(&mut self, attempt: u32) -> Result<ShapeSpec, CohortError> {
        let plan = &self.generator.plan;
        let mut spec = plan.draw(self.index, attempt);
        let convex = plan.sampler.is_none();
        if convex && is_guided(attempt) && self.targeting.pool.len() >= plan.arity {
            spec.training_indices = guided_indices(spec.seed, &self.targeting.pool, plan.arity);
        }
        Ok(plan.with_anchors(spec))
    }

    /// Only drawn weights of training shapes are refined; a refinement keeps its draw's
    /// seed (and so its latent noise): only the weights change.
    fn refine(&mut self, spec: &ShapeSpec, measured: &ShapeAnatomy) -> Option<ShapeSpec> {
        let plan = &self.generator.plan;
        if !plan.weights.is_drawn() || plan.sampler.is_some() {
            return None;
        }
        let t = self.targeting;
        let weights = refine_weights(
            &t.targets,
            &t.training,
            &spec.training_indices,
            &spec.weights,
            measured,
        )?;
        Some(ShapeSpec {
            weights,
            ..spec.clone()
        })
    }

    fn screen(&mut self, spec: &ShapeSpec) -> Result<Result<ShapeAnatomy, String>, CohortError> {
        self.generator.screen(self.index, spec)
    }

    fn finalize(&mut self, attempt: u32, spec: &ShapeSpec) -> Result<Measured<Draw>, CohortError> {
        let draw = self.generator.draw(self.index, attempt, spec.clone())?;
        let anatomy = measure_mm(&draw.shape);
        let rank = draw.novelty.chamfer;
        Ok(Measured {
            accept: self.generator.novelty_met(&draw.novelty),
            candidate: draw,
            anatomy,
            rank,
        })
    }
}
