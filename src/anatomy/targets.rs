//! Conditioned cohorts: target ranges for anatomical measurements, their feasibility against
//! a model's training shapes, and the bounded candidate search that meets them.
//!
//! The search is engine-agnostic: callers implement [`CandidateSource`] to draw, refine,
//! mesh and measure candidates, so the service and the command line run the same loop and
//! tests can drive it with a cheap stand-in.

use std::collections::BTreeMap;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::shape::ShapeAnatomy;

/// Candidates tried per shape when the request does not say.
pub const DEFAULT_MAX_CANDIDATES: u32 = 20;
/// Hard cap on candidates per shape (each costs one coarse extraction).
pub const MAX_CANDIDATES: u32 = 100;
/// Grid resolution of the coarse extraction candidates are screened with (and the
/// training shapes measured at).
pub const SCREEN_RESOLUTION: usize = 64;
/// A target is feasible when it overlaps the training shapes' range of that measurement
/// widened on both sides by this fraction of the largest training value: convex mixtures
/// mostly interpolate the measurements, but the decoder and the mixed transform can move a
/// little past the extremes.
pub const FEASIBILITY_MARGIN: f64 = 0.05;

/// A measurement a target may name (the fields of [`ShapeAnatomy`] in mm).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Measurement {
    /// `annulus_mm`.
    Annulus,
    /// `sinus_mm`.
    Sinus,
    /// `stj_mm`.
    Stj,
    /// `sinus_height_mm`.
    SinusHeight,
    /// `ascending_mm`.
    Ascending,
    /// `length_mm`.
    Length,
    /// `max_diameter_mm`.
    MaxDiameter,
}

impl Measurement {
    /// Every measurement, in order.
    pub const ALL: [Self; 7] = [
        Self::Annulus,
        Self::Sinus,
        Self::Stj,
        Self::SinusHeight,
        Self::Ascending,
        Self::Length,
        Self::MaxDiameter,
    ];

    /// The name used in requests and in [`ShapeAnatomy`].
    pub fn name(self) -> &'static str {
        match self {
            Self::Annulus => "annulus_mm",
            Self::Sinus => "sinus_mm",
            Self::Stj => "stj_mm",
            Self::SinusHeight => "sinus_height_mm",
            Self::Ascending => "ascending_mm",
            Self::Length => "length_mm",
            Self::MaxDiameter => "max_diameter_mm",
        }
    }

    /// Parses a name.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Its value on a measured shape (the root landmarks are absent on a plain vessel).
    pub fn value(self, a: &ShapeAnatomy) -> Option<f64> {
        match self {
            Self::Annulus => a.annulus_mm,
            Self::Sinus => a.sinus_mm,
            Self::Stj => a.stj_mm,
            Self::SinusHeight => a.sinus_height_mm,
            Self::Ascending => a.ascending_mm,
            Self::Length => Some(a.length_mm),
            Self::MaxDiameter => Some(a.max_diameter_mm),
        }
    }

    /// The accepted names, for error messages.
    pub fn names() -> String {
        Self::ALL.map(Self::name).join(", ")
    }
}

/// An accepted interval in mm; either bound may be absent (not both).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TargetRange {
    /// Smallest accepted value (mm, ≥ 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// Largest accepted value (mm, ≥ min).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
}

impl TargetRange {
    /// How far `value` lies outside the range (0 inside).
    pub fn miss(&self, value: f64) -> f64 {
        let below = self.min.map_or(0.0, |m| (m - value).max(0.0));
        let above = self.max.map_or(0.0, |m| (value - m).max(0.0));
        below + above
    }

    /// Whether `value` lies inside.
    pub fn contains(&self, value: f64) -> bool {
        self.miss(value) == 0.0
    }
}

impl std::fmt::Display for TargetRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.min, self.max) {
            (Some(lo), Some(hi)) => write!(f, "[{lo}, {hi}] mm"),
            (Some(lo), None) => write!(f, "≥ {lo} mm"),
            (None, Some(hi)) => write!(f, "≤ {hi} mm"),
            (None, None) => write!(f, "any value"),
        }
    }
}

/// A broken rule of a target list; [`Self::field`] and [`Self::rule`] name it for API errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TargetError {
    /// No measurement named.
    #[error("must name at least one measurement ({})", Measurement::names())]
    Empty,
    /// A name that is not a measurement.
    #[error(
        "{name:?} is not a measurement; expected one of {}",
        Measurement::names()
    )]
    Unknown {
        /// The name given.
        name: String,
    },
    /// Neither bound given.
    #[error("{name} needs a min, a max or both")]
    NoBound {
        /// The measurement.
        name: &'static str,
    },
    /// A bound that is not a finite number.
    #[error("{name}.{bound} must be a finite number, got {value}")]
    NonFinite {
        /// The measurement.
        name: &'static str,
        /// `min` or `max`.
        bound: &'static str,
        /// The value.
        value: f64,
    },
    /// A negative bound (every measurement is a length).
    #[error("{name}.{bound} must be ≥ 0 mm, got {value}")]
    Negative {
        /// The measurement.
        name: &'static str,
        /// `min` or `max`.
        bound: &'static str,
        /// The value.
        value: f64,
    },
    /// `min` above `max`.
    #[error("{name}: min {min} must not exceed max {max}")]
    Inverted {
        /// The measurement.
        name: &'static str,
        /// Lower bound.
        min: f64,
        /// Upper bound.
        max: f64,
    },
}

