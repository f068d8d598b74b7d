//! The cohort request (DESIGN §4), parsed once: [`CohortFields`] is what arrives (an HTTP
//! body or command-line flags), [`CohortRequest`] what the rest of the code works with. Every
//! rule is checked on the way in and a broken one is a [`RequestError`] naming the field and
//! the rule, so the API and the command line refuse the same requests with the same words.

use std::collections::BTreeMap;
use std::fmt::Display;

use super::sampler::{LatentSource, SamplerChoice, SamplerFields};
use super::targets::{DEFAULT_MAX_CANDIDATES, MAX_CANDIDATES, TargetError, TargetRange, Targets};
use super::weights::{WeightChoice, WeightError, Weighting};
use super::{DEFAULT_RESOLUTION, RESOLUTION_RANGE, Selection};
use crate::engine::ModelInfo;

/// Fewest shapes a cohort may have.
pub const MIN_COUNT: i64 = 1;
/// Fewest members a convex combination mixes.
pub const MIN_CONVEX_ARITY: i64 = 2;

/// A cohort request as it arrives, before its rules are checked. `A` names an anchor: an id
/// in the service, a name in a model directory's `anchors.json` on the command line.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CohortFields<A> {
    /// Number of shapes.
    pub count: i64,
    /// Shapes mixed per generated shape, anchors included (required by the convex sampler;
    /// 1 + anchors with a density sampler).
    pub arity: Option<i64>,
    /// Explicit weights (length = arity).
    pub weights: Option<Vec<f64>>,
    /// Weight strategy when `weights` is absent (default Dirichlet).
    pub weighting: Option<Weighting>,
    /// Seed (drawn when absent).
    pub seed: Option<u64>,
    /// Marching-cubes resolution per axis.
    pub resolution: Option<i64>,
    /// Latent noise in training standard deviations.
    pub latent_noise: Option<f64>,
    /// How the training latents are picked.
    pub selection: Option<Selection>,
    /// Smallest accepted Chamfer distance to the nearest training shape.
    pub min_novelty: Option<f64>,
    /// Target ranges (mm) keyed by measurement name.
    pub targets: Option<BTreeMap<String, TargetRange>>,
    /// Most candidates per targeted shape.
    pub max_candidates: Option<i64>,
    /// Fitted anchors forced into every shape.
    pub anchors: Option<Vec<A>>,
    /// The sampler (absent: convex combinations).
    pub sampler: Option<SamplerFields>,
}

/// Bounds the service configures on a request (the command line has none).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RequestLimits {
    /// Most shapes per cohort.
    pub max_count: u32,
    /// Most `count × resolution³` voxels per cohort (the work budget).
    pub max_voxels: u64,
}

impl RequestLimits {
    /// No bound beyond what the types hold.
    pub const NONE: Self = Self {
        max_count: u32::MAX,
        max_voxels: u64::MAX,
    };
}

/// A valid cohort request.
#[derive(Debug, Clone, PartialEq)]
pub struct CohortRequest<A> {
    /// Number of shapes (≥ 1).
    pub count: u32,
    /// Members mixed per generated shape, anchors included: training shapes (≥ 2 in all)
    /// for the convex sampler, the sampled latent (1 + anchors) for a density sampler.
    pub arity: usize,
    /// How each shape's latent is drawn.
    pub sampler: SamplerChoice,
    /// Where each shape's weights come from.
    pub weights: WeightChoice,
    /// The seed (given, or drawn when the request was parsed).
    pub seed: u64,
    /// Marching-cubes resolution within [`RESOLUTION_RANGE`].
    pub resolution: usize,
    /// How the training latents are picked.
    pub selection: Selection,
    /// Latent noise (finite, ≥ 0; 0 = plain convex combinations).
    pub latent_noise: f64,
    /// Smallest accepted novelty (finite, ≥ 0), if any.
    pub min_novelty: Option<f64>,
    /// Anatomical targets and the candidate bound, if any.
    pub targets: Option<TargetSearch>,
    /// Distinct anchors, at most `arity` of them (empty: none).
    pub anchors: Vec<A>,
}

/// The targets of a conditioned cohort.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetSearch {
    /// The ranges.
    pub targets: Targets,
    /// Most candidates per shape (1–[`MAX_CANDIDATES`]).
    pub max_candidates: u32,
}

