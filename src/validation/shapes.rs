//! The shape level of a validation (DESIGN §8): Chamfer distances between whole surfaces on
//! one common scale, and from them MMD, COV and 1-NNA of the cohort against the reference,
//! the pairwise diversity of both, the distance of each shape to its closest training
//! shape (DCR) beside the same figure for real shapes the model has not seen, and the same
//! protocol applied to the training shapes themselves (the real-vs-real baseline).
//!
//! Common scale: every surface is taken in mm, centred at its bounding-box centre (position
//! is not anatomy) and divided by one length `scale_mm` for all shapes (by default the
//! model's mean training radius, about 105 mm for SynthAorta), so sizes differ as they do
//! in the population — never each shape's own unit ball. Distances are then squared
//! lengths in units of `scale_mm`, comparable to the service's unit-ball figures.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use rand::SeedableRng;
use rand::seq::index::sample;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::population::Population;
use crate::geometry::TriMesh;
use crate::geometry::chamfer::{ChamferIndex, chamfer_between_serial};
use crate::geometry::normalize::normalize_to_unit_ball;
use crate::geometry::sampling::sample_surface;
use crate::shape_metrics::coverage::mmd_cov;
use crate::shape_metrics::dcr::{Dcr, dcr};
use crate::shape_metrics::nna::{NnaConfig, NnaEstimate, one_nna_subsampled};
use crate::shape_metrics::{DistanceMatrix, ShapeMetricsError};
use crate::stats::descriptive::Summary;

/// Surface samples per shape by default (the figure the SynthAorta study used).
pub const DEFAULT_POINTS: usize = 10_000;
/// A generated shape closer than this many sampling floors to a training shape is a
/// near-copy of it — unless a real new patient is as close (see [`near_copy_threshold`]).
pub const NEAR_COPY_FLOORS: f64 = 2.0;

/// How the shape level is computed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ShapeSettings {
    /// Surface samples per shape.
    pub points: usize,
    /// The common length every surface is divided by (mm).
    pub scale_mm: f64,
    /// Seed of the surface samplings and the subsets.
    pub seed: u64,
    /// Equal-size subsets for 1-NNA, MMD and COV when the sets differ in size.
    pub subsets: usize,
}

/// Mean and 2.5–97.5 % range of a figure over equal-size subsets.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Interval {
    /// Mean over subsets.
    pub mean: f64,
    /// 2.5 % quantile.
    pub low: f64,
    /// 97.5 % quantile.
    pub high: f64,
}

/// MMD and COV of a set against the reference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct CoverageEstimate {
    /// MMD of the whole set (mean over references of the closest shape's distance).
    pub mmd: f64,
    /// COV of the whole set (share of references that are some shape's nearest).
    pub cov: f64,
    /// Shapes per subset (the reference's size, or the set's if smaller).
    pub subset_size: usize,
    /// Subsets evaluated (1 when the set is not larger than the reference).
    pub subsets: usize,
    /// MMD over equal-size subsets.
    pub mmd_subsets: Interval,
    /// COV over equal-size subsets: comparable between sets of different sizes.
    pub cov_subsets: Interval,
}

/// Pairwise distances within the cohort and within the reference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct PairwiseComparison {
    /// Over every pair of cohort shapes.
    pub cohort: Summary,
    /// Over every pair of reference shapes.
    pub reference: Summary,
    /// cohort median / reference median (1: as diverse as the population).
    pub median_ratio: f64,
    /// Every cohort pair's distance (for plots).
    pub cohort_values: Vec<f64>,
    /// Every reference pair's distance.
    pub reference_values: Vec<f64>,
}

/// Distance to the closest training shape, beside real shapes the model has not seen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct DcrComparison {
    /// Which real shapes stand for new patients.
    pub newcomers: String,
    /// The distances and their summaries.
    pub dcr: Dcr,
    /// Generated shapes closer to a training shape than [`near_copy_threshold`].
    pub near_copies: usize,
    /// The DCR below which a generated shape counts as a near-copy.
    pub near_copy_threshold: f64,
    /// True when the cohort sits closer to the training patients than new patients do
    /// (DCR median ratio below 1) or holds near-copies.
    pub flagged: bool,
}

