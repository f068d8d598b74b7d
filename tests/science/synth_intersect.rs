//! Self-intersection check: a spatial hash over triangle bounding boxes, then an exact
//! segment–triangle test (Möller–Trumbore) on every non-adjacent candidate pair. Two
//! non-coplanar triangles intersect iff an edge of one pierces the other.

use std::collections::HashMap;

use aortagen::geometry::TriMesh;
use aortagen::geometry::mesh::{cross, dot, sub};

type Tri = [[f64; 3]; 3];

/// Does segment p→q meet triangle t (boundaries included)?
fn segment_hits_triangle(p: [f64; 3], q: [f64; 3], t: &Tri) -> bool {
    let eps = 1e-9;
    let d = sub(q, p);
    let (e1, e2) = (sub(t[1], t[0]), sub(t[2], t[0]));
    let h = cross(d, e2);
    let det = dot(e1, h);
    if det.abs() < 1e-12 {
        return false; // parallel to the plane; coplanar pairs are not expected here
    }
    let s = sub(p, t[0]);
    let u = dot(s, h) / det;
    let qv = cross(s, e1);
    let v = dot(d, qv) / det;
    let w = dot(e2, qv) / det;
    u >= -eps && v >= -eps && u + v <= 1.0 + eps && (-eps..=1.0 + eps).contains(&w)
}

/// Exact test for two triangles in general position.
pub fn triangles_intersect(a: &Tri, b: &Tri) -> bool {
    let edges = |t: &Tri| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])];
    edges(a)
        .iter()
        .any(|&(p, q)| segment_hits_triangle(p, q, b))
        || edges(b)
            .iter()
            .any(|&(p, q)| segment_hits_triangle(p, q, a))
}

/// Pairs of triangles that share no vertex yet intersect (at most `limit` reported).
pub fn self_intersections(mesh: &TriMesh, limit: usize) -> Vec<(usize, usize)> {
    let tris: Vec<Tri> = (0..mesh.triangle_count())
        .map(|t| mesh.corners(t))
        .collect();
    let boxes: Vec<([f64; 3], [f64; 3])> = tris
        .iter()
        .map(|t| {
            let lo = std::array::from_fn(|k| t.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min));
            let hi =
                std::array::from_fn(|k| t.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max));
            (lo, hi)
        })
        .collect();
    let cell = 2.0;
    let key = |p: [f64; 3]| p.map(|c| (c / cell).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (t, (lo, hi)) in boxes.iter().enumerate() {
        let (a, b) = (key(*lo), key(*hi));
        for x in a[0]..=b[0] {
            for y in a[1]..=b[1] {
                for z in a[2]..=b[2] {
                    grid.entry([x, y, z]).or_default().push(t);
                }
            }
        }
    }
    let mut found = Vec::new();
    for (cell_key, members) in &grid {
        for (i, &a) in members.iter().enumerate() {
            for &b in &members[i + 1..] {
                let (ta, tb) = (mesh.triangles[a], mesh.triangles[b]);
                if ta.iter().any(|v| tb.contains(v)) {
                    continue;
                }
                let lo: [f64; 3] = std::array::from_fn(|k| boxes[a].0[k].max(boxes[b].0[k]));
                let hi: [f64; 3] = std::array::from_fn(|k| boxes[a].1[k].min(boxes[b].1[k]));
                // Boxes must overlap; test each pair once, in the cell holding the overlap's corner.
                if (0..3).any(|k| lo[k] > hi[k]) || key(lo) != *cell_key {
                    continue;
                }
                if triangles_intersect(&tris[a], &tris[b]) {
                    found.push((a, b));
                    if found.len() >= limit {
                        return found;
                    }
                }
            }
        }
    }
    found
}

#[test]
fn crossing_and_separate_triangles_are_told_apart() {
    let a: Tri = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
    let crossing: Tri = [[0.5, 0.5, -1.0], [0.5, 0.5, 1.0], [3.0, 3.0, 0.5]];
    let above: Tri = [[0.5, 0.5, 0.1], [0.5, 0.6, 1.0], [3.0, 3.0, 0.5]];
    let beside: Tri = [[1.5, 1.5, -1.0], [1.5, 1.5, 1.0], [3.0, 3.0, 0.0]];
    assert!(triangles_intersect(&a, &crossing));
    assert!(!triangles_intersect(&a, &above));
    assert!(!triangles_intersect(&a, &beside));
}

#[test]
fn overlapping_copies_of_a_root_are_caught() {
    let (_, mut mesh) = aortagen::synth::generate_root(2, 0, true);
    let n = mesh.vertex_count() as u32;
    let shifted: Vec<[f32; 3]> = mesh
        .positions
        .iter()
        .map(|p| [p[0] + 3.0, p[1], p[2]])
        .collect();
    let extra: Vec<[u32; 3]> = mesh.triangles.iter().map(|t| t.map(|i| i + n)).collect();
    mesh.positions.extend(shifted);
    mesh.triangles.extend(extra);
    assert!(!self_intersections(&mesh, 1).is_empty());
}