/// A broken rule of a cohort request.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct RequestError {
    /// The offending field (a JSON path such as `targets.annulus_mm.min` or `anchors[1]`).
    pub field: String,
    /// Short rule name (`range`, `budget`, `sum`, `feasible`, …).
    pub rule: &'static str,
    /// Human sentence.
    pub message: String,
}

impl RequestError {
    /// A broken `rule` of `field`.
    pub fn new(field: impl Into<String>, rule: &'static str, message: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            rule,
            message: message.into(),
        }
    }
}

impl From<WeightError> for RequestError {
    fn from(e: WeightError) -> Self {
        Self::new("weights", e.rule(), e.to_string())
    }
}

impl From<TargetError> for RequestError {
    fn from(e: TargetError) -> Self {
        Self::new(e.field(), e.rule(), e.to_string())
    }
}

impl From<super::Infeasible> for RequestError {
    fn from(e: super::Infeasible) -> Self {
        Self::new(e.field(), "feasible", e.to_string())
    }
}

impl<A: PartialEq + Display + Clone> CohortRequest<A> {
    /// Checks every rule that needs no model, in a fixed order, and returns the typed
    /// request; `draw_seed` gives the seed when the request has none.
    pub fn parse(
        fields: CohortFields<A>,
        limits: RequestLimits,
        draw_seed: impl FnOnce() -> u64,
    ) -> Result<Self, RequestError> {
        let count = check_count(fields.count, limits.max_count)?;
        let sampler = SamplerChoice::parse(fields.sampler.as_ref())?;
        let anchor_count = fields.anchors.as_ref().map_or(0, Vec::len);
        let arity = check_arity(fields.arity, &sampler, anchor_count)?;
        if !sampler.is_convex() {
            check_convex_only(&fields)?;
        }
        let resolution = check_resolution(fields.resolution)?;
        let weighting = fields.weighting.unwrap_or_default();
        let weights = WeightChoice::new(fields.weights, weighting, arity)?;
        let latent_noise = non_negative("latent_noise", fields.latent_noise)?.unwrap_or(0.0);
        let min_novelty = non_negative("min_novelty", fields.min_novelty)?;
        let targets = target_search(fields.targets, fields.max_candidates)?;
        let draws = draws_per_shape(targets.as_ref(), min_novelty);
        check_budget(count, draws, 0, resolution, limits.max_voxels)?;
        let anchors = fields
            .anchors
            .map(|a| check_anchors(a, arity))
            .transpose()?;
        Ok(Self {
            count,
            arity,
            sampler,
            weights,
            seed: fields.seed.unwrap_or_else(draw_seed),
            resolution,
            selection: fields.selection.unwrap_or_default(),
            latent_noise,
            min_novelty,
            targets,
            anchors: anchors.unwrap_or_default(),
        })
    }

    /// The rules against the model: the arity within its training shapes, a density
    /// sampler's component count below them, and re-fitted latents only from a model that
    /// has them.
    pub fn check_model(&self, model: &ModelInfo) -> Result<(), RequestError> {
        let training_shapes = model.training_shape_count();
        if self.sampler.latent_source() == Some(LatentSource::Refitted) && !model.refitted_latents {
            return Err(RequestError::new(
                "sampler.latents",
                "unavailable",
                "the model's training shapes were not re-fitted (POST /v1/models/{id}/refit or \
                 `aortagen refit` fits them with the network frozen); use \"training\"",
            ));
        }
        if let SamplerChoice::Density(crate::latent_models::SamplerConfig::PcaMixture(m), _) =
            &self.sampler
            && let crate::latent_models::mixture::ComponentCount::Fixed(k) = m.components
            && k > training_shapes
        {
            let msg =
                format!("must not exceed the model's {training_shapes} training shapes, got {k}");
            return Err(RequestError::new("sampler.components", "range", msg));
        }
        if self.arity > training_shapes {
            let msg = format!(
                "must not exceed the model's {training_shapes} training shapes, got {}",
                self.arity
            );
            return Err(RequestError::new("arity", "range", msg));
        }
        Ok(())
    }