/// The training shapes put through the same protocol as a cohort.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Baseline {
    /// What was compared.
    pub label: String,
    /// 1-NNA of the training shapes against the reference.
    pub nna: NnaEstimate,
    /// Their MMD and COV.
    pub coverage: CoverageEstimate,
    /// Their pairwise median over the reference's.
    pub pairwise_median_ratio: f64,
}

/// The shape level of a validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ShapeLevel {
    /// The unit of every distance here.
    pub units: String,
    /// The settings used.
    pub settings: ShapeSettings,
    /// Median over reference shapes of the distance between two samplings of the same
    /// surface: nothing below it is measurable.
    pub sampling_floor: f64,
    /// 1-NNA of the cohort against the reference (0.5 ideal).
    pub nna: Option<NnaEstimate>,
    /// MMD and COV.
    pub coverage: Option<CoverageEstimate>,
    /// Pairwise diversity.
    pub pairwise: Option<PairwiseComparison>,
    /// The privacy check.
    pub dcr: Option<DcrComparison>,
    /// The real-vs-real baseline.
    pub baseline: Option<Baseline>,
    /// Why a figure is missing, by name.
    pub not_computed: BTreeMap<String, String>,
}

/// Which real shapes stand for new patients in the DCR comparison.
pub enum Newcomers<'a> {
    /// The reference itself (real patients outside the training set).
    Reference,
    /// Another population (the held-out shapes when the reference is the training set).
    Other(&'a Population),
    /// None, with the reason.
    Missing(String),
}

/// The populations of a shape-level comparison.
pub struct ShapeInputs<'a> {
    /// The generated cohort.
    pub cohort: &'a Population,
    /// The reference.
    pub reference: &'a Population,
    /// The model's training shapes (DCR and the baseline), if available.
    pub training: Option<&'a Population>,
    /// Whether the reference is the training set (no baseline then).
    pub reference_is_training: bool,
    /// New patients for DCR.
    pub newcomers: Newcomers<'a>,
}

impl ShapeInputs<'_> {
    /// Chamfer distances the comparison computes (for progress).
    pub fn pairs(&self) -> u64 {
        let n = match &self.newcomers {
            Newcomers::Other(p) => p.len(),
            _ => 0,
        };
        chamfer_pairs(
            self.cohort.len(),
            self.reference.len(),
            self.training.map_or(0, Population::len),
            n,
            self.reference_is_training,
        )
    }
}

/// Chamfer distances of a shape-level comparison of `cohort` shapes with `reference` shapes,
/// beside `training` shapes and `newcomers` (the held-out shapes when the reference is the
/// training set): within each set, across them, and the real-vs-real baseline.
pub fn chamfer_pairs(
    cohort: usize,
    reference: usize,
    training: usize,
    newcomers: usize,
    reference_is_training: bool,
) -> u64 {
    let (s, r, t, n) = (
        cohort as u64,
        reference as u64,
        training as u64,
        newcomers as u64,
    );
    let within = |k: u64| k * k.saturating_sub(1) / 2;
    let baseline = if reference_is_training { 0 } else { within(t) };
    within(s) + s * r + within(r) + r + s * t + r * t + n * t + baseline
}

/// The running count of Chamfer distances and the request to give up on them.
#[derive(Debug, Clone, Copy)]
pub struct Progress<'a> {
    /// Chamfer distances done.
    pub done: &'a AtomicU64,
    /// Raised when the result is no longer wanted (a cancelled job, a lost lease): the
    /// remaining distances are skipped and the shape level is not computed.
    pub stop: Option<&'a AtomicBool>,
}

impl<'a> Progress<'a> {
    /// Counting into `done`, never stopped.
    pub fn counting(done: &'a AtomicU64) -> Self {
        Self { done, stop: None }
    }

    /// Whether the stop flag is up.
    pub fn stopped(&self) -> bool {
        self.stop.is_some_and(|s| s.load(Ordering::Relaxed))
    }

    fn step(&self) {
        self.done.fetch_add(1, Ordering::Relaxed);
    }
}

