//! Reconstruction fidelity of a trained model: each training shape's latent is meshed and
//! compared with the original surface by the Chamfer distance (DESIGN §3), in unit-ball
//! coordinates (squared distances, sum of both directed means).
//!
//! The report also gives the sampling floor: the Chamfer distance between two independent
//! samplings of the same original surface, the value a perfect reconstruction would score
//! with this many points (median over shapes). Shapes run one after another; the dense grid
//! evaluation and the nearest-neighbour searches inside each are parallel.

use serde::{Deserialize, Serialize};

use crate::geometry::TriMesh;
use crate::geometry::chamfer::{chamfer_distance, sampling_floor};
use crate::geometry::sampling::sample_surface;
use crate::sdf::inference::field::SdfField;
use crate::sdf::inference::reconstruct::{ExtractionMethod, ReconstructError, reconstruct};
use crate::sdf::store::LoadedModel;

/// The unit every Chamfer figure is reported in.
pub const CHAMFER_UNITS: &str =
    "unit-ball coordinates (squared distances; shape's farthest vertex at radius 1)";

/// How to evaluate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct EvaluationSettings {
    /// Grid samples per axis over [-1,1]³.
    pub resolution: usize,
    /// Points sampled on each surface for the Chamfer distance.
    pub chamfer_points: usize,
    /// Seed of those samplings.
    pub seed: u64,
    /// Fast (coarse-to-fine) or dense extraction of the reconstructed surface.
    #[serde(default)]
    pub extraction: ExtractionMethod,
}

/// One training shape's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShapeFidelity {
    /// Training index.
    pub index: usize,
    /// Shape name.
    pub name: String,
    /// Chamfer distance reconstruction ↔ original, or `None` when no mesh came out.
    pub chamfer: Option<f64>,
    /// CD of two independent samplings of the original (this shape's floor).
    pub sampling_floor: f64,
    /// Triangles of the reconstruction.
    pub triangles: usize,
    /// Why the reconstruction failed, if it did.
    pub error: Option<String>,
}

/// Order statistics of the successful Chamfer distances.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Number of values.
    pub count: usize,
    /// Smallest.
    pub min: f64,
    /// 25th percentile.
    pub q25: f64,
    /// Median.
    pub median: f64,
    /// 75th percentile.
    pub q75: f64,
    /// 90th percentile.
    pub q90: f64,
    /// Largest.
    pub max: f64,
    /// Arithmetic mean.
    pub mean: f64,
}

/// Counts of values per bin, bins equal in log10 between the smallest and largest value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Histogram {
    /// `counts.len() + 1` bin edges, increasing.
    pub edges: Vec<f64>,
    /// Values per bin (the last bin includes its upper edge).
    pub counts: Vec<usize>,
}

/// The whole evaluation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvaluationReport {
    /// Model identity (weights hash prefix).
    pub model_id: String,
    /// See [`CHAMFER_UNITS`].
    pub units: String,
    /// Settings used.
    pub settings: EvaluationSettings,
    /// Per-shape results in training order.
    pub shapes: Vec<ShapeFidelity>,
    /// Statistics of the successful Chamfer distances (`None` if none succeeded).
    pub summary: Option<Summary>,
    /// Histogram of the successful Chamfer distances.
    pub histogram: Option<Histogram>,
    /// Median over shapes of the per-shape sampling floor.
    pub sampling_floor_median: f64,
    /// Shapes whose reconstruction failed.
    pub failures: usize,
    /// The held-out shapes, fitted with the network frozen (models trained with a holdout).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heldout: Option<HeldOutEvaluation>,
}

/// Reconstruction of the held-out shapes (DeepSDF's test protocol): each fitted with the
/// network frozen, then meshed and measured exactly as the training shapes are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeldOutEvaluation {
    /// Adam steps of each fit.
    pub iterations: usize,
    /// Per-shape results in held-out order (`index` is the position among them).
    pub shapes: Vec<ShapeFidelity>,
    /// Statistics of the successful Chamfer distances.
    pub summary: Option<Summary>,
    /// Median over shapes of the per-shape sampling floor.
    pub sampling_floor_median: f64,
    /// Shapes whose fit or reconstruction failed.
    pub failures: usize,
}

impl HeldOutEvaluation {
    /// The summary of `shapes` fitted with `iterations` steps.
    pub fn new(iterations: usize, shapes: Vec<ShapeFidelity>) -> Self {
        let (cds, floor) = sorted_figures(&shapes);
        Self {
            iterations,
            failures: shapes.len() - cds.len(),
            summary: summarize(&cds),
            sampling_floor_median: quantile(&floor, 0.5),
            shapes,
        }
    }
}

/// The successful Chamfer distances and the sampling floors of `shapes`, each sorted.
fn sorted_figures(shapes: &[ShapeFidelity]) -> (Vec<f64>, Vec<f64>) {
    let mut cds: Vec<f64> = shapes.iter().filter_map(|s| s.chamfer).collect();
    cds.sort_by(f64::total_cmp);
    let mut floors: Vec<f64> = shapes.iter().map(|s| s.sampling_floor).collect();
    floors.sort_by(f64::total_cmp);
    (cds, floors)
}

