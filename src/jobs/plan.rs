//! How a cohort turns into per-shape specifications: which training shapes each shape
//! mixes and with which weights, all derived from the cohort seed so a cohort can be
//! replayed bit for bit.

use std::sync::Arc;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::engine::{AnchorLatent, ShapeSpec};
use crate::sdf::generate::{Selection, attempt_seed, select_spread};

/// Tolerance on the sum of explicit weights (DESIGN §4).
pub const WEIGHT_SUM_TOLERANCE: f64 = 1e-6;

/// How weights are chosen when the request gives none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Weighting {
    /// 1/k each.
    Equal,
    /// Dirichlet(1, …, 1), i.e. uniform on the simplex, drawn per shape from the seed.
    Dirichlet,
}

impl Weighting {
    /// The stored name.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Equal => "equal",
            Self::Dirichlet => "dirichlet",
        }
    }

    /// Parses a stored name.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "equal" => Some(Self::Equal),
            "dirichlet" => Some(Self::Dirichlet),
            _ => None,
        }
    }
}

/// Everything needed to derive every shape of a cohort.
#[derive(Debug, Clone, PartialEq)]
pub struct CohortPlan {
    /// Training shapes of the model.
    pub training_shapes: usize,
    /// Shapes mixed per generated shape.
    pub arity: usize,
    /// Explicit weights (then used for every shape), else `weighting` applies.
    pub weights: Option<Vec<f64>>,
    /// Strategy when `weights` is None.
    pub weighting: Weighting,
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
}

impl CohortPlan {
    /// The specification of shape `index`; depends only on the plan and the index, so a
    /// resumed job regenerates exactly what an uninterrupted one would have.
    pub fn shape_spec(&self, index: u64) -> ShapeSpec {
        self.shape_spec_attempt(index, 0)
    }

    /// Draw `attempt` of shape `index` (later draws replace shapes too close to a training
    /// shape); its seed derives from the shape seed and the attempt, draw 0 is
    /// [`Self::shape_spec`].
    pub fn shape_spec_attempt(&self, index: u64, attempt: u32) -> ShapeSpec {
        let seed = attempt_seed(shape_seed(self.seed, index), attempt);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let training_indices = match (self.selection, &self.latents) {
            (Selection::Spread, Some(latents)) => select_spread(&mut rng, latents, self.arity),
            _ => choose_distinct(&mut rng, self.training_shapes, self.arity),
        };
        let weights = match (&self.weights, self.weighting) {
            (Some(w), _) => w.clone(),
            (None, Weighting::Equal) => vec![1.0 / self.arity as f64; self.arity],
            (None, Weighting::Dirichlet) => dirichlet_ones(&mut rng, self.arity),
        };
        ShapeSpec {
            training_indices,
            weights,
            seed,
            resolution: self.resolution,
            latent_noise: self.latent_noise,
            anchors: Vec::new(),
        }
    }
}

/// Forces `anchors` into a drawn spec: they take the places of the last `anchors.len()`
/// training picks (and their weights), so the mixture still has `arity` members and every
/// other draw of the plan is unchanged.
pub fn force_anchors(mut spec: ShapeSpec, anchors: &[AnchorLatent]) -> ShapeSpec {
    if anchors.is_empty() {
        return spec;
    }
    let keep = spec.training_indices.len().saturating_sub(anchors.len());
    spec.training_indices.truncate(keep);
    spec.anchors = anchors.to_vec();
    spec
}

/// Checks explicit weights; the error names the violated rule.
pub fn check_weights(weights: &[f64], arity: usize) -> Result<(), String> {
    if weights.len() != arity {
        return Err(format!(
            "must have arity = {arity} entries, got {}",
            weights.len()
        ));
    }
    if let Some(i) = weights.iter().position(|w| !w.is_finite()) {
        return Err(format!("entry {i} is not a finite number"));
    }
    if let Some(i) = weights.iter().position(|w| *w < 0.0) {
        return Err(format!(
            "entry {i} is negative ({}); weights must be ≥ 0",
            weights[i]
        ));
    }
    let sum: f64 = weights.iter().sum();
    if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
        return Err(format!(
            "must sum to 1 within {WEIGHT_SUM_TOLERANCE:e}, sum is {sum}"
        ));
    }
    Ok(())
}