/// Runs the shape level; `progress` counts the Chamfer distances done, and a raised stop
/// flag ends it early without a result.
pub fn compare_shapes(
    inputs: &ShapeInputs<'_>,
    settings: &ShapeSettings,
    progress: Progress<'_>,
) -> Result<ShapeLevel, String> {
    for (what, p) in [("cohort", inputs.cohort), ("reference", inputs.reference)] {
        if !p.has_surfaces() {
            return Err(format!("the {what} has no surfaces (a measurements table)"));
        }
    }
    if inputs.cohort.len() < 2 || inputs.reference.len() < 2 {
        return Err("the shape level needs at least 2 shapes on each side".into());
    }
    let s = sample_population(inputs.cohort, settings, 1)?;
    let r = sample_population(inputs.reference, settings, 2)?;
    let mut level = ShapeLevel {
        units: format!(
            "squared distances on a common scale: mm / {:.2} (surfaces centred at their \
             bounding-box centres), {} points per surface",
            settings.scale_mm, settings.points
        ),
        settings: *settings,
        sampling_floor: sampling_floor(inputs.reference, settings, progress),
        nna: None,
        coverage: None,
        pairwise: None,
        dcr: None,
        baseline: None,
        not_computed: BTreeMap::new(),
    };
    let ss = within(&s, progress);
    let sr = cross(&s, &r, progress);
    let rr = within(&r, progress);
    let mut note = |name: &str, e: String| level.not_computed.insert(name.into(), e);
    let nna = nna(&sr, &ss, &rr, settings).map_err(|e| e.to_string());
    let coverage = coverage(&sr, settings).map_err(|e| e.to_string());
    let pairwise = pairwise(&ss, &rr);
    let (nna, coverage, pairwise) = (
        nna.map_err(|e| note("nna", e)).ok(),
        coverage.map_err(|e| note("coverage", e)).ok(),
        pairwise.map_err(|e| note("pairwise", e)).ok(),
    );
    let training_parts = match inputs.training {
        None => Err("the model's training shapes are not available".to_owned()),
        Some(t) if !t.has_surfaces() => Err("the training shapes have no surfaces".to_owned()),
        Some(t) => training_comparisons(inputs, t, &s, &r, &rr, settings, progress),
    };
    match training_parts {
        Ok((dcr, baseline)) => {
            let dcr = dcr.map(|d| with_flag(d, level.sampling_floor));
            let dcr = dcr.map_err(|e| note("dcr", e)).ok();
            let baseline = baseline.map_err(|e| note("baseline", e)).ok();
            (level.dcr, level.baseline) = (dcr, baseline);
        }
        Err(e) => {
            note("dcr", e.clone());
            note("baseline", e);
        }
    }
    if progress.stopped() {
        return Err("stopped before every Chamfer distance was computed".into());
    }
    (level.nna, level.coverage, level.pairwise) = (nna, coverage, pairwise);
    Ok(level)
}

/// DCR (cohort and newcomers to training) and the baseline (training against the
/// reference), each or why not.
#[allow(clippy::type_complexity)]
fn training_comparisons(
    inputs: &ShapeInputs<'_>,
    training: &Population,
    s: &[ChamferIndex],
    r: &[ChamferIndex],
    rr: &DistanceMatrix,
    settings: &ShapeSettings,
    progress: Progress<'_>,
) -> Result<(Result<(Dcr, String), String>, Result<Baseline, String>), String> {
    let t = sample_population(training, settings, 3)?;
    let st = cross(s, &t, progress);
    let rt = cross(r, &t, progress);
    let dcr = match &inputs.newcomers {
        Newcomers::Reference => dcr(&st, &rt)
            .map(|d| (d, inputs.reference.label.clone()))
            .map_err(|e| e.to_string()),
        Newcomers::Other(p) => {
            let nt = cross(&sample_population(p, settings, 4)?, &t, progress);
            dcr(&st, &nt)
                .map(|d| (d, p.label.clone()))
                .map_err(|e| e.to_string())
        }
        Newcomers::Missing(why) => Err(why.clone()),
    };
    let baseline = if inputs.reference_is_training {
        Err("the reference is the training set itself".to_owned())
    } else {
        let tt = within(&t, progress);
        baseline(&training.label, &rt.transposed(), &tt, rr, settings).map_err(|e| e.to_string())
    };
    Ok((dcr, baseline))
}

fn with_flag((dcr, newcomers): (Dcr, String), floor: f64) -> DcrComparison {
    let threshold = near_copy_threshold(floor, &dcr.heldout);
    let near_copies = dcr.generated.iter().filter(|d| **d < threshold).count();
    DcrComparison {
        newcomers,
        flagged: dcr.median_ratio.is_some_and(|r| r < 1.0) || near_copies > 0,
        near_copies,
        near_copy_threshold: threshold,
        dcr,
    }
}