    /// The work budget with the setup this request needs on its model: `setup_shapes`
    /// training shapes not yet reconstructed at the request's resolution (each one field
    /// evaluation like a draw).
    pub fn check_budget_with_setup(
        &self,
        setup_shapes: usize,
        max_voxels: u64,
    ) -> Result<(), RequestError> {
        check_budget(
            self.count,
            draws_per_shape(self.targets.as_ref(), self.min_novelty),
            setup_shapes as u64,
            self.resolution,
            max_voxels,
        )
    }
}

/// Draws per shape at most: candidates with targets, redraws with a minimum novelty, one
/// otherwise.
fn draws_per_shape(targets: Option<&TargetSearch>, min_novelty: Option<f64>) -> u32 {
    match (targets, min_novelty) {
        (Some(t), _) => t.max_candidates,
        (None, Some(_)) => super::MAX_REDRAWS + 1,
        (None, None) => 1,
    }
}

/// The arity: given and ≥ 2 for the convex sampler; 1 + anchors (given or not) for a
/// density sampler.
fn check_arity(
    arity: Option<i64>,
    sampler: &SamplerChoice,
    anchors: usize,
) -> Result<usize, RequestError> {
    if !sampler.is_convex() {
        let members = 1 + anchors;
        return match arity {
            None => Ok(members),
            Some(a) if a == members as i64 => Ok(members),
            Some(a) => {
                let msg = format!(
                    "with a density sampler each shape mixes its sampled latent and the \
                     {anchors} anchors, so arity is {members} (or left out), got {a}"
                );
                Err(RequestError::new("arity", "range", msg))
            }
        };
    }
    match arity {
        None => {
            let msg = "is required by the convex sampler (training shapes mixed per shape)";
            Err(RequestError::new("arity", "required", msg))
        }
        Some(a) if a < MIN_CONVEX_ARITY => {
            let msg = format!("must be at least {MIN_CONVEX_ARITY}, got {a}");
            Err(RequestError::new("arity", "range", msg))
        }
        Some(a) => Ok(usize::try_from(a).unwrap_or(usize::MAX)),
    }
}

/// Fields that only convex combinations have, refused with a density sampler.
fn check_convex_only<A>(fields: &CohortFields<A>) -> Result<(), RequestError> {
    let msg = "applies to the convex sampler only; a density sampler's spread is set by \
               its own parameters";
    if fields.selection == Some(Selection::Spread) {
        return Err(RequestError::new("selection", "convex-only", msg));
    }
    if fields.latent_noise.is_some_and(|n| n != 0.0) {
        return Err(RequestError::new("latent_noise", "convex-only", msg));
    }
    Ok(())
}

fn check_count(count: i64, max_count: u32) -> Result<u32, RequestError> {
    if !(MIN_COUNT..=i64::from(max_count)).contains(&count) {
        let msg = format!("must be between {MIN_COUNT} and {max_count}, got {count}");
        return Err(RequestError::new("count", "range", msg));
    }
    Ok(count as u32)
}

fn check_resolution(resolution: Option<i64>) -> Result<usize, RequestError> {
    let (lo, hi) = (
        *RESOLUTION_RANGE.start() as i64,
        *RESOLUTION_RANGE.end() as i64,
    );
    match resolution {
        None => Ok(DEFAULT_RESOLUTION),
        Some(r) if (lo..=hi).contains(&r) => Ok(r as usize),
        Some(r) => {
            let msg = format!("must be between {lo} and {hi}, got {r}");
            Err(RequestError::new("resolution", "range", msg))
        }
    }
}