impl TargetError {
    /// The offending request field, e.g. `targets.annulus_mm.min`.
    pub fn field(&self) -> String {
        match self {
            Self::Empty => "targets".into(),
            Self::Unknown { name } => format!("targets.{name}"),
            Self::NoBound { name } | Self::Inverted { name, .. } => format!("targets.{name}"),
            Self::NonFinite { name, bound, .. } | Self::Negative { name, bound, .. } => {
                format!("targets.{name}.{bound}")
            }
        }
    }

    /// The short rule name.
    pub fn rule(&self) -> &'static str {
        match self {
            Self::Empty => "non-empty",
            Self::Unknown { .. } => "unknown-measurement",
            Self::NoBound { .. } => "bound-required",
            Self::NonFinite { .. } => "finite",
            Self::Negative { .. } => "non-negative",
            Self::Inverted { .. } => "min-le-max",
        }
    }
}

/// Parses a command-line target `NAME=MIN:MAX` (either bound may be empty, e.g.
/// `length_mm=:90`); the name and bounds are validated by [`Targets::parse`].
pub fn parse_target_arg(text: &str) -> Result<(String, TargetRange), String> {
    let (name, range) = text
        .split_once('=')
        .ok_or_else(|| format!("{text:?} is not NAME=MIN:MAX"))?;
    let (lo, hi) = range
        .split_once(':')
        .ok_or_else(|| format!("{range:?} is not MIN:MAX (either may be empty)"))?;
    let bound = |s: &str, which: &str| -> Result<Option<f64>, String> {
        match s.trim() {
            "" => Ok(None),
            t => t
                .parse::<f64>()
                .map(Some)
                .map_err(|e| format!("{name} {which} {t:?} is not a number: {e}")),
        }
    };
    let range = TargetRange {
        min: bound(lo, "min")?,
        max: bound(hi, "max")?,
    };
    Ok((name.trim().to_string(), range))
}

/// Validated targets, one range per measurement, in [`Measurement`] order.
#[derive(Debug, Clone, PartialEq)]
pub struct Targets(Vec<(Measurement, TargetRange)>);

impl Targets {
    /// Validates ranges keyed by measurement name.
    pub fn parse(ranges: &BTreeMap<String, TargetRange>) -> Result<Self, TargetError> {
        if ranges.is_empty() {
            return Err(TargetError::Empty);
        }
        let mut out = Vec::with_capacity(ranges.len());
        for (key, range) in ranges {
            let measurement = Measurement::parse(key)
                .ok_or_else(|| TargetError::Unknown { name: key.clone() })?;
            let name = measurement.name();
            if range.min.is_none() && range.max.is_none() {
                return Err(TargetError::NoBound { name });
            }
            for (bound, value) in [("min", range.min), ("max", range.max)] {
                let Some(value) = value else { continue };
                if !value.is_finite() {
                    return Err(TargetError::NonFinite { name, bound, value });
                }
                if value < 0.0 {
                    return Err(TargetError::Negative { name, bound, value });
                }
            }
            if let (Some(min), Some(max)) = (range.min, range.max)
                && min > max
            {
                return Err(TargetError::Inverted { name, min, max });
            }
            out.push((measurement, *range));
        }
        out.sort_by_key(|(m, _)| *m);
        Ok(Self(out))
    }

    /// The ranges keyed by name (what is stored and shown).
    pub fn to_map(&self) -> BTreeMap<String, TargetRange> {
        self.0
            .iter()
            .map(|(m, r)| (m.name().to_string(), *r))
            .collect()
    }

    /// The targeted measurements with their ranges.
    pub fn iter(&self) -> impl Iterator<Item = (Measurement, TargetRange)> + '_ {
        self.0.iter().copied()
    }

    /// Total distance in mm of a shape's measurements outside their ranges: 0 when every
    /// target is met, infinite when a targeted measurement is missing (or the shape could
    /// not be measured).
    pub fn miss(&self, anatomy: Option<&ShapeAnatomy>) -> f64 {
        let Some(a) = anatomy else {
            return f64::INFINITY;
        };
        self.0
            .iter()
            .map(|(m, r)| m.value(a).map_or(f64::INFINITY, |v| r.miss(v)))
            .sum()
    }
}

/// The range of each measurement over a model's training shapes (`None`: measured on none).
pub fn training_ranges(training: &[Option<ShapeAnatomy>], m: Measurement) -> Option<(f64, f64)> {
    training
        .iter()
        .flatten()
        .filter_map(|a| m.value(a))
        .fold(None, |acc, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((f64::min(lo, v), f64::max(hi, v))),
        })
}

/// A target no convex mixture of the training shapes can plausibly reach.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Infeasible {
    /// The measurement was found on no training shape.
    #[error("{name} was measured on none of the model's training shapes, so it cannot be targeted")]
    NotMeasured {
        /// The measurement.
        name: &'static str,
    },
    /// The target misses the achievable range.
    #[error(
        "{name} target {target} lies outside the achievable range [{lo:.2}, {hi:.2}] mm \
         (the training shapes span [{train_lo:.2}, {train_hi:.2}] mm, widened by 5 % of the largest)"
    )]
    OutOfRange {
        /// The measurement.
        name: &'static str,
        /// The requested range.
        target: TargetRange,
        /// Achievable lower bound.
        lo: f64,
        /// Achievable upper bound.
        hi: f64,
        /// Smallest training value.
        train_lo: f64,
        /// Largest training value.
        train_hi: f64,
    },
}