/// Evaluates every training shape of `model` against `originals` (in the shapes' own units,
/// same order as the manifest). `on_shape` is called after each shape (for progress).
pub fn evaluate_model(
    model: &LoadedModel,
    originals: &[TriMesh],
    settings: &EvaluationSettings,
    on_shape: &mut dyn FnMut(&ShapeFidelity),
) -> anyhow::Result<EvaluationReport> {
    let shapes = &model.manifest.shapes;
    anyhow::ensure!(
        originals.len() == shapes.len(),
        "the data has {} meshes but the model was trained on {} shapes",
        originals.len(),
        shapes.len()
    );
    let latents = model.latents();
    let mut results = Vec::with_capacity(shapes.len());
    for (index, (record, original)) in shapes.iter().zip(originals).enumerate() {
        let unit = record.transform.mesh_to_unit(original);
        let seed = settings.seed.wrapping_add(2 * index as u64);
        let floor = sampling_floor(&unit, settings.chamfer_points, seed);
        let reconstructed = model
            .field(&latents[index])
            .map_err(Into::into)
            .and_then(|f| reconstruction_chamfer(&f, &unit, settings, seed));
        let result = match reconstructed {
            Ok((chamfer, triangles)) => ShapeFidelity {
                index,
                name: record.name.clone(),
                chamfer: Some(chamfer),
                sampling_floor: floor,
                triangles,
                error: None,
            },
            Err(e) => ShapeFidelity {
                index,
                name: record.name.clone(),
                chamfer: None,
                sampling_floor: floor,
                triangles: 0,
                error: Some(e.to_string()),
            },
        };
        on_shape(&result);
        results.push(result);
    }
    Ok(report(
        model.manifest.model_id().to_string(),
        *settings,
        results,
    ))
}

/// The reconstruction Chamfer distance of one shape as `aortagen evaluate` measures it: the
/// zero level of `field` meshed with `settings`, both surfaces sampled with
/// `settings.chamfer_points` points from `seed`, in unit-ball coordinates. Returns the
/// distance and the reconstruction's triangle count.
pub fn reconstruction_chamfer(
    field: &SdfField,
    original_unit: &TriMesh,
    settings: &EvaluationSettings,
    seed: u64,
) -> Result<(f64, usize), ReconstructError> {
    let mesh = reconstruct(field, settings.resolution, settings.extraction)?.mesh;
    let a = sample_surface(&mesh, settings.chamfer_points, seed ^ 0x5eed);
    let b = sample_surface(original_unit, settings.chamfer_points, seed ^ 0xb0b);
    Ok((chamfer_distance(&a.points, &b.points), mesh.triangles.len()))
}

fn report(
    model_id: String,
    settings: EvaluationSettings,
    shapes: Vec<ShapeFidelity>,
) -> EvaluationReport {
    let (cds, floors) = sorted_figures(&shapes);
    EvaluationReport {
        model_id,
        units: CHAMFER_UNITS.into(),
        settings,
        failures: shapes.len() - cds.len(),
        summary: summarize(&cds),
        histogram: histogram(&cds, 10),
        sampling_floor_median: quantile(&floors, 0.5),
        shapes,
        heldout: None,
    }
}

/// Order statistics of sorted values (`None` when empty).
pub fn summarize(sorted: &[f64]) -> Option<Summary> {
    let (&min, &max) = (sorted.first()?, sorted.last()?);
    Some(Summary {
        count: sorted.len(),
        min,
        q25: quantile(sorted, 0.25),
        median: quantile(sorted, 0.5),
        q75: quantile(sorted, 0.75),
        q90: quantile(sorted, 0.9),
        max,
        mean: sorted.iter().sum::<f64>() / sorted.len() as f64,
    })
}

/// Linear-interpolation quantile of sorted values (NaN when empty).
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

/// `bins` log-spaced bins between the smallest and largest positive value.
pub fn histogram(sorted: &[f64], bins: usize) -> Option<Histogram> {
    let positive: Vec<f64> = sorted.iter().copied().filter(|v| *v > 0.0).collect();
    let (lo, hi) = (positive.first()?.log10(), positive.last()?.log10());
    let bins = if hi > lo { bins.max(1) } else { 1 };
    let width = (hi - lo).max(f64::MIN_POSITIVE) / bins as f64;
    let edges: Vec<f64> = (0..=bins)
        .map(|i| 10f64.powf(lo + i as f64 * width))
        .collect();
    let mut counts = vec![0usize; bins];
    for v in &positive {
        let bin = ((v.log10() - lo) / width).floor() as usize;
        counts[bin.min(bins - 1)] += 1;
    }
    Some(Histogram { edges, counts })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_between_order_statistics() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(quantile(&v, 0.5), 3.0);
        assert_eq!(quantile(&v, 0.25), 2.0);
        assert_eq!(quantile(&v, 0.9), 4.6);
        assert_eq!(quantile(&[2.0, 4.0], 0.5), 3.0);
        assert!(quantile(&[], 0.5).is_nan());
        let s = summarize(&v).unwrap();
        assert_eq!((s.count, s.min, s.max, s.mean), (5, 1.0, 5.0, 3.0));
        assert!(summarize(&[]).is_none());
    }

    #[test]
    fn the_histogram_counts_every_value_in_log_bins() {
        let v = [1e-4, 2e-4, 1e-3, 5e-3, 1e-2];
        let h = histogram(&v, 2).unwrap();
        assert_eq!(h.edges.len(), 3);
        assert!((h.edges[0] - 1e-4).abs() < 1e-12 && (h.edges[2] - 1e-2).abs() < 1e-12);
        assert!((h.edges[1] - 1e-3).abs() < 1e-12);
        assert_eq!(h.counts, [2, 3]);
        let single = histogram(&[0.5, 0.5], 10).unwrap();
        assert_eq!(single.counts, [2]);
    }
}