/// The work budget: the field evaluations a cohort may cost, `(count × draws per shape +
/// setup shapes) × resolution³` voxels, named on `count`. Draws per shape are the worst
/// case (every candidate of a targeted shape, every redraw of a novelty minimum); setup
/// shapes are the model's training shapes reconstructed at a resolution for the first time.
/// (The pairwise step is bounded on its own: at most 4 950 pairs whatever the count.)
fn check_budget(
    count: u32,
    draws: u32,
    setup_shapes: u64,
    resolution: usize,
    max_voxels: u64,
) -> Result<(), RequestError> {
    let cube = (resolution as u64).pow(3);
    let draws_total = u64::from(count).saturating_mul(u64::from(draws.max(1)));
    let voxels = draws_total
        .saturating_add(setup_shapes)
        .saturating_mul(cube);
    if voxels <= max_voxels {
        return Ok(());
    }
    let fields = max_voxels / cube;
    let plural = if setup_shapes == 1 { "" } else { "s" };
    if setup_shapes > 0 && setup_shapes >= fields {
        let msg = format!(
            "the model's {setup_shapes} training shape{plural} must first be reconstructed at resolution \
             {resolution} before any draw: {setup_shapes} × {resolution}³ = {} voxels, which \
             leaves no room in the budget of {max_voxels} voxels; ask a lower resolution (a \
             cohort at a resolution reuses the reconstructions) or raise \
             --max-cohort-voxels",
            setup_shapes.saturating_mul(cube)
        );
        return Err(RequestError::new("resolution", "budget", msg));
    }
    let most = (fields - setup_shapes) / u64::from(draws.max(1));
    let mut terms = format!("{count}");
    if draws > 1 {
        terms.push_str(&format!(
            " shapes × {draws} draws a shape (the most a novelty minimum or a target search may take)"
        ));
    }
    if setup_shapes > 0 {
        terms = format!(
            "({terms} + {setup_shapes} training shape{plural} first reconstructed at this \
             resolution)"
        );
    }
    let msg = format!(
        "a cohort's field evaluations must not exceed {max_voxels} voxels, got {terms} × \
         {resolution}³ = {voxels}; at resolution {resolution} at most {most} shapes"
    );
    Err(RequestError::new("count", "budget", msg))
}

fn non_negative(field: &str, value: Option<f64>) -> Result<Option<f64>, RequestError> {
    match value {
        Some(v) if !(v.is_finite() && v >= 0.0) => {
            let msg = format!("must be a finite number ≥ 0, got {v}");
            Err(RequestError::new(field, "non-negative", msg))
        }
        other => Ok(other),
    }
}

fn target_search(
    ranges: Option<BTreeMap<String, TargetRange>>,
    max_candidates: Option<i64>,
) -> Result<Option<TargetSearch>, RequestError> {
    if let Some(m) = max_candidates {
        if !(1..=i64::from(MAX_CANDIDATES)).contains(&m) {
            let msg = format!("must be between 1 and {MAX_CANDIDATES}, got {m}");
            return Err(RequestError::new("max_candidates", "range", msg));
        }
        if ranges.is_none() {
            let msg = "applies to targeted cohorts only; give targets too";
            return Err(RequestError::new("max_candidates", "requires-targets", msg));
        }
    }
    let Some(ranges) = ranges else {
        return Ok(None);
    };
    Ok(Some(TargetSearch {
        targets: Targets::parse(&ranges)?,
        max_candidates: max_candidates.map_or(DEFAULT_MAX_CANDIDATES, |m| m as u32),
    }))
}