impl Infeasible {
    /// The request field it is about (`targets.<name>`).
    pub fn field(&self) -> String {
        match self {
            Self::NotMeasured { name } | Self::OutOfRange { name, .. } => {
                format!("targets.{name}")
            }
        }
    }
}

/// Checks every target against the training shapes' measurements ([`FEASIBILITY_MARGIN`]).
pub fn check_feasible(
    targets: &Targets,
    training: &[Option<ShapeAnatomy>],
) -> Result<(), Infeasible> {
    for (m, target) in targets.iter() {
        let name = m.name();
        let (train_lo, train_hi) =
            training_ranges(training, m).ok_or(Infeasible::NotMeasured { name })?;
        let margin = FEASIBILITY_MARGIN * train_hi.abs();
        let (lo, hi) = (train_lo - margin, train_hi + margin);
        let below = target.max.is_some_and(|max| max < lo);
        let above = target.min.is_some_and(|min| min > hi);
        if below || above {
            return Err(Infeasible::OutOfRange {
                name,
                target,
                lo,
                hi,
                train_lo,
                train_hi,
            });
        }
    }
    Ok(())
}

/// Training shapes that guided candidates mix: those meeting every target, or, when fewer
/// than `arity` do, the `arity` nearest to meeting them (ties by index).
pub fn guided_pool(
    targets: &Targets,
    training: &[Option<ShapeAnatomy>],
    arity: usize,
) -> Vec<usize> {
    let mut ranked: Vec<(f64, usize)> = training
        .iter()
        .enumerate()
        .map(|(i, a)| (targets.miss(a.as_ref()), i))
        .collect();
    ranked.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let inside = ranked.iter().filter(|(miss, _)| *miss == 0.0).count();
    ranked.truncate(inside.max(arity).min(training.len()));
    ranked.into_iter().map(|(_, i)| i).collect()
}

/// Whether candidate `attempt` is guided: the first is the plain draw (so a shape that meets
/// its targets at once equals the unconditioned shape), then plain and guided draws
/// alternate, keeping some of the plain draws' diversity.
pub fn is_guided(attempt: u32) -> bool {
    attempt % 2 == 1
}

/// `arity` distinct training indices from `pool`, drawn from `seed`.
pub fn guided_indices(seed: u64, pool: &[usize], arity: usize) -> Vec<usize> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7461_7267_6574);
    let mut pool = pool.to_vec();
    let k = arity.min(pool.len());
    for i in 0..k {
        let j = rng.random_range(i..pool.len());
        pool.swap(i, j);
    }
    pool.truncate(k);
    pool
}

/// A candidate meshed at the final resolution and measured.
#[derive(Debug, Clone)]
pub struct Measured<C> {
    /// What the caller keeps (mesh, mixture, …).
    pub candidate: C,
    /// Its measurements at the final resolution, or why they failed.
    pub anatomy: Result<ShapeAnatomy, String>,
    /// The caller's other constraints hold (e.g. the minimum novelty).
    pub accept: bool,
    /// Tie-breaker among candidates missing equally (larger is better, e.g. novelty).
    pub rank: f64,
}

/// The kept candidate of a search.
#[derive(Debug, Clone)]
pub struct SearchOutcome<C> {
    /// The kept candidate.
    pub kept: Measured<C>,
    /// Its attempt number.
    pub attempt: u32,
    /// Candidates drawn and measured (coarse or final), at least 1.
    pub candidates: u32,
    /// How many of them were weight refinements of the one before ([`refine_weights`]).
    pub refined: u32,
    /// Whether the kept candidate meets every target (at the final resolution).
    pub met: bool,
}

/// Weight refinements in a row from one drawn mixture before the search draws afresh.
pub const MAX_REFINEMENTS: u32 = 3;

/// What a search draws, meshes and measures: the service and the command line each
/// implement it around their engine, tests with a cheap stand-in.
pub trait CandidateSource {
    /// A candidate's mixture (what gets meshed).
    type Spec;
    /// What the caller keeps of a finished candidate.
    type Kept;
    /// Why drawing or meshing failed (ends the search).
    type Error;
    /// The drawn mixture of candidate `attempt` (deterministic in the attempt number).
    fn draw(&mut self, attempt: u32) -> Result<Self::Spec, Self::Error>;
    /// A mixture with the same parts as `spec` whose weights should bring `measured`
    /// (what `spec` gave) into the targets, or `None` when its weights may not change.
    fn refine(&mut self, spec: &Self::Spec, measured: &ShapeAnatomy) -> Option<Self::Spec>;
    /// Meshes `spec` coarsely and measures it.
    fn screen(&mut self, spec: &Self::Spec) -> Result<Result<ShapeAnatomy, String>, Self::Error>;
    /// Meshes `spec` at the final resolution and measures it.
    fn finalize(
        &mut self,
        attempt: u32,
        spec: &Self::Spec,
    ) -> Result<Measured<Self::Kept>, Self::Error>;
}

