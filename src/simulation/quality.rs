//! Triangle quality and topology of a surface mesh: distributions (summary and histogram) of
//! the smallest angle, the aspect ratio and the edge length, manifoldness and the number of
//! self-intersecting triangle pairs — what a volume mesher (TetGen, snappyHexMesh) or an FEA
//! pre-processor checks before it accepts a surface.

use std::collections::HashMap;

use serde::{Deserialize, Serialize};

use super::intersect::self_intersections;
use crate::geometry::TriMesh;
use crate::geometry::mesh::{norm, sub};

/// Counts of values between consecutive bin edges (the last bin includes its upper edge).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Histogram {
    /// Bin edges, one more than there are bins.
    pub edges: Vec<f64>,
    /// Values per bin.
    pub counts: Vec<usize>,
}

/// Summary of a sample of values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Distribution {
    /// Smallest value.
    pub min: f64,
    /// 1st percentile.
    pub p01: f64,
    /// 5th percentile.
    pub p05: f64,
    /// Median.
    pub median: f64,
    /// Mean.
    pub mean: f64,
    /// 95th percentile.
    pub p95: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest value.
    pub max: f64,
    /// Counts per bin.
    pub histogram: Histogram,
}

impl Distribution {
    /// The distribution of `values` over the bins `edges` (values outside go to the end bins).
    pub fn new(mut values: Vec<f64>, edges: Vec<f64>) -> Self {
        values.retain(|v| v.is_finite());
        values.sort_by(f64::total_cmp);
        let at = |q: f64| {
            if values.is_empty() {
                return 0.0;
            }
            values[((values.len() - 1) as f64 * q).round() as usize]
        };
        let bins = edges.len().saturating_sub(1).max(1);
        let mut counts = vec![0; bins];
        for &v in &values {
            let k = edges.partition_point(|&e| e <= v).saturating_sub(1);
            counts[k.min(bins - 1)] += 1;
        }
        Self {
            min: at(0.0),
            p01: at(0.01),
            p05: at(0.05),
            median: at(0.5),
            mean: values.iter().sum::<f64>() / values.len().max(1) as f64,
            p95: at(0.95),
            p99: at(0.99),
            max: at(1.0),
            histogram: Histogram { edges, counts },
        }
    }
}

/// Topology of the surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifoldness {
    /// Edges used by one triangle only.
    pub boundary_edges: usize,
    /// Closed chains of boundary edges (holes, openings).
    pub boundary_loops: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Vertices whose triangles form more than one fan.
    pub non_manifold_vertices: usize,
    /// Edges whose two triangles disagree on orientation.
    pub inconsistently_oriented_edges: usize,
    /// V − E + F (2 for a closed surface of genus 0).
    pub euler_characteristic: i64,
    /// Closed, manifold and consistently oriented.
    pub watertight: bool,
}

/// Triangle quality of one mesh.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QualityReport {
    /// Vertex count.
    pub vertices: usize,
    /// Triangle count.
    pub triangles: usize,
    /// Smallest angle of each triangle, degrees (60 for an equilateral triangle).
    pub min_angle_deg: Distribution,
    /// Share of triangles whose smallest angle is at least 20°.
    pub share_min_angle_20: f64,
    /// Share of triangles whose smallest angle is at least 30°.
    pub share_min_angle_30: f64,
    /// Circumradius over twice the inradius of each triangle (1 for equilateral).
    pub aspect_ratio: Distribution,
    /// Length of each edge, mm.
    pub edge_length_mm: Distribution,
    /// Triangles of zero area.
    pub degenerate_triangles: usize,
    /// Topology.
    pub manifold: Manifoldness,
    /// Pairs of triangles sharing no vertex that intersect (exact test).
    pub self_intersections: usize,
}

