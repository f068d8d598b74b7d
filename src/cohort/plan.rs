//! How a cohort turns into per-shape specifications: which training shapes each draw mixes
//! (or which latent a density sampler draws), which fitted anchors, with which weights, all
//! derived from the cohort seed by the [`seeds`](super::seeds) scheme so a cohort can be
//! replayed bit for bit.

use std::path::Path;
use std::sync::Arc;

use anyhow::Context;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::CohortError;
use super::request::CohortRequest;
use super::sampler::joint::JointSampler;
use super::sampler::{LatentSource, SamplerChoice};
use super::seeds::{attempt_seed, shape_seed};
use super::selection::{Selection, choose_distinct, select_spread};
use super::weights::WeightChoice;
use crate::engine::{AnchorLatent, Engine, ShapeSpec};
use crate::geometry::normalize::UnitBallTransform;
use crate::sdf::store::refits::RefittedLatents;

/// The model's training latents (and, for density samplers, their transforms), which
/// spread selection picks from and density samplers are fitted to: the latents from
/// training, or the training shapes' re-fitted latents when the sampler asks for them.
#[derive(Debug, Clone)]
pub struct ModelLatents {
    /// Latents in training-index order.
    pub latents: Arc<Vec<Vec<f32>>>,
    /// Their unit-ball transforms (empty unless read for a density sampler).
    pub transforms: Vec<UnitBallTransform>,
}

impl ModelLatents {
    /// What `request` needs of the model in `model_dir` (none when it needs nothing),
    /// checked to cover its `count` training shapes. Re-fitted latents come from `refitted`
    /// when given (the service's own refit of the model), else from the engine (the
    /// `refits.json` of `aortagen refit` beside the model).
    pub fn read<A>(
        engine: &dyn Engine,
        model_dir: &Path,
        request: &CohortRequest<A>,
        count: usize,
        refitted: Option<RefittedLatents>,
    ) -> anyhow::Result<Option<Self>> {
        let density = !request.sampler.is_convex();
        if !(density || request.selection.needs_latents()) {
            return Ok(None);
        }
        if request.sampler.latent_source() == Some(LatentSource::Refitted) {
            let from_engine = || {
                engine
                    .refitted_latents(model_dir)
                    .context("cannot read the re-fitted latents")
            };
            let (latents, transforms) = match refitted {
                Some(given) => given,
                None => from_engine()?.context(
                    "the model has no re-fitted latents for every training shape \
                     (`aortagen refit` or POST /v1/models/{id}/refit adds them)",
                )?,
            };
            anyhow::ensure!(
                latents.len() == count && transforms.len() == count,
                "the engine returned {} re-fitted latents for {count} training shapes",
                latents.len()
            );
            return Ok(Some(Self {
                latents: Arc::new(latents),
                transforms,
            }));
        }
        let latents = engine
            .training_latents(model_dir)
            .context("cannot read the training latents")?;
        anyhow::ensure!(
            latents.len() == count,
            "the engine returned {} latents for {count} training shapes",
            latents.len()
        );
        let transforms = match density {
            false => Vec::new(),
            true => engine
                .training_transforms(model_dir)
                .context("cannot read the training transforms")?,
        };
        Ok(Some(Self {
            latents: Arc::new(latents),
            transforms,
        }))
    }
}

/// Everything needed to derive every draw of every shape of a cohort.
#[derive(Debug, Clone, PartialEq)]
pub struct CohortPlan {
    /// Training shapes of the model.
    pub training_shapes: usize,
    /// Shapes mixed per generated shape, anchors included.
    pub arity: usize,
    /// Where the weights come from.
    pub weights: WeightChoice,
    /// Cohort seed.
    pub seed: u64,
    /// Marching-cubes resolution.
    pub resolution: usize,
    /// How the training latents are picked.
    pub selection: Selection,
    /// Latent noise in training standard deviations.
    pub latent_noise: f64,
    /// The training latents (needed by [`Selection::Spread`] only).
    pub latents: Option<Arc<Vec<Vec<f32>>>>,
    /// Fitted anchors forced into every shape, in the request's order.
    pub anchors: Vec<AnchorLatent>,
    /// The density sampler drawing each shape's latent (none: convex combinations).
    pub sampler: Option<Arc<JointSampler>>,
}