/// Searches at most `max_candidates` candidates for one that meets `targets` and the
/// caller's other constraints. With `screening`, each candidate is first measured on a
/// coarse mesh and only candidates that pass are meshed at the final resolution and
/// measured again. A candidate that misses is followed by a refinement of its weights
/// (up to [`MAX_REFINEMENTS`] in a row while the miss shrinks), otherwise by a fresh draw.
/// The first candidate that passes every check is kept; otherwise the final candidate
/// missing least (then accepted, then highest rank), or, when none passed the screen, the
/// best screened one meshed at the final resolution.
pub fn search<S: CandidateSource>(
    targets: &Targets,
    max_candidates: u32,
    screening: bool,
    source: &mut S,
) -> Result<SearchOutcome<S::Kept>, S::Error> {
    let mut best_final: Option<(u32, f64, Measured<S::Kept>)> = None;
    let mut best_screen: Option<(u32, f64, S::Spec)> = None;
    let (mut candidates, mut refined) = (0, 0);
    // The refinement to try next, its place in the chain and the miss it must beat.
    let mut next: Option<(S::Spec, u32, f64)> = None;
    for attempt in 0..max_candidates.max(1) {
        candidates += 1;
        let (spec, chain, previous_miss) = match next.take() {
            Some(n) => {
                refined += 1;
                n
            }
            None => (source.draw(attempt)?, 0, f64::INFINITY),
        };
        let (miss, anatomy) = if screening {
            let anatomy = source.screen(&spec)?.ok();
            (targets.miss(anatomy.as_ref()), anatomy)
        } else {
            (0.0, None)
        };
        let (miss, anatomy) = if miss > 0.0 {
            (miss, anatomy)
        } else {
            let measured = source.finalize(attempt, &spec)?;
            let miss = targets.miss(measured.anatomy.as_ref().ok());
            let anatomy = measured.anatomy.clone().ok();
            let done = miss == 0.0 && measured.accept;
            let better = best_final
                .as_ref()
                .is_none_or(|(_, best_miss, best)| better(miss, &measured, *best_miss, best));
            if better {
                best_final = Some((attempt, miss, measured));
            }
            if done {
                break;
            }
            (miss, anatomy)
        };
        if chain < MAX_REFINEMENTS && miss > 0.0 && miss.is_finite() && miss < previous_miss {
            next = anatomy
                .and_then(|a| source.refine(&spec, &a))
                .map(|s| (s, chain + 1, miss));
        }
        if miss > 0.0 && best_screen.as_ref().is_none_or(|(_, best, _)| miss < *best) {
            best_screen = Some((attempt, miss, spec));
        }
    }
    let (attempt, miss, kept) = match best_final {
        Some(best) => best,
        None => {
            let (attempt, _, spec) = best_screen.expect("at least one candidate was screened");
            let measured = source.finalize(attempt, &spec)?;
            (
                attempt,
                targets.miss(measured.anatomy.as_ref().ok()),
                measured,
            )
        }
    };
    Ok(SearchOutcome {
        kept,
        attempt,
        candidates,
        refined,
        met: miss == 0.0,
    })
}

fn better<C>(miss: f64, m: &Measured<C>, best_miss: f64, best: &Measured<C>) -> bool {
    if miss != best_miss {
        return miss < best_miss;
    }
    if m.accept != best.accept {
        return m.accept;
    }
    m.rank > best.rank
}

/// Convex weights for a mixture whose first `indices.len()` weights belong to those training
/// shapes (any further weights, e.g. anchors', stay fixed) that should bring its
/// measurements into `targets`, given that the mixture measured `measured`.
///
/// Each measurement is predicted as the weighted mean of the parts' training measurements
/// plus the residual the current weights left (which carries the fixed parts, the latent
/// noise and the decoder's departure from linearity). The weights then descend on the
/// squared distance of the prediction outside the targets, inset by a quarter of each
/// two-sided range (a tenth of the parts' spread for a one-sided bound) so that the
/// remaining non-linearity still lands inside, projected onto the simplex of the same total
/// weight. Starting from the current weights, they stop as soon as the prediction is inside,
/// so a refined mixture stays as close as it can to its draw. `None` when a part or a target
/// is unmeasured, fewer than two weights can move, they would not move, or even the
/// prediction of the best weights misses the targets.
pub fn refine_weights(
    targets: &Targets,
    training: &[Option<ShapeAnatomy>],
    indices: &[usize],
    weights: &[f64],
    measured: &ShapeAnatomy,
) -> Option<Vec<f64>> {
    let k = indices.len();
    if k < 2 || weights.len() < k {
        return None;
    }
    let start = &weights[..k];
    let mass: f64 = start.iter().sum();
    if !mass.is_finite() || mass <= 1e-9 {
        return None;
    }
    /// One target's linear prediction `p(w) = slope · w + offset` and its aim `[lo, hi]`.
    struct Row {
        slope: Vec<f64>,
        offset: f64,
        lo: f64,
        hi: f64,
    }
    let mut rows = Vec::new();
    for (m, range) in targets.iter() {
        let values = indices
            .iter()
            .map(|&i| training.get(i)?.as_ref().and_then(|a| m.value(a)))
            .collect::<Option<Vec<f64>>>()?;
        let actual = m.value(measured)?;
        let predicted: f64 = values.iter().zip(start).map(|(v, w)| v * w).sum();
        let mean = values.iter().sum::<f64>() / k as f64;
        let (lo, hi) = values
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        let inset = match (range.min, range.max) {
            (Some(a), Some(b)) => 0.25 * (b - a),
            _ => 0.1 * (hi - lo),
        };
        rows.push(Row {
            // Centred: the weights' sum is fixed, so the mean only shifts the offset and the
            // descent is better conditioned.
            slope: values.iter().map(|v| v - mean).collect(),
            offset: mass * mean + (actual - predicted),
            lo: range.min.map_or(f64::NEG_INFINITY, |a| a + inset),
            hi: range.max.map_or(f64::INFINITY, |b| b - inset),
        });
    }
    let lipschitz: f64 = rows
        .iter()
        .map(|r| r.slope.iter().map(|s| s * s).sum::<f64>())
        .sum();
    if lipschitz <= 1e-12 {
        return None;
    }
    let mut w = start.to_vec();
    for _ in 0..2000 {
        let mut gradient = vec![0.0; k];
        for r in &rows {
            let p: f64 = r.slope.iter().zip(&w).map(|(s, w)| s * w).sum::<f64>() + r.offset;
            let excess = if p > r.hi {
                p - r.hi
            } else if p < r.lo {
                p - r.lo
            } else {
                0.0
            };
            for (g, s) in gradient.iter_mut().zip(&r.slope) {
                *g += excess * s;
            }
        }
        if gradient.iter().all(|g| g.abs() < 1e-12) {
            break;
        }
        let stepped: Vec<f64> = w
            .iter()
            .zip(&gradient)
            .map(|(w, g)| w - g / lipschitz)
            .collect();
        w = project_to_simplex(&stepped, mass);
    }
    let moved = w.iter().zip(start).any(|(a, b)| (a - b).abs() > 1e-4);
    // A mixture whose parts cannot reach the targets even by the prediction is better
    // replaced by a fresh draw than refined.
    let reaches = targets.iter().zip(&rows).all(|((_, range), r)| {
        let p: f64 = r.slope.iter().zip(&w).map(|(s, w)| s * w).sum::<f64>() + r.offset;
        range.miss(p) < 1e-9
    });
    (moved && reaches).then(|| [w.as_slice(), &weights[k..]].concat())
}