/// [`NEAR_COPY_FLOORS`] sampling floors, lowered to the smallest newcomer's DCR: with few
/// surface samples the floor dominates every distance, and a shape no closer to the
/// training set than some real new patient is not a copy of a training patient.
pub fn near_copy_threshold(floor: f64, newcomer_dcr: &[f64]) -> f64 {
    newcomer_dcr
        .iter()
        .copied()
        .fold(NEAR_COPY_FLOORS * floor, f64::min)
}

fn baseline(
    label: &str,
    tr: &DistanceMatrix,
    tt: &DistanceMatrix,
    rr: &DistanceMatrix,
    settings: &ShapeSettings,
) -> Result<Baseline, ShapeMetricsError> {
    let pairwise = pairwise(tt, rr).map_err(|detail| ShapeMetricsError::Domain {
        what: "baseline pairwise distances",
        detail,
    })?;
    Ok(Baseline {
        label: format!("{label} against the reference"),
        nna: nna(tr, tt, rr, settings)?,
        coverage: coverage(tr, settings)?,
        pairwise_median_ratio: pairwise.median_ratio,
    })
}

fn nna(
    sr: &DistanceMatrix,
    ss: &DistanceMatrix,
    rr: &DistanceMatrix,
    settings: &ShapeSettings,
) -> Result<NnaEstimate, ShapeMetricsError> {
    let config = NnaConfig {
        subsets: settings.subsets,
        seed: settings.seed,
    };
    one_nna_subsampled(sr, ss, rr, &config)
}

/// MMD and COV of the whole set and over subsets of the reference's size.
fn coverage(
    sr: &DistanceMatrix,
    settings: &ShapeSettings,
) -> Result<CoverageEstimate, ShapeMetricsError> {
    let full = mmd_cov(sr)?;
    let (ns, nr) = (sr.rows(), sr.cols());
    let k = ns.min(nr);
    let draws = if ns > nr { settings.subsets.max(1) } else { 1 };
    let mut rng = ChaCha8Rng::seed_from_u64(settings.seed ^ 0xC0_7E2A6E);
    let mut mmds = Vec::with_capacity(draws);
    let mut covs = Vec::with_capacity(draws);
    for _ in 0..draws {
        let rows: Vec<usize> = match ns > nr {
            true => sample(&mut rng, ns, k).into_vec(),
            false => (0..ns).collect(),
        };
        let values = rows
            .iter()
            .flat_map(|&i| sr.row(i).iter().copied())
            .collect();
        let m = mmd_cov(&DistanceMatrix::new("COV subset", rows.len(), nr, values)?)?;
        mmds.push(m.mmd);
        covs.push(m.cov);
    }
    Ok(CoverageEstimate {
        mmd: full.mmd,
        cov: full.cov,
        subset_size: k,
        subsets: draws,
        mmd_subsets: interval(mmds),
        cov_subsets: interval(covs),
    })
}

fn interval(mut values: Vec<f64>) -> Interval {
    values.sort_by(f64::total_cmp);
    let q = |p: f64| crate::stats::descriptive::quantile_sorted(&values, p).unwrap_or(f64::NAN);
    Interval {
        mean: values.iter().sum::<f64>() / values.len().max(1) as f64,
        low: q(0.025),
        high: q(0.975),
    }
}

fn pairwise(ss: &DistanceMatrix, rr: &DistanceMatrix) -> Result<PairwiseComparison, String> {
    let upper = |m: &DistanceMatrix| -> Vec<f64> {
        (0..m.rows())
            .flat_map(|i| (i + 1..m.cols()).map(move |j| (i, j)))
            .map(|(i, j)| m.get(i, j))
            .collect()
    };
    let (cohort_values, reference_values) = (upper(ss), upper(rr));
    let cohort = Summary::of(&cohort_values).map_err(|e| format!("cohort pairs: {e}"))?;
    let reference = Summary::of(&reference_values).map_err(|e| format!("reference pairs: {e}"))?;
    if reference.median <= 0.0 {
        return Err("the reference's shapes are identical (pairwise median 0)".into());
    }
    Ok(PairwiseComparison {
        median_ratio: cohort.median / reference.median,
        cohort,
        reference,
        cohort_values,
        reference_values,
    })
}