/// The anchor list's own rules: 1 ≤ length ≤ arity, distinct.
fn check_anchors<A: PartialEq + Display>(
    anchors: Vec<A>,
    arity: usize,
) -> Result<Vec<A>, RequestError> {
    if anchors.is_empty() || anchors.len() > arity {
        let msg = format!(
            "must list 1 to arity = {arity} anchors, got {}",
            anchors.len()
        );
        return Err(RequestError::new("anchors", "length", msg));
    }
    for (i, a) in anchors.iter().enumerate() {
        if anchors[..i].contains(a) {
            let msg = format!("anchor {a} is listed twice");
            return Err(RequestError::new(format!("anchors[{i}]"), "distinct", msg));
        }
    }
    Ok(anchors)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields() -> CohortFields<i64> {
        CohortFields {
            count: 3,
            arity: Some(2),
            ..CohortFields::default()
        }
    }

    fn parse(f: CohortFields<i64>) -> Result<CohortRequest<i64>, RequestError> {
        let limits = RequestLimits {
            max_count: 10,
            max_voxels: 3 * 64u64.pow(3),
        };
        CohortRequest::parse(f, limits, || 99)
    }

    #[test]
    fn defaults_fill_what_the_request_leaves_out() {
        let f = CohortFields {
            resolution: Some(64),
            ..fields()
        };
        let r = parse(f).unwrap();
        assert_eq!((r.count, r.arity, r.seed, r.resolution), (3, 2, 99, 64));
        assert_eq!(r.weights, WeightChoice::Dirichlet);
        assert_eq!((r.selection, r.latent_noise), (Selection::Uniform, 0.0));
        assert!(r.targets.is_none() && r.anchors.is_empty() && r.min_novelty.is_none());
        assert_eq!(draws_per_shape(r.targets.as_ref(), r.min_novelty), 1);
    }

    #[test]
    fn each_broken_rule_names_its_field_and_rule() {
        let at64 = |f: CohortFields<i64>| CohortFields {
            resolution: Some(64),
            ..f
        };
        let cases: Vec<(CohortFields<i64>, &str, &str)> = vec![
            (
                CohortFields {
                    count: 0,
                    ..fields()
                },
                "count",
                "range",
            ),
            (
                CohortFields {
                    count: 11,
                    ..fields()
                },
                "count",
                "range",
            ),
            (
                CohortFields {
                    arity: Some(1),
                    ..fields()
                },
                "arity",
                "range",
            ),
            (
                CohortFields {
                    arity: None,
                    ..fields()
                },
                "arity",
                "required",
            ),
            (
                CohortFields {
                    resolution: Some(16),
                    ..fields()
                },
                "resolution",
                "range",
            ),
            // The default resolution (256³) is over this budget.
            (fields(), "count", "budget"),
            (
                at64(CohortFields {
                    weights: Some(vec![0.5, 0.6]),
                    ..fields()
                }),
                "weights",
                "sum",
            ),
            (
                at64(CohortFields {
                    latent_noise: Some(-1.0),
                    ..fields()
                }),
                "latent_noise",
                "non-negative",
            ),
            (
                at64(CohortFields {
                    min_novelty: Some(f64::NAN),
                    ..fields()
                }),
                "min_novelty",
                "non-negative",
            ),
            (
                at64(CohortFields {
                    max_candidates: Some(3),
                    ..fields()
                }),
                "max_candidates",
                "requires-targets",
            ),
            (
                at64(CohortFields {
                    anchors: Some(vec![1, 2, 3]),
                    ..fields()
                }),
                "anchors",
                "length",
            ),
            (
                at64(CohortFields {
                    anchors: Some(vec![4, 4]),
                    ..fields()
                }),
                "anchors[1]",
                "distinct",
            ),
        ];
        for (f, field, rule) in cases {
            let err = parse(f.clone()).unwrap_err();
            assert_eq!(
                (err.field.as_str(), err.rule),
                (field, rule),
                "{f:?}: {err}"
            );
        }
    }

    #[test]
    fn the_budget_counts_every_draw_a_shape_may_take_and_the_setup() {
        // 3 shapes at 64³ fill the test budget of 3 × 64³ voxels exactly.
        let plain = CohortFields {
            resolution: Some(64),
            ..fields()
        };
        let r = parse(plain.clone()).unwrap();
        // A novelty minimum may take 11 draws a shape: 33 fields.
        let err = parse(CohortFields {
            min_novelty: Some(0.01),
            ..plain.clone()
        })
        .unwrap_err();
        assert_eq!((err.field.as_str(), err.rule), ("count", "budget"));
        assert!(err.message.contains("11 draws a shape"), "{}", err.message);
        // At 32³ the budget holds 24 fields: 2 shapes of 11 draws.
        let err = parse(CohortFields {
            min_novelty: Some(0.01),
            resolution: Some(32),
            ..plain.clone()
        })
        .unwrap_err();
        assert!(err.message.contains("at most 2 shapes"), "{}", err.message);
        // Training shapes first reconstructed at the resolution count as well.
        assert!(r.check_budget_with_setup(0, 3 * 64u64.pow(3)).is_ok());
        let err = r.check_budget_with_setup(1, 3 * 64u64.pow(3)).unwrap_err();
        assert!(
            err.message.contains("1 training shape first"),
            "{}",
            err.message
        );
        assert!(err.message.contains("at most 2 shapes"), "{}", err.message);
        // When the setup alone fills the budget no count fits: the resolution is at fault.
        let err = r.check_budget_with_setup(3, 3 * 64u64.pow(3)).unwrap_err();
        assert_eq!((err.field.as_str(), err.rule), ("resolution", "budget"));
        assert!(err.message.contains("3 training shapes"), "{}", err.message);
    }

    #[test]
    fn targets_bring_their_candidate_bound() {
        let mut ranges = BTreeMap::new();
        ranges.insert(
            "annulus_mm".into(),
            TargetRange {
                min: Some(20.0),
                max: None,
            },
        );
        // One shape of 20 candidates at 32³ fits the test budget of 3 × 64³ voxels.
        let f = CohortFields {
            count: 1,
            resolution: Some(32),
            targets: Some(ranges),
            ..fields()
        };
        let r = parse(f.clone()).unwrap();
        assert_eq!(
            r.targets.as_ref().unwrap().max_candidates,
            DEFAULT_MAX_CANDIDATES
        );
        assert_eq!(
            draws_per_shape(r.targets.as_ref(), r.min_novelty),
            DEFAULT_MAX_CANDIDATES
        );
        let r = parse(CohortFields {
            max_candidates: Some(7),
            ..f
        })
        .unwrap();
        assert_eq!(r.targets.unwrap().max_candidates, 7);
    }

    #[test]
    fn a_density_sampler_counts_its_latent_and_the_anchors_and_refuses_convex_fields() {
        use crate::cohort::sampler::SamplerKind;
        let gaussian = Some(SamplerFields {
            kind: SamplerKind::PcaGaussian,
            ..SamplerFields::default()
        });
        let density = |f: CohortFields<i64>| CohortFields {
            sampler: gaussian.clone(),
            resolution: Some(64),
            ..f
        };
        let r = parse(density(CohortFields {
            arity: None,
            ..fields()
        }))
        .unwrap();
        assert_eq!(r.arity, 1);
        assert!(!r.sampler.is_convex());
        let r = parse(density(CohortFields {
            arity: None,
            anchors: Some(vec![4]),
            weights: Some(vec![0.7, 0.3]),
            ..fields()
        }))
        .unwrap();
        assert_eq!((r.arity, r.weights.fixed()), (2, Some(&[0.7, 0.3][..])));
        for (f, field, rule) in [
            (
                CohortFields {
                    arity: Some(3),
                    ..fields()
                },
                "arity",
                "range",
            ),
            (
                CohortFields {
                    arity: None,
                    selection: Some(Selection::Spread),
                    ..fields()
                },
                "selection",
                "convex-only",
            ),
            (
                CohortFields {
                    arity: None,
                    latent_noise: Some(0.5),
                    ..fields()
                },
                "latent_noise",
                "convex-only",
            ),
            (
                CohortFields {
                    arity: None,
                    weights: Some(vec![0.5, 0.5]),
                    ..fields()
                },
                "weights",
                "length",
            ),
        ] {
            let err = parse(density(f)).unwrap_err();
            assert_eq!((err.field.as_str(), err.rule), (field, rule), "{err}");
        }
        // The plain fields the command line always sends are accepted.
        assert!(
            parse(density(CohortFields {
                arity: None,
                selection: Some(Selection::Uniform),
                latent_noise: Some(0.0),
                ..fields()
            }))
            .is_ok()
        );
    }

    #[test]
    fn the_arity_is_checked_against_the_model() {
        let r = parse(CohortFields {
            arity: Some(5),
            resolution: Some(64),
            ..fields()
        })
        .unwrap();
        assert!(r.check_model(&model(5, false)).is_ok());
        let err = r.check_model(&model(4, false)).unwrap_err();
        assert_eq!((err.field.as_str(), err.rule), ("arity", "range"));
    }

    fn model(shapes: usize, refitted_latents: bool) -> ModelInfo {
        ModelInfo {
            refitted_latents,
            ..ModelInfo::with_shapes(2, (0..shapes).map(|i| format!("s{i}")))
        }
    }

    #[test]
    fn refitted_latents_are_asked_only_of_a_model_that_has_them() {
        let r = parse(CohortFields {
            arity: None,
            resolution: Some(64),
            sampler: Some(SamplerFields {
                latents: Some(LatentSource::Refitted),
                ..SamplerFields {
                    kind: crate::cohort::SamplerKind::PcaGaussian,
                    ..SamplerFields::default()
                }
            }),
            ..fields()
        })
        .unwrap();
        let err = r.check_model(&model(5, false)).unwrap_err();
        assert_eq!(
            (err.field.as_str(), err.rule),
            ("sampler.latents", "unavailable")
        );
        assert!(r.check_model(&model(5, true)).is_ok());
    }
}