/// Per-shape seed: a SplitMix64 mix of the cohort seed and the index, so neighbouring
/// shapes get unrelated streams.
pub fn shape_seed(cohort_seed: u64, index: u64) -> u64 {
    splitmix64(cohort_seed ^ splitmix64(index.wrapping_add(0x5EED)))
}

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// `k` distinct indices of `0..n` in random order (partial Fisher–Yates).
fn choose_distinct(rng: &mut ChaCha8Rng, n: usize, k: usize) -> Vec<usize> {
    let mut pool: Vec<usize> = (0..n).collect();
    for i in 0..k.min(n) {
        let j = rng.random_range(i..n);
        pool.swap(i, j);
    }
    pool.truncate(k.min(n));
    pool
}

/// A draw from Dirichlet(1, …, 1): normalised Exp(1) variables.
fn dirichlet_ones(rng: &mut ChaCha8Rng, k: usize) -> Vec<f64> {
    let draws: Vec<f64> = (0..k).map(|_| -(1.0 - rng.random::<f64>()).ln()).collect();
    let sum: f64 = draws.iter().sum();
    draws.into_iter().map(|d| d / sum).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(weighting: Weighting) -> CohortPlan {
        CohortPlan {
            training_shapes: 10,
            arity: 4,
            weights: None,
            weighting,
            seed: 42,
            resolution: 64,
            selection: Selection::Uniform,
            latent_noise: 0.0,
            latents: None,
        }
    }

    #[test]
    fn redraws_have_their_own_seeds_and_spread_uses_the_latents() {
        let p = plan(Weighting::Dirichlet);
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
        let p = plan(Weighting::Dirichlet);
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
        let p = plan(Weighting::Equal);
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
        assert_eq!(plan(Weighting::Equal).shape_spec(0).weights, vec![0.25; 4]);
        let p = plan(Weighting::Dirichlet);
        let mut first_weight_mean = 0.0;
        for i in 0..2000 {
            let w = p.shape_spec(i).weights;
            assert!(check_weights(&w, 4).is_ok(), "{w:?}");
            first_weight_mean += w[0] / 2000.0;
        }
        // Dirichlet(1,1,1,1) has E[w_0] = 1/4; the standard error over 2000 draws is ~0.004.
        assert!(
            (first_weight_mean - 0.25).abs() < 0.02,
            "{first_weight_mean}"
        );
    }

    #[test]
    fn forced_anchors_replace_the_last_training_picks_and_keep_the_weights() {
        let p = plan(Weighting::Dirichlet);
        let anchor = AnchorLatent {
            anchor_id: 9,
            latent: vec![0.5; 3],
            transform: crate::geometry::normalize::UnitBallTransform::IDENTITY,
        };
        let drawn = p.shape_spec(4);
        let forced = force_anchors(drawn.clone(), std::slice::from_ref(&anchor));
        assert_eq!(forced.training_indices, drawn.training_indices[..3]);
        assert_eq!(forced.weights, drawn.weights);
        assert_eq!(forced.anchors, [anchor]);
        assert_eq!(forced.seed, drawn.seed);
        assert_eq!(force_anchors(drawn.clone(), &[]), drawn);
    }

    #[test]
    fn explicit_weights_are_used_for_every_shape() {
        let p = CohortPlan {
            weights: Some(vec![0.1, 0.2, 0.3, 0.4]),
            ..plan(Weighting::Equal)
        };
        assert_eq!(p.shape_spec(7).weights, vec![0.1, 0.2, 0.3, 0.4]);
    }

    #[test]
    fn weight_rules_name_the_failed_rule() {
        assert!(check_weights(&[0.5, 0.5], 2).is_ok());
        assert!(check_weights(&[0.5, 0.5 + 0.9e-6], 2).is_ok());
        assert!(check_weights(&[0.5], 2).unwrap_err().contains("arity = 2"));
        assert!(
            check_weights(&[f64::NAN, 1.0], 2)
                .unwrap_err()
                .contains("finite")
        );
        assert!(
            check_weights(&[-0.5, 1.5], 2)
                .unwrap_err()
                .contains("negative")
        );
        assert!(
            check_weights(&[0.5, 0.6], 2)
                .unwrap_err()
                .contains("sum to 1")
        );
    }
}