/// The points of one surface on the common frame: sampled on the mesh in mm, centred at
/// its bounding-box centre, divided by `scale_mm`.
pub fn common_frame_points(
    mesh_mm: &TriMesh,
    points: usize,
    scale_mm: f64,
    seed: u64,
) -> Vec<[f32; 3]> {
    let centre = normalize_to_unit_ball(mesh_mm).1.centre;
    sample_surface(mesh_mm, points, seed)
        .points
        .iter()
        .map(|p| std::array::from_fn(|k| ((f64::from(p[k]) - centre[k]) / scale_mm) as f32))
        .collect()
}

/// Seed of member `i` of sampling stream `stream` (one stream per population and use).
fn member_seed(settings: &ShapeSettings, stream: u64, i: usize) -> u64 {
    settings.seed ^ (stream << 48) ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// Every member's surface sampled and indexed; a member without a surface to sample is
/// an error naming it.
fn sample_population(
    p: &Population,
    settings: &ShapeSettings,
    stream: u64,
) -> Result<Vec<ChamferIndex>, String> {
    p.members
        .par_iter()
        .enumerate()
        .map(|(i, m)| {
            let mesh = m
                .surface_mm
                .as_ref()
                .ok_or_else(|| format!("{} {} has no surface", p.label, m.name))?;
            let seed = member_seed(settings, stream, i);
            let points = common_frame_points(mesh, settings.points, settings.scale_mm, seed);
            match points.is_empty() {
                true => Err(format!("{} {} has no area to sample", p.label, m.name)),
                false => Ok(ChamferIndex::new(&points)),
            }
        })
        .collect()
}

/// Median over the reference of the distance between two samplings of the same surface.
fn sampling_floor(reference: &Population, settings: &ShapeSettings, progress: Progress<'_>) -> f64 {
    let floors: Vec<f64> = reference
        .members
        .par_iter()
        .enumerate()
        .map(|(i, m)| {
            let Some(mesh) = m.surface_mm.as_ref().filter(|_| !progress.stopped()) else {
                return 0.0;
            };
            let points = |stream| {
                let seed = member_seed(settings, stream, i);
                ChamferIndex::new(&common_frame_points(
                    mesh,
                    settings.points,
                    settings.scale_mm,
                    seed,
                ))
            };
            let d = chamfer_between_serial(&points(5), &points(6));
            progress.step();
            d
        })
        .collect();
    Summary::of(&floors).map_or(floors.first().copied().unwrap_or(0.0), |s| s.median)
}

/// Distances from every set of `a` to every set of `b`.
fn cross(a: &[ChamferIndex], b: &[ChamferIndex], progress: Progress<'_>) -> DistanceMatrix {
    let values: Vec<f64> = (0..a.len() * b.len())
        .into_par_iter()
        .map(|k| {
            if progress.stopped() {
                return 0.0;
            }
            let d = chamfer_between_serial(&a[k / b.len()], &b[k % b.len()]);
            progress.step();
            d
        })
        .collect();
    DistanceMatrix::new("Chamfer distances", a.len(), b.len(), values)
        .expect("Chamfer distances of sampled surfaces are finite and ≥ 0")
}

/// The symmetric matrix of distances within `a` (zero diagonal).
fn within(a: &[ChamferIndex], progress: Progress<'_>) -> DistanceMatrix {
    let n = a.len();
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .collect();
    let values: Vec<f64> = pairs
        .par_iter()
        .map(|&(i, j)| {
            if progress.stopped() {
                return 0.0;
            }
            let d = chamfer_between_serial(&a[i], &a[j]);
            progress.step();
            d
        })
        .collect();
    let mut full = vec![0.0; n * n];
    for (&(i, j), &v) in pairs.iter().zip(&values) {
        (full[i * n + j], full[j * n + i]) = (v, v);
    }
    DistanceMatrix::new("Chamfer distances", n, n, full)
        .expect("Chamfer distances of sampled surfaces are finite and ≥ 0")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_near_copy_threshold_is_two_floors_unless_a_new_patient_is_closer() {
        assert_eq!(near_copy_threshold(1.0, &[]), 2.0);
        assert_eq!(near_copy_threshold(1.0, &[3.0, 2.5]), 2.0);
        assert_eq!(near_copy_threshold(1.0, &[3.0, 1.5, 4.0]), 1.5);
    }
}