impl CohortPlan {
    /// The plan of `request` on a model with `training_shapes` shapes (the request's rules
    /// against the model hold: see [`CohortRequest::check_model`]); `latents` are the
    /// training latents when the selection needs them, `anchors` the request's anchors.
    ///
    /// A density sampler is fitted here, to `model`'s latents and transforms: a pure function
    /// of them, so the command line and a resumed job fit the same sampler.
    pub fn new<A>(
        request: &CohortRequest<A>,
        training_shapes: usize,
        model: Option<&ModelLatents>,
        anchors: Vec<AnchorLatent>,
    ) -> Result<Self, CohortError> {
        let sampler = match (&request.sampler, model) {
            (SamplerChoice::Convex, _) => None,
            (SamplerChoice::Density(config, _), Some(m)) => Some(Arc::new(
                JointSampler::fit(config, &m.latents, &m.transforms)
                    .map_err(CohortError::Sampler)?,
            )),
            (SamplerChoice::Density(..), None) => {
                return Err(CohortError::Reference(anyhow::anyhow!(
                    "a density sampler needs the training latents"
                )));
            }
        };
        Ok(Self {
            training_shapes,
            arity: request.arity,
            weights: request.weights.clone(),
            seed: request.seed,
            resolution: request.resolution,
            selection: request.selection,
            latent_noise: request.latent_noise,
            latents: model.map(|m| m.latents.clone()),
            anchors,
            sampler,
        })
    }

    /// The specification of shape `index`; depends only on the plan and the index, so a
    /// resumed job regenerates exactly what an uninterrupted one would have.
    pub fn shape_spec(&self, index: u64) -> ShapeSpec {
        self.shape_spec_attempt(index, 0)
    }

    /// Draw `attempt` of shape `index` with the anchors forced in; draw 0 is
    /// [`Self::shape_spec`].
    pub fn shape_spec_attempt(&self, index: u64, attempt: u32) -> ShapeSpec {
        self.with_anchors(self.draw(index, attempt))
    }

    /// Draw `attempt` of shape `index` before the anchors are forced in: `arity` training
    /// shapes and `arity` weights, from the draw's own seed — or, with a density sampler,
    /// the sampled latent (from the same seed, its own stream) and the weights.
    pub fn draw(&self, index: u64, attempt: u32) -> ShapeSpec {
        let seed = attempt_seed(shape_seed(self.seed, index), attempt);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        if let Some(sampler) = &self.sampler {
            return ShapeSpec {
                training_indices: Vec::new(),
                weights: self.weights.draw(&mut rng, self.arity),
                seed,
                resolution: self.resolution,
                latent_noise: 0.0,
                anchors: Vec::new(),
                sampled: Some(sampler.draw(seed)),
            };
        }
        let training_indices = match (self.selection, &self.latents) {
            (Selection::Spread, Some(latents)) => select_spread(&mut rng, latents, self.arity),
            _ => choose_distinct(&mut rng, self.training_shapes, self.arity),
        };
        let weights = self.weights.draw(&mut rng, self.arity);
        ShapeSpec {
            training_indices,
            weights,
            seed,
            resolution: self.resolution,
            latent_noise: self.latent_noise,
            anchors: Vec::new(),
            sampled: None,
        }
    }

