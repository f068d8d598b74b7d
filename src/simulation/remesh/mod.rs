//! Isotropic remeshing to a target edge length L (Botsch & Kobbelt 2004): split edges longer
//! than 4/3·L, collapse edges shorter than 4/5·L, flip edges towards valence 6, relax vertices
//! tangentially and project them back onto the input surface — each vertex onto its own face
//! (wall, cap or extension), rim vertices along their rim, corners fixed — so caps stay flat
//! and labels keep their borders. The largest distance to the input surface is measured both
//! ways on the result and reported with its angle statistics.
//!
//! No Rust crate did this when it was written: `remesh` 0.0.x is marked experimental by its
//! author (its smoothing with projection can make overlaps), and `baby_shark`'s incremental
//! remesher brings nalgebra and faer and can only freeze boundaries, not keep face labels
//! or let rims be resampled.

mod halfedge;
mod ops;
pub mod project;

use serde::{Deserialize, Serialize};

use super::quality::triangle_shape;
use super::{LabelledMesh, SimulationError};
use crate::geometry::TriMesh;
use project::TriangleTree;

/// Smallest and largest accepted target edge length, mm.
pub const TARGET_RANGE_MM: (f64, f64) = (0.1, 10.0);

/// Triangles an isotropic remesh of `area_mm2` to edges of `target_mm` makes: the area over
/// an equilateral triangle's. The remesh's time and memory grow with it, so services bound
/// it before starting.
pub fn expected_triangles(area_mm2: f64, target_mm: f64) -> u64 {
    (area_mm2.max(0.0) / equilateral_area(target_mm)).ceil() as u64
}

/// Area of an equilateral triangle with edge `edge_mm`: √3/4 · L².
fn equilateral_area(edge_mm: f64) -> f64 {
    3f64.sqrt() / 4.0 * edge_mm * edge_mm
}

/// The finest target edge length, to 0.01 mm, whose remesh of `area_mm2` makes at most
/// `max_triangles` triangles.
pub fn finest_target_mm(area_mm2: f64, max_triangles: u64) -> f64 {
    let edge = (area_mm2.max(0.0) / (equilateral_area(1.0) * max_triangles.max(1) as f64)).sqrt();
    let mut hundredths = (edge * 100.0).ceil();
    while expected_triangles(area_mm2, hundredths / 100.0) > max_triangles {
        hundredths += 1.0;
    }
    (hundredths / 100.0).max(TARGET_RANGE_MM.0)
}

/// Refuses a remesh of `area_mm2` to `target_mm` that would make more than `max_triangles`
/// triangles, naming the finest target within the limit.
pub fn check_budget(
    area_mm2: f64,
    target_mm: f64,
    max_triangles: u64,
) -> Result<(), SimulationError> {
    let triangles = expected_triangles(area_mm2, target_mm);
    if triangles <= max_triangles {
        return Ok(());
    }
    Err(SimulationError::OverBudget {
        triangles,
        max_triangles,
        area_mm2,
        finest_mm: finest_target_mm(area_mm2, max_triangles),
    })
}

/// Remeshing settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RemeshOptions {
    /// Target edge length, mm.
    pub target_mm: f64,
    /// Split–collapse–flip–relax passes.
    pub iterations: usize,
}

impl RemeshOptions {
    /// Settings for a target edge length (0.1–10 mm), 8 passes.
    pub fn new(target_mm: f64) -> Result<Self, SimulationError> {
        let (lo, hi) = TARGET_RANGE_MM;
        if !(target_mm.is_finite() && (lo..=hi).contains(&target_mm)) {
            return Err(SimulationError::option(
                "remesh_mm",
                format!("{target_mm} mm must lie within {lo}–{hi} mm"),
            ));
        }
        Ok(Self {
            target_mm,
            iterations: 8,
        })
    }
}

/// What the remeshing did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RemeshReport {
    /// Target edge length, mm.
    pub target_mm: f64,
    /// Triangles before and after.
    pub triangles_before: usize,
    /// Triangles after.
    pub triangles_after: usize,
    /// Largest distance between the remeshed and the input surface, either way (vertices,
    /// edge midpoints and triangle centroids of each measured against the other), mm.
    pub max_distance_mm: f64,
    /// Smallest triangle angle after remeshing, degrees.
    pub min_angle_deg: f64,
    /// Share of triangles whose smallest angle is at least 20°.
    pub share_min_angle_20: f64,
    /// Median edge length after remeshing, mm.
    pub median_edge_mm: f64,
}

/// Remeshes a closed labelled mesh; labels, cap planes and rims are kept.
pub fn remesh(
    mesh: &LabelledMesh,
    opts: &RemeshOptions,
) -> Result<(LabelledMesh, RemeshReport), SimulationError> {
    let input = &mesh.mesh;
    let remeshed = ops::Remesher::new(mesh, opts.target_mm)?.run(opts.iterations);
    let (positions, triangles, labels) = remeshed;
    let mut out = TriMesh::new(
        positions.iter().map(|p| p.map(|c| c as f32)).collect(),
        triangles,
    );
    out.normals = Some(out.compute_vertex_normals());
    let report = report(input, &out, opts.target_mm);
    Ok((
        LabelledMesh {
            mesh: out,
            face_ids: labels,
            faces: mesh.faces.clone(),
        },
        report,
    ))
}

/// Points that stand for a surface: vertices, edge midpoints and triangle centroids.
fn samples(m: &TriMesh) -> Vec<[f64; 3]> {
    let mut out: Vec<[f64; 3]> = m.positions.iter().map(|p| p.map(f64::from)).collect();
    for t in 0..m.triangle_count() {
        let c = m.corners(t);
        out.push(std::array::from_fn(|i| (c[0][i] + c[1][i] + c[2][i]) / 3.0));
        for k in 0..3 {
            out.push(std::array::from_fn(|i| 0.5 * (c[k][i] + c[(k + 1) % 3][i])));
        }
    }
    out
}

fn one_way(from: &TriMesh, to: &TriMesh) -> f64 {
    use rayon::prelude::*;
    let tree = TriangleTree::new((0..to.triangle_count()).map(|t| to.corners(t)).collect());
    samples(from)
        .par_iter()
        .map(|&p| tree.closest(p).map_or(0.0, |(_, d)| d))
        .reduce(|| 0.0, f64::max)
}

fn report(input: &TriMesh, out: &TriMesh, target: f64) -> RemeshReport {
    let angles: Vec<f64> = (0..out.triangle_count())
        .map(|t| triangle_shape(out.corners(t)).map_or(0.0, |s| s.0))
        .collect();
    let mut edges: Vec<f64> = out
        .triangles
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
        .filter(|(a, b)| a < b)
        .map(|(a, b)| {
            let p = |v: u32| out.positions[v as usize].map(f64::from);
            crate::geometry::mesh::norm(crate::geometry::mesh::sub(p(a), p(b)))
        })
        .collect();
    edges.sort_by(f64::total_cmp);
    RemeshReport {
        target_mm: target,
        triangles_before: input.triangle_count(),
        triangles_after: out.triangle_count(),
        max_distance_mm: one_way(out, input).max(one_way(input, out)),
        min_angle_deg: angles.iter().copied().fold(f64::INFINITY, f64::min),
        share_min_angle_20: angles.iter().filter(|&&a| a >= 20.0).count() as f64
            / angles.len().max(1) as f64,
        median_edge_mm: edges.get(edges.len() / 2).copied().unwrap_or(0.0),
    }
}