/// Smallest angle (degrees) and aspect ratio R/(2r) of a triangle; `None` when degenerate.
pub fn triangle_shape(c: [[f64; 3]; 3]) -> Option<(f64, f64)> {
    let l = [0, 1, 2].map(|k| norm(sub(c[(k + 1) % 3], c[(k + 2) % 3])));
    let s = 0.5 * (l[0] + l[1] + l[2]);
    let area2 = s * (s - l[0]) * (s - l[1]) * (s - l[2]);
    if area2 <= 0.0 || l.contains(&0.0) {
        return None;
    }
    let area = area2.sqrt();
    // The smallest angle is opposite the shortest edge (law of cosines).
    let (a, b, c2) = {
        let mut m = l;
        m.sort_by(f64::total_cmp);
        (m[0], m[1], m[2])
    };
    let cos = ((b * b + c2 * c2 - a * a) / (2.0 * b * c2)).clamp(-1.0, 1.0);
    let circumradius = l[0] * l[1] * l[2] / (4.0 * area);
    let inradius = area / s;
    Some((cos.acos().to_degrees(), circumradius / (2.0 * inradius)))
}

/// Quality, topology and self-intersections of `mesh`.
pub fn quality_report(mesh: &TriMesh) -> QualityReport {
    let shapes: Vec<Option<(f64, f64)>> = (0..mesh.triangle_count())
        .map(|t| triangle_shape(mesh.corners(t)))
        .collect();
    let angles: Vec<f64> = shapes.iter().map(|s| s.map_or(0.0, |s| s.0)).collect();
    let aspects: Vec<f64> = shapes.iter().flatten().map(|s| s.1).collect();
    let n = angles.len().max(1) as f64;
    let share = |deg: f64| angles.iter().filter(|&&a| a >= deg).count() as f64 / n;
    let edges = unique_edges(mesh);
    let lengths: Vec<f64> = edges
        .keys()
        .map(|&(a, b)| {
            let p = |v: u32| mesh.positions[v as usize].map(f64::from);
            norm(sub(p(a), p(b)))
        })
        .collect();
    let (lo, hi) = lengths
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, h), &x| (l.min(x), h.max(x)));
    let length_edges = (0..=20).map(|k| lo + (hi - lo) * k as f64 / 20.0).collect();
    let max_aspect = aspects.iter().copied().fold(10.0, f64::max);
    QualityReport {
        vertices: mesh.vertex_count(),
        triangles: mesh.triangle_count(),
        min_angle_deg: Distribution::new(
            angles.clone(),
            (0..=12).map(|k| 5.0 * k as f64).collect(),
        ),
        share_min_angle_20: share(20.0),
        share_min_angle_30: share(30.0),
        aspect_ratio: Distribution::new(
            aspects,
            vec![1.0, 1.1, 1.25, 1.5, 2.0, 3.0, 5.0, 10.0, max_aspect],
        ),
        edge_length_mm: Distribution::new(lengths, length_edges),
        degenerate_triangles: shapes.iter().filter(|s| s.is_none()).count(),
        manifold: manifoldness(mesh, &edges),
        self_intersections: self_intersections(mesh),
    }
}

/// Each undirected edge with the (triangle, corner) uses of it.
fn unique_edges(mesh: &TriMesh) -> HashMap<(u32, u32), Vec<usize>> {
    let mut out: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            out.entry((a.min(b), a.max(b))).or_default().push(t);
        }
    }
    out
}