/// The nearest point to `v` with non-negative entries summing to `mass` (Euclidean).
fn project_to_simplex(v: &[f64], mass: f64) -> Vec<f64> {
    let mut sorted = v.to_vec();
    sorted.sort_by(|a, b| b.total_cmp(a));
    let (mut sum, mut shift) = (0.0, 0.0);
    for (j, u) in sorted.iter().enumerate() {
        sum += u;
        let candidate = (sum - mass) / (j + 1) as f64;
        if u - candidate > 0.0 {
            shift = candidate;
        }
    }
    v.iter().map(|x| (x - shift).max(0.0)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn anatomy(annulus: Option<f64>, length: f64) -> ShapeAnatomy {
        ShapeAnatomy {
            method: if annulus.is_some() { "root" } else { "vessel" }.into(),
            annulus_mm: annulus,
            sinus_mm: annulus.map(|a| a * 1.3),
            stj_mm: annulus.map(|a| a * 1.1),
            sinus_height_mm: annulus.map(|a| a * 0.8),
            ascending_mm: annulus.map(|a| a * 1.2),
            length_mm: length,
            max_diameter_mm: annulus.map_or(20.0, |a| a * 1.3),
            root_error: None,
        }
    }

    /// A measurement name with its bounds.
    type Bounds<'a> = (&'a str, Option<f64>, Option<f64>);

    fn targets(pairs: &[Bounds]) -> Result<Targets, TargetError> {
        let map = pairs
            .iter()
            .map(|&(n, min, max)| (n.to_string(), TargetRange { min, max }))
            .collect();
        Targets::parse(&map)
    }

    #[test]
    fn bad_targets_name_the_field_and_rule() {
        let cases: [(&[Bounds], &str, &str); 6] = [
            (&[], "targets", "non-empty"),
            (
                &[("aorta_mm", Some(1.0), None)],
                "targets.aorta_mm",
                "unknown-measurement",
            ),
            (
                &[("annulus_mm", None, None)],
                "targets.annulus_mm",
                "bound-required",
            ),
            (
                &[("stj_mm", Some(-1.0), Some(3.0))],
                "targets.stj_mm.min",
                "non-negative",
            ),
            (
                &[("sinus_mm", Some(1.0), Some(f64::NAN))],
                "targets.sinus_mm.max",
                "finite",
            ),
            (
                &[("length_mm", Some(30.0), Some(20.0))],
                "targets.length_mm",
                "min-le-max",
            ),
        ];
        for (pairs, field, rule) in cases {
            let err = targets(pairs).unwrap_err();
            assert_eq!((err.field().as_str(), err.rule()), (field, rule), "{err}");
        }
        let ok = targets(&[
            ("length_mm", Some(20.0), None),
            ("annulus_mm", Some(23.0), Some(27.0)),
        ])
        .unwrap();
        let names: Vec<_> = ok.iter().map(|(m, _)| m.name()).collect();
        assert_eq!(names, ["annulus_mm", "length_mm"]);
        assert_eq!(Targets::parse(&ok.to_map()).unwrap(), ok);
    }

    #[test]
    fn command_line_targets_parse_with_open_bounds() {
        let r = |min, max| TargetRange { min, max };
        assert_eq!(
            parse_target_arg("annulus_mm=23:27"),
            Ok(("annulus_mm".into(), r(Some(23.0), Some(27.0))))
        );
        assert_eq!(
            parse_target_arg("length_mm=:90.5"),
            Ok(("length_mm".into(), r(None, Some(90.5))))
        );
        assert_eq!(
            parse_target_arg("stj_mm=20:"),
            Ok(("stj_mm".into(), r(Some(20.0), None)))
        );
        for bad in ["annulus_mm", "annulus_mm=23", "annulus_mm=a:27"] {
            assert!(parse_target_arg(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_miss_is_the_distance_outside_and_infinite_when_unmeasured() {
        let t = targets(&[
            ("annulus_mm", Some(23.0), Some(27.0)),
            ("length_mm", None, Some(80.0)),
        ])
        .unwrap();
        assert_eq!(t.miss(Some(&anatomy(Some(25.0), 70.0))), 0.0);
        assert_eq!(t.miss(Some(&anatomy(Some(21.5), 82.0))), 3.5);
        assert_eq!(t.miss(Some(&anatomy(None, 70.0))), f64::INFINITY);
        assert_eq!(t.miss(None), f64::INFINITY);
    }

    #[test]
    fn feasibility_uses_the_training_range_widened_by_the_margin() {
        let training = vec![
            Some(anatomy(Some(20.0), 60.0)),
            None,
            Some(anatomy(Some(30.0), 70.0)),
            Some(anatomy(None, 90.0)),
        ];
        assert_eq!(
            training_ranges(&training, Measurement::Annulus),
            Some((20.0, 30.0))
        );
        // Margin: 5 % of 30 = 1.5 mm → achievable [18.5, 31.5].
        for (min, max, ok) in [
            (Some(23.0), Some(27.0), true),
            (Some(31.0), Some(40.0), true),
            (Some(32.0), None, false),
            (None, Some(18.0), false),
            (Some(10.0), Some(19.0), true),
        ] {
            let t = targets(&[("annulus_mm", min, max)]).unwrap();
            let result = check_feasible(&t, &training);
            assert_eq!(result.is_ok(), ok, "{min:?}..{max:?}: {result:?}");
            if let Err(e) = result {
                assert_eq!(e.field(), "targets.annulus_mm");
                assert!(e.to_string().contains("[18.50, 31.50]"), "{e}");
            }
        }
        let vessels = vec![Some(anatomy(None, 60.0)), Some(anatomy(None, 70.0))];
        let t = targets(&[("annulus_mm", Some(23.0), Some(27.0))]).unwrap();
        assert!(matches!(
            check_feasible(&t, &vessels),
            Err(Infeasible::NotMeasured { name: "annulus_mm" })
        ));
    }

    #[test]
    fn the_guided_pool_holds_the_shapes_inside_or_the_nearest() {
        let training: Vec<_> = [18.0, 24.0, 26.0, 31.0, 25.0, 40.0]
            .into_iter()
            .map(|a| Some(anatomy(Some(a), 60.0)))
            .collect();
        let t = targets(&[("annulus_mm", Some(23.0), Some(27.0))]).unwrap();
        let mut pool = guided_pool(&t, &training, 2);
        pool.sort_unstable();
        assert_eq!(pool, [1, 2, 4]);
        // Four needed: the three inside and the nearest outside (31 misses by 4, 18 by 5).
        let mut pool = guided_pool(&t, &training, 4);
        pool.sort_unstable();
        assert_eq!(pool, [1, 2, 3, 4]);
        let picked = guided_indices(9, &pool, 3);
        assert_eq!(picked, guided_indices(9, &pool, 3));
        let mut distinct = picked.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), 3);
        assert!(picked.iter().all(|i| pool.contains(i)));
    }

    /// A stand-in for draw + mesh + measure: candidate `a` has annulus `values[a]`; the
    /// coarse measurement reads 0.5 mm low. Specs are attempt numbers and never refined.
    struct Table<'a> {
        values: &'a [f64],
        accept: bool,
        ranks: &'a [f64],
        screened: Vec<u32>,
        finals: Vec<u32>,
    }

    impl<'a> Table<'a> {
        fn new(values: &'a [f64]) -> Self {
            Self {
                values,
                accept: true,
                ranks: &[],
                screened: Vec::new(),
                finals: Vec::new(),
            }
        }
    }

    impl CandidateSource for Table<'_> {
        type Spec = u32;
        type Kept = u32;
        type Error = ();
        fn draw(&mut self, attempt: u32) -> Result<u32, ()> {
            Ok(attempt)
        }
        fn refine(&mut self, _: &u32, _: &ShapeAnatomy) -> Option<u32> {
            None
        }
        fn screen(&mut self, &a: &u32) -> Result<Result<ShapeAnatomy, String>, ()> {
            self.screened.push(a);
            Ok(Ok(anatomy(Some(self.values[a as usize] - 0.5), 60.0)))
        }
        fn finalize(&mut self, attempt: u32, &a: &u32) -> Result<Measured<u32>, ()> {
            assert_eq!(attempt, a);
            self.finals.push(a);
            Ok(Measured {
                candidate: a,
                anatomy: Ok(anatomy(self.values.get(a as usize).copied(), 60.0)),
                accept: self.accept,
                rank: self.ranks.get(a as usize).copied().unwrap_or(0.0),
            })
        }
    }

    fn run(
        values: &[f64],
        max: u32,
        screening: bool,
        target: (f64, f64),
    ) -> (SearchOutcome<u32>, Vec<u32>, Vec<u32>) {
        let t = targets(&[("annulus_mm", Some(target.0), Some(target.1))]).unwrap();
        let mut table = Table::new(values);
        let outcome = search(&t, max, screening, &mut table).unwrap();
        (outcome, table.screened, table.finals)
    }

    #[test]
    fn the_search_stops_at_the_first_candidate_that_passes_both_checks() {
        let values = [30.0, 21.0, 25.0, 24.0, 26.0];
        let (o, screened, finals) = run(&values, 5, true, (23.0, 27.0));
        assert_eq!(
            (o.attempt, o.candidates, o.met, o.kept.candidate),
            (2, 3, true, 2)
        );
        assert_eq!((screened, finals), (vec![0, 1, 2], vec![2]));
        // Without screening every candidate is meshed at the final resolution.
        let (o, screened, finals) = run(&values, 5, false, (23.0, 27.0));
        assert_eq!((o.attempt, o.candidates, o.met), (2, 3, true));
        assert_eq!((screened.len(), finals), (0, vec![0, 1, 2]));
    }

    #[test]
    fn a_coarse_pass_that_fails_the_final_check_keeps_searching() {
        // Candidate 0 reads 27.0 coarse (inside) but 27.5 final (outside).
        let values = [27.5, 30.0, 24.0];
        let (o, _, finals) = run(&values, 5, true, (23.0, 27.0));
        assert_eq!(finals, [0, 2]);
        assert_eq!((o.attempt, o.candidates, o.met), (2, 3, true));
    }

    #[test]
    fn an_unmet_search_is_bounded_and_keeps_the_closest_candidate() {
        let values = [30.0, 28.0, 35.0, 29.0];
        let (o, screened, finals) = run(&values, 4, true, (23.0, 27.0));
        assert_eq!(screened, [0, 1, 2, 3]);
        // None passed the screen: the closest screened one is meshed once at the end.
        assert_eq!(finals, [1]);
        assert_eq!((o.attempt, o.candidates, o.met), (1, 4, false));
        let (o, _, finals) = run(&values, 4, false, (23.0, 27.0));
        assert_eq!(
            (finals.len(), o.attempt, o.candidates, o.met),
            (4, 1, 4, false)
        );
    }

    #[test]
    fn other_constraints_and_rank_break_ties() {
        let t = targets(&[("length_mm", Some(50.0), None)]).unwrap();
        let mut table = Table {
            accept: false,
            ranks: &[1.0, 3.0, 2.0, 0.0],
            ..Table::new(&[])
        };
        let o = search(&t, 4, false, &mut table).unwrap();
        // Every candidate meets the target but none is accepted: all four are tried and
        // the highest rank is kept; the targets themselves are met.
        assert_eq!(
            (o.candidates, o.attempt, o.met, o.kept.accept),
            (4, 1, true, false)
        );
        assert!(table.screened.is_empty());
    }

    /// Training shapes 0 and 1 with annuli 20 and 30 mm (length 60 and 80 mm).
    fn two_roots() -> Vec<Option<ShapeAnatomy>> {
        vec![
            Some(anatomy(Some(20.0), 60.0)),
            Some(anatomy(Some(30.0), 80.0)),
        ]
    }

    fn annulus_of(weights: &[f64]) -> f64 {
        20.0 * weights[0] + 30.0 * weights[1]
    }

    #[test]
    fn refined_weights_bring_a_linear_measurement_just_inside_the_inset_range() {
        let t = targets(&[("annulus_mm", Some(28.0), Some(30.0))]).unwrap();
        let training = two_roots();
        // Measured exactly as the linear prediction: the aim is [28.5, 29.5], reached at
        // its near end, so w₁ = 0.85.
        let w = refine_weights(
            &t,
            &training,
            &[0, 1],
            &[0.5, 0.5],
            &anatomy(Some(25.0), 70.0),
        )
        .unwrap();
        assert!((w[0] + w[1] - 1.0).abs() < 1e-12 && w.iter().all(|&x| x >= 0.0));
        assert!((annulus_of(&w) - 28.5).abs() < 1e-3, "{w:?}");
        // The shape measured 1 mm above the prediction: the residual is carried over.
        let w = refine_weights(
            &t,
            &training,
            &[0, 1],
            &[0.5, 0.5],
            &anatomy(Some(26.0), 70.0),
        )
        .unwrap();
        assert!((annulus_of(&w) + 1.0 - 28.5).abs() < 1e-3, "{w:?}");
    }

    #[test]
    fn refinement_keeps_fixed_weights_and_meets_several_targets() {
        let t = targets(&[
            ("annulus_mm", Some(22.0), Some(24.0)),
            ("length_mm", None, Some(70.0)),
        ])
        .unwrap();
        let training = vec![
            Some(anatomy(Some(20.0), 60.0)),
            Some(anatomy(Some(30.0), 80.0)),
            Some(anatomy(Some(24.0), 90.0)),
        ];
        // The last weight (an anchor's) stays; the three training parts share 0.7.
        let start = [0.1, 0.3, 0.3, 0.3];
        let measured = anatomy(Some(26.0), 80.0);
        let w = refine_weights(&t, &training, &[0, 1, 2], &start, &measured).unwrap();
        assert_eq!(w.len(), 4);
        assert_eq!(w[3], 0.3);
        assert!((w[..3].iter().sum::<f64>() - 0.7).abs() < 1e-12);
        let linear = |w: &[f64], f: fn(&ShapeAnatomy) -> f64| -> f64 {
            let parts: f64 = (0..3)
                .map(|i| w[i] * f(training[i].as_ref().unwrap()))
                .sum();
            let start_parts: f64 = (0..3)
                .map(|i| start[i] * f(training[i].as_ref().unwrap()))
                .sum();
            parts + f(&measured) - start_parts
        };
        let annulus = linear(&w, |a| a.annulus_mm.unwrap());
        let length = linear(&w, |a| a.length_mm);
        assert!(
            (22.0..=24.0).contains(&annulus),
            "annulus {annulus} from {w:?}"
        );
        assert!(length <= 70.0 + 1e-6, "length {length} from {w:?}");
    }

    #[test]
    fn refinement_declines_what_it_cannot_improve() {
        let t = targets(&[("annulus_mm", Some(24.0), Some(26.0))]).unwrap();
        let training = two_roots();
        let inside = anatomy(Some(25.0), 70.0);
        // Already inside the aim: the weights would not move.
        assert_eq!(
            refine_weights(&t, &training, &[0, 1], &[0.5, 0.5], &inside),
            None
        );
        let outside = anatomy(Some(21.0), 70.0);
        // A part without a measurement, a single movable weight, or an unmeasured target.
        let unmeasured = vec![training[0].clone(), None];
        assert_eq!(
            refine_weights(&t, &unmeasured, &[0, 1], &[0.5, 0.5], &outside),
            None
        );
        assert_eq!(
            refine_weights(&t, &training, &[0], &[0.5, 0.5], &outside),
            None
        );
        let vessel = anatomy(None, 70.0);
        assert_eq!(
            refine_weights(&t, &training, &[0, 1], &[0.5, 0.5], &vessel),
            None
        );
        // Both parts' annuli (20 and 30 mm) lie above 19 mm and the mixture measured as
        // predicted (25 mm): no weights can reach it.
        let below = targets(&[("annulus_mm", None, Some(19.0))]).unwrap();
        assert_eq!(
            refine_weights(&below, &training, &[0, 1], &[0.5, 0.5], &inside),
            None
        );
        // Measured 5 mm below the prediction, the same mixture can: all weight on part 0.
        let low = anatomy(Some(20.0), 70.0);
        let w = refine_weights(&below, &training, &[0, 1], &[0.5, 0.5], &low).unwrap();
        assert!(annulus_of(&w) - 5.0 <= 19.0 && w[0] > 0.5, "{w:?}");
    }

    #[test]
    fn projection_onto_the_simplex_is_the_nearest_point() {
        let p = project_to_simplex(&[0.5, 0.7, -0.2], 1.0);
        let expected = [0.4, 0.6, 0.0];
        assert!(
            p.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-12),
            "{p:?}"
        );
        // Brute force over a fine grid of the simplex.
        let v = [0.9, -0.4, 0.3];
        let p = project_to_simplex(&v, 0.6);
        let dist = |q: &[f64]| q.iter().zip(&v).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        let n = 600;
        let best = (0..=n)
            .flat_map(|i| (0..=n - i).map(move |j| (i, j)))
            .map(|(i, j)| {
                let (a, b) = (0.6 * i as f64 / n as f64, 0.6 * j as f64 / n as f64);
                dist(&[a, b, 0.6 - a - b])
            })
            .fold(f64::INFINITY, f64::min);
        assert!((p.iter().sum::<f64>() - 0.6).abs() < 1e-12 && p.iter().all(|&x| x >= 0.0));
        assert!(dist(&p) <= best + 1e-9, "{p:?}");
    }

    /// Two training roots mixed by weight; the decoder bends the annulus by up to 1.5 mm
    /// (largest at equal weights), so one linear step does not land exactly.
    struct Bent {
        training: Vec<Option<ShapeAnatomy>>,
        targets: Targets,
        draws: Vec<u32>,
    }

    impl CandidateSource for Bent {
        type Spec = Vec<f64>;
        type Kept = Vec<f64>;
        type Error = ();
        fn draw(&mut self, attempt: u32) -> Result<Vec<f64>, ()> {
            self.draws.push(attempt);
            Ok(vec![0.9, 0.1])
        }
        fn refine(&mut self, w: &Vec<f64>, measured: &ShapeAnatomy) -> Option<Vec<f64>> {
            refine_weights(&self.targets, &self.training, &[0, 1], w, measured)
        }
        fn screen(&mut self, w: &Vec<f64>) -> Result<Result<ShapeAnatomy, String>, ()> {
            Ok(Ok(anatomy(Some(bent(w)), 70.0)))
        }
        fn finalize(&mut self, _: u32, w: &Vec<f64>) -> Result<Measured<Vec<f64>>, ()> {
            Ok(Measured {
                candidate: w.clone(),
                anatomy: Ok(anatomy(Some(bent(w)), 70.0)),
                accept: true,
                rank: 0.0,
            })
        }
    }

    fn bent(w: &[f64]) -> f64 {
        annulus_of(w) + 6.0 * w[0] * w[1]
    }

    #[test]
    fn the_search_refines_the_weights_of_a_missing_draw_until_it_meets_the_target() {
        let t = targets(&[("annulus_mm", Some(26.0), Some(27.0))]).unwrap();
        let mut source = Bent {
            training: two_roots(),
            targets: t.clone(),
            draws: Vec::new(),
        };
        let o = search(&t, 10, true, &mut source).unwrap();
        assert!(o.met, "{:?}", o.kept.candidate);
        assert!((26.0..=27.0).contains(&bent(&o.kept.candidate)));
        // Every drawn mixture is [0.9, 0.1] (21.4 mm): only refinement can meet the target.
        assert!(o.refined >= 1 && o.candidates <= 1 + MAX_REFINEMENTS);
        assert_eq!(source.draws, [0]);
        assert_eq!(o.candidates, o.attempt + 1);
    }
}