    /// Forces the plan's anchors into a draw: they take the places of its last training
    /// picks (and their weights), so the mixture still has `arity` members and every other
    /// draw of the plan is unchanged. A sampled latent keeps its place before them.
    pub fn with_anchors(&self, mut spec: ShapeSpec) -> ShapeSpec {
        if self.anchors.is_empty() {
            return spec;
        }
        let keep = spec
            .training_indices
            .len()
            .saturating_sub(self.anchors.len());
        spec.training_indices.truncate(keep);
        spec.anchors = self.anchors.clone();
        spec
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cohort::weights::check_weights;

    fn plan(weights: WeightChoice) -> CohortPlan {
        CohortPlan {
            training_shapes: 10,
            arity: 4,
            weights,
            seed: 42,
            resolution: 64,
            selection: Selection::Uniform,
            latent_noise: 0.0,
            latents: None,
            anchors: Vec::new(),
            sampler: None,
        }
    }

    #[test]
    fn redraws_have_their_own_seeds_and_spread_uses_the_latents() {
        let p = plan(WeightChoice::Dirichlet);
        assert_eq!(p.shape_spec_attempt(5, 0), p.shape_spec(5));
        let first = p.shape_spec_attempt(5, 0);
        let second = p.shape_spec_attempt(5, 1);
        assert_ne!(first.seed, second.seed);
        assert_eq!(second, p.shape_spec_attempt(5, 1));
        // Latents 0–7 coincide at the origin, 8 and 9 lie far away: a spread pair always
        // contains one of the far ones, a uniform pair often does not.
        let mut latents = vec![vec![0.0f32; 2]; 10];
        latents[8] = vec![5.0, 0.0];
        latents[9] = vec![0.0, 5.0];
        let spread = CohortPlan {
            arity: 2,
            selection: Selection::Spread,
            latents: Some(Arc::new(latents)),
            ..p.clone()
        };
        let uniform = CohortPlan {
            arity: 2,
            ..p.clone()
        };
        let far = |plan: &CohortPlan| {
            (0..100)
                .filter(|&i| plan.shape_spec(i).training_indices.iter().any(|&j| j >= 8))
                .count()
        };
        assert_eq!(far(&spread), 100);
        assert!(far(&uniform) < 60, "{}", far(&uniform));
    }

    #[test]
    fn specs_are_reproducible_and_differ_between_shapes() {
        let p = plan(WeightChoice::Dirichlet);
        assert_eq!(p.shape_spec(3), p.shape_spec(3));
        assert_ne!(p.shape_spec(3), p.shape_spec(4));
        let other_seed = CohortPlan {
            seed: 43,
            ..p.clone()
        };
        assert_ne!(p.shape_spec(3), other_seed.shape_spec(3));
    }

    #[test]
    fn training_indices_are_distinct_and_in_range() {
        let p = plan(WeightChoice::Equal);
        for i in 0..200 {
            let mut idx = p.shape_spec(i).training_indices;
            assert!(idx.iter().all(|&j| j < 10));
            idx.sort_unstable();
            idx.dedup();
            assert_eq!(idx.len(), 4, "shape {i}");
        }
    }

    #[test]
    fn generated_weights_lie_on_the_simplex() {
        assert_eq!(
            plan(WeightChoice::Equal).shape_spec(0).weights,
            vec![0.25; 4]
        );
        let p = plan(WeightChoice::Dirichlet);
        for i in 0..200 {
            let w = p.shape_spec(i).weights;
            assert!(check_weights(&w, 4).is_ok(), "{w:?}");
        }
    }

    #[test]
    fn forced_anchors_replace_the_last_training_picks_and_keep_the_weights() {
        let anchor = AnchorLatent {
            name: "patient".into(),
            latent: vec![0.5; 3],
            transform: crate::geometry::normalize::UnitBallTransform::IDENTITY,
        };
        let p = plan(WeightChoice::Dirichlet);
        let anchored = CohortPlan {
            anchors: vec![anchor.clone()],
            ..p.clone()
        };
        let drawn = p.shape_spec(4);
        let forced = anchored.shape_spec(4);
        assert_eq!(forced.training_indices, drawn.training_indices[..3]);
        assert_eq!(forced.weights, drawn.weights);
        assert_eq!(forced.anchors, [anchor]);
        assert_eq!(forced.seed, drawn.seed);
        assert_eq!(p.with_anchors(drawn.clone()), drawn);
    }

    #[test]
    fn explicit_weights_are_used_for_every_shape() {
        let p = plan(WeightChoice::Fixed(vec![0.1, 0.2, 0.3, 0.4]));
        assert_eq!(p.shape_spec(7).weights, vec![0.1, 0.2, 0.3, 0.4]);
    }
}