fn find(parent: &mut [usize], mut x: usize) -> usize {
    while parent[x] != x {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    x
}

fn manifoldness(mesh: &TriMesh, edges: &HashMap<(u32, u32), Vec<usize>>) -> Manifoldness {
    let report = mesh.edge_report();
    // Corners (triangle, vertex) of one vertex join when their triangles share an edge at
    // it; a manifold vertex ends with one group.
    let corner =
        |t: usize, v: u32| 3 * t + mesh.triangles[t].iter().position(|&x| x == v).unwrap_or(0);
    let mut parent: Vec<usize> = (0..3 * mesh.triangles.len()).collect();
    let mut loops: Vec<usize> = (0..mesh.positions.len()).collect();
    for (&(a, b), users) in edges {
        for &t in &users[1..] {
            for v in [a, b] {
                let (x, y) = (
                    find(&mut parent, corner(users[0], v)),
                    find(&mut parent, corner(t, v)),
                );
                parent[x] = y;
            }
        }
        if users.len() == 1 {
            let (x, y) = (find(&mut loops, a as usize), find(&mut loops, b as usize));
            loops[x] = y;
        }
    }
    let mut groups: HashMap<u32, Vec<usize>> = HashMap::new();
    for t in 0..mesh.triangles.len() {
        for (k, &v) in mesh.triangles[t].iter().enumerate() {
            groups
                .entry(v)
                .or_default()
                .push(find(&mut parent, 3 * t + k));
        }
    }
    let non_manifold_vertices = groups
        .values_mut()
        .map(|g| {
            g.sort_unstable();
            g.dedup();
            g.len()
        })
        .filter(|&fans| fans > 1)
        .count();
    let mut on_boundary: Vec<usize> = edges
        .iter()
        .filter(|(_, u)| u.len() == 1)
        .map(|(&(a, _), _)| find(&mut loops, a as usize))
        .collect();
    on_boundary.sort_unstable();
    on_boundary.dedup();
    Manifoldness {
        boundary_edges: report.boundary_edges,
        boundary_loops: on_boundary.len(),
        non_manifold_edges: report.non_manifold_edges,
        non_manifold_vertices,
        inconsistently_oriented_edges: report.inconsistently_oriented_edges,
        euler_characteristic: mesh.euler_characteristic(),
        watertight: report.is_closed_and_oriented() && non_manifold_vertices == 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_shapes_match_closed_forms() {
        let h = 3f64.sqrt() / 2.0;
        let (angle, aspect) = triangle_shape([[0.0; 3], [1.0, 0.0, 0.0], [0.5, h, 0.0]]).unwrap();
        assert!((angle - 60.0).abs() < 1e-9 && (aspect - 1.0).abs() < 1e-9);
        // Right isosceles: 45°, R = √2/2, r = 1 − √2/2.
        let (angle, aspect) = triangle_shape([[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]).unwrap();
        let exact = (2f64.sqrt() / 2.0) / (2.0 * (1.0 - 2f64.sqrt() / 2.0));
        assert!((angle - 45.0).abs() < 1e-9 && (aspect - exact).abs() < 1e-9);
        assert!(triangle_shape([[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]).is_none());
    }

    #[test]
    fn distributions_bin_and_rank_their_values() {
        let d = Distribution::new((1..=100).map(f64::from).collect(), vec![0.0, 50.0, 100.0]);
        assert_eq!(d.histogram.counts, [49, 51]);
        assert_eq!((d.min, d.median, d.max), (1.0, 51.0, 100.0));
        assert_eq!((d.p01, d.p99), (2.0, 99.0));
        assert!((d.mean - 50.5).abs() < 1e-12);
    }

    #[test]
    fn a_cube_is_watertight_and_a_cube_with_a_hole_is_not() {
        let cube = TriMesh::unit_cube();
        let q = quality_report(&cube);
        assert!(q.manifold.watertight);
        assert_eq!(
            (q.manifold.boundary_loops, q.manifold.euler_characteristic),
            (0, 2)
        );
        assert_eq!(q.self_intersections, 0);
        // Right isosceles halves of squares.
        assert!((q.min_angle_deg.min - 45.0).abs() < 1e-6);
        assert_eq!(q.min_angle_deg.histogram.counts.iter().sum::<usize>(), 12);
        let mut holed = cube.clone();
        holed.triangles.truncate(10);
        let q = quality_report(&holed);
        assert!(!q.manifold.watertight);
        assert_eq!(
            (q.manifold.boundary_loops, q.manifold.boundary_edges),
            (1, 4)
        );
    }

    #[test]
    fn two_cubes_touching_at_a_corner_make_a_non_manifold_vertex() {
        let mut m = TriMesh::unit_cube();
        let other = TriMesh::unit_cube();
        let base = m.positions.len() as u32;
        // Shift the second cube so its vertex 0 coincides with the first cube's vertex 7.
        m.positions
            .extend(other.positions.iter().skip(1).map(|p| p.map(|c| c + 1.0)));
        let remap = |v: u32| if v == 0 { 7 } else { base + v - 1 };
        m.triangles
            .extend(other.triangles.iter().map(|t| t.map(remap)));
        let q = quality_report(&m);
        assert_eq!(q.manifold.non_manifold_vertices, 1);
        assert_eq!(q.manifold.non_manifold_edges, 0);
        assert!(!q.manifold.watertight);
    }
}
