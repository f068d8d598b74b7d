//! Self-intersection count of a triangle mesh: every pair of triangles that share no vertex
//! and whose bounding boxes meet in a uniform grid of cells is tested exactly. The test
//! decides with Shewchuk's adaptive exact orientation predicates (the `robust` crate) on the
//! mesh's own coordinates, so touching and crossing are never confused by rounding.

use std::collections::HashMap;

use robust::{Coord, Coord3D, orient2d, orient3d};

use crate::geometry::TriMesh;

type P = [f64; 3];

fn o3(a: P, b: P, c: P, d: P) -> i8 {
    let c3 = |p: P| Coord3D {
        x: p[0],
        y: p[1],
        z: p[2],
    };
    let v = orient3d(c3(a), c3(b), c3(c), c3(d));
    (v > 0.0) as i8 - (v < 0.0) as i8
}

fn o2(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> i8 {
    let c2 = |p: [f64; 2]| Coord { x: p[0], y: p[1] };
    let v = orient2d(c2(a), c2(b), c2(c));
    (v > 0.0) as i8 - (v < 0.0) as i8
}

fn same_side(s: [i8; 3]) -> bool {
    (s[0] > 0 && s[1] > 0 && s[2] > 0) || (s[0] < 0 && s[1] < 0 && s[2] < 0)
}

/// Whether two triangles share at least one point (touching counts), decided exactly.
/// Degenerate (zero-area) triangles are reported as not intersecting.
pub fn triangles_intersect(t: [P; 3], u: [P; 3]) -> bool {
    let su = u.map(|p| o3(t[0], t[1], t[2], p));
    if same_side(su) {
        return false;
    }
    let st = t.map(|p| o3(u[0], u[1], u[2], p));
    if same_side(st) {
        return false;
    }
    if su == [0; 3] {
        return coplanar_intersect(t, u);
    }
    // Non-coplanar: the intersection, if any, has an end on an edge of one triangle.
    (0..3).any(|k| segment_hits(t[k], t[(k + 1) % 3], u))
        || (0..3).any(|k| segment_hits(u[k], u[(k + 1) % 3], t))
}

fn segment_hits(a: P, b: P, t: [P; 3]) -> bool {
    let (sa, sb) = (o3(t[0], t[1], t[2], a), o3(t[0], t[1], t[2], b));
    if sa == sb && sa != 0 {
        return false;
    }
    if sa == 0 && sb == 0 {
        let drop = dominant_axis(t);
        let q = |p: P| project(p, drop);
        let tri = t.map(q);
        return segment_meets_triangle_2d(q(a), q(b), tri);
    }
    let s = [
        o3(a, b, t[0], t[1]),
        o3(a, b, t[1], t[2]),
        o3(a, b, t[2], t[0]),
    ];
    s.iter().all(|&x| x >= 0) || s.iter().all(|&x| x <= 0)
}

/// The axis along which the triangle's normal is largest (dropping it keeps the triangle
/// non-degenerate in the projection).
fn dominant_axis(t: [P; 3]) -> usize {
    let (e1, e2) = (
        std::array::from_fn::<f64, 3, _>(|i| t[1][i] - t[0][i]),
        std::array::from_fn::<f64, 3, _>(|i| t[2][i] - t[0][i]),
    );
    let n = crate::geometry::mesh::cross(e1, e2);
    (0..3)
        .max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
        .unwrap_or(2)
}

fn project(p: P, drop: usize) -> [f64; 2] {
    match drop {
        0 => [p[1], p[2]],
        1 => [p[2], p[0]],
        _ => [p[0], p[1]],
    }
}

fn coplanar_intersect(t: [P; 3], u: [P; 3]) -> bool {
    let drop = dominant_axis(t);
    let (a, b) = (t.map(|p| project(p, drop)), u.map(|p| project(p, drop)));
    (0..3).any(|k| segment_meets_triangle_2d(a[k], a[(k + 1) % 3], b))
        || point_in_triangle_2d(b[0], a)
}

fn point_in_triangle_2d(p: [f64; 2], t: [[f64; 2]; 3]) -> bool {
    let s = [o2(t[0], t[1], p), o2(t[1], t[2], p), o2(t[2], t[0], p)];
    s.iter().all(|&x| x >= 0) || s.iter().all(|&x| x <= 0)
}

fn segment_meets_triangle_2d(a: [f64; 2], b: [f64; 2], t: [[f64; 2]; 3]) -> bool {
    point_in_triangle_2d(a, t) || (0..3).any(|k| segments_meet_2d(a, b, t[k], t[(k + 1) % 3]))
}

fn segments_meet_2d(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (d1, d2, d3, d4) = (o2(c, d, a), o2(c, d, b), o2(a, b, c), o2(a, b, d));
    if d1 * d2 < 0 && d3 * d4 < 0 {
        return true;
    }
    let within = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| {
        (0..2).all(|i| r[i] >= p[i].min(q[i]) && r[i] <= p[i].max(q[i]))
    };
    (d1 == 0 && within(c, d, a))
        || (d2 == 0 && within(c, d, b))
        || (d3 == 0 && within(a, b, c))
        || (d4 == 0 && within(a, b, d))
}

/// Number of pairs of triangles that share no vertex and intersect.
pub fn self_intersections(mesh: &TriMesh) -> usize {
    let n = mesh.triangles.len();
    if n < 2 {
        return 0;
    }
    let corners: Vec<[P; 3]> = (0..n).map(|t| mesh.corners(t)).collect();
    let boxes: Vec<(P, P)> = corners
        .iter()
        .map(|c| {
            let lo = std::array::from_fn(|i| c[0][i].min(c[1][i]).min(c[2][i]));
            let hi = std::array::from_fn(|i| c[0][i].max(c[1][i]).max(c[2][i]));
            (lo, hi)
        })
        .collect();
    let cell = boxes
        .iter()
        .map(|(lo, hi)| (0..3).map(|i| hi[i] - lo[i]).fold(0.0, f64::max))
        .sum::<f64>()
        / n as f64
        * 2.0;
    let cell = if cell > 0.0 { cell } else { 1.0 };
    let index = |x: f64| (x / cell).floor() as i64;
    let range = |b: &(P, P)| -> [std::ops::RangeInclusive<i64>; 3] {
        std::array::from_fn(|i| index(b.0[i])..=index(b.1[i]))
    };
    let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    for (t, b) in boxes.iter().enumerate() {
        let [rx, ry, rz] = range(b);
        for x in rx {
            for y in ry.clone() {
                for z in rz.clone() {
                    grid.entry([x, y, z]).or_default().push(t as u32);
                }
            }
        }
    }
    let mut count = 0;
    for (key, members) in &grid {
        for (i, &a) in members.iter().enumerate() {
            for &b in &members[i + 1..] {
                let (ba, bb) = (&boxes[a as usize], &boxes[b as usize]);
                if (0..3).any(|k| ba.1[k] < bb.0[k] || bb.1[k] < ba.0[k]) {
                    continue;
                }
                // Test each pair once: in the cell holding the low corner of the overlap.
                let first: [i64; 3] = std::array::from_fn(|k| index(ba.0[k].max(bb.0[k])));
                if &first != key {
                    continue;
                }
                let (ta, tb) = (mesh.triangles[a as usize], mesh.triangles[b as usize]);
                if ta.iter().any(|v| tb.contains(v)) {
                    continue;
                }
                if triangles_intersect(corners[a as usize], corners[b as usize]) {
                    count += 1;
                }
            }
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: [P; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

    #[test]
    fn crossing_touching_and_separate_triangles_are_told_apart() {
        // A vertical triangle piercing T, one touching T's edge, one just above T.
        let piercing = [[0.2, 0.2, -1.0], [0.3, 0.2, 1.0], [0.2, 0.3, 1.0]];
        let touching = [[0.5, 0.5, 0.0], [0.5, 0.5, 1.0], [1.0, 1.0, 1.0]];
        let above = [[0.0, 0.0, 1e-9], [1.0, 0.0, 1e-9], [0.0, 1.0, 1e-9]];
        let beside = [[0.51, 0.5, -1.0], [0.51, 0.5, 1.0], [1.0, 1.0, 0.0]];
        assert!(triangles_intersect(T, piercing));
        assert!(triangles_intersect(piercing, T));
        assert!(triangles_intersect(T, touching));
        assert!(!triangles_intersect(T, above));
        assert!(!triangles_intersect(T, beside));
    }

    #[test]
    fn coplanar_triangles_overlap_only_when_they_share_area_or_a_point() {
        let overlapping = [[0.2, 0.2, 0.0], [2.0, 0.2, 0.0], [0.2, 2.0, 0.0]];
        let apart = [[0.6, 0.6, 0.0], [2.0, 0.6, 0.0], [0.6, 2.0, 0.0]];
        let inside = [[0.1, 0.1, 0.0], [0.2, 0.1, 0.0], [0.1, 0.2, 0.0]];
        assert!(triangles_intersect(T, overlapping));
        assert!(!triangles_intersect(T, apart));
        assert!(triangles_intersect(T, inside));
        assert!(triangles_intersect(inside, T));
    }

    #[test]
    fn a_clean_sphere_has_none_and_two_overlapping_spheres_have_many() {
        let a = crate::geometry::test_shapes::uv_sphere(1.0, [0.0; 3], 12, 16);
        assert_eq!(self_intersections(&a), 0);
        let b = crate::geometry::test_shapes::uv_sphere(1.0, [0.9, 0.1, 0.05], 12, 16);
        let mut both = a.clone();
        let offset = a.positions.len() as u32;
        both.positions.extend(&b.positions);
        both.triangles
            .extend(b.triangles.iter().map(|t| t.map(|v| v + offset)));
        // The two spheres cross along a circle: at least one pair per crossed triangle of
        // the smaller ring of crossings.
        assert!(
            self_intersections(&both) >= 16,
            "{}",
            self_intersections(&both)
        );
    }
}
