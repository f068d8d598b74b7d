//! Flat caps: each boundary loop, a planar polygon, triangulated by ear clipping and then
//! made constrained-Delaunay by edge flips (which maximises the smallest angle among the
//! triangulations of the loop's own vertices). Marching-cubes loops have many nearly
//! collinear vertices and very short edges; ears are only cut where they are strictly
//! convex and empty, with a fallback that keeps the clipping going on rounding noise.

use std::collections::HashMap;

use crate::anatomy::sections::PlaneFrame;

/// Triangles (indices into `loop_2d`) covering the simple polygon `loop_2d`, which must
/// run counter-clockwise; the triangles run counter-clockwise too.
pub fn triangulate_polygon(loop_2d: &[[f64; 2]]) -> Vec<[usize; 3]> {
    let mut triangles = ear_clip(loop_2d);
    make_delaunay(loop_2d, &mut triangles);
    triangles
}

/// The loop `ring` (vertex ids, running as the cap must: counter-clockwise seen from outside
/// along `frame.normal`) projected into the cap's plane.
pub fn project_loop(positions: &[[f64; 3]], ring: &[u32], frame: &PlaneFrame) -> Vec<[f64; 2]> {
    ring.iter()
        .map(|&v| frame.project(positions[v as usize]))
        .collect()
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Whether `p` lies inside or on the counter-clockwise triangle (a, b, c).
fn in_triangle(p: [f64; 2], a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> bool {
    cross(a, b, p) >= 0.0 && cross(b, c, p) >= 0.0 && cross(c, a, p) >= 0.0
}

fn ear_clip(q: &[[f64; 2]]) -> Vec<[usize; 3]> {
    let n = q.len();
    let mut prev: Vec<usize> = (0..n).map(|i| (i + n - 1) % n).collect();
    let mut next: Vec<usize> = (0..n).map(|i| (i + 1) % n).collect();
    let mut out = Vec::with_capacity(n.saturating_sub(2));
    let mut remaining = n;
    let mut cur = 0;
    let mut misses = 0;
    while remaining > 3 {
        let (a, b, c) = (prev[cur], cur, next[cur]);
        let ear = cross(q[a], q[b], q[c]) > 0.0 && {
            let mut v = next[c];
            let mut empty = true;
            while v != a {
                // Only reflex (or flat) vertices can lie inside an ear.
                if cross(q[prev[v]], q[v], q[next[v]]) <= 0.0
                    && q[v] != q[a]
                    && q[v] != q[b]
                    && q[v] != q[c]
                    && in_triangle(q[v], q[a], q[b], q[c])
                {
                    empty = false;
                    break;
                }
                v = next[v];
            }
            empty
        };
        // After a full round without an ear (rounding noise on a nearly straight run), the
        // most convex corner is cut anyway so the clipping always finishes.
        let forced = misses > remaining;
        if ear || forced {
            let b = if forced {
                most_convex(q, &prev, &next, cur)
            } else {
                b
            };
            let (a, c) = (prev[b], next[b]);
            out.push([a, b, c]);
            next[a] = c;
            prev[c] = a;
            remaining -= 1;
            cur = c;
            misses = 0;
        } else {
            cur = next[cur];
            misses += 1;
        }
    }
    out.push([prev[cur], cur, next[cur]]);
    out
}

fn most_convex(q: &[[f64; 2]], prev: &[usize], next: &[usize], start: usize) -> usize {
    let mut best = (f64::NEG_INFINITY, start);
    let mut v = start;
    loop {
        let c = cross(q[prev[v]], q[v], q[next[v]]);
        if c > best.0 {
            best = (c, v);
        }
        v = next[v];
        if v == start {
            return best.1;
        }
    }
}

/// Whether `d` lies strictly inside the circumcircle of the counter-clockwise (a, b, c).
fn in_circle(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let rows = [a, b, c].map(|p| {
        let (x, y) = (p[0] - d[0], p[1] - d[1]);
        [x, y, x * x + y * y]
    });
    let [r0, r1, r2] = rows;
    let det = r0[0] * (r1[1] * r2[2] - r1[2] * r2[1]) - r0[1] * (r1[0] * r2[2] - r1[2] * r2[0])
        + r0[2] * (r1[0] * r2[1] - r1[1] * r2[0]);
    let scale = rows.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    det > 1e-12 * scale * scale
}

/// Lawson flips until every interior edge is locally Delaunay.
fn make_delaunay(q: &[[f64; 2]], triangles: &mut [[usize; 3]]) {
    let n = q.len();
    for _ in 0..10 * n.max(1) {
        let mut by_edge: HashMap<(usize, usize), (usize, usize)> = HashMap::new();
        let mut flipped = false;
        for (t, tri) in triangles.iter().enumerate() {
            for k in 0..3 {
                by_edge.insert((tri[k], tri[(k + 1) % 3]), (t, tri[(k + 2) % 3]));
            }
        }
        let mut touched = vec![false; triangles.len()];
        // Sorted, so that ties between co-circular vertices always resolve the same way.
        let mut edges: Vec<((usize, usize), (usize, usize))> =
            by_edge.iter().map(|(&k, &v)| (k, v)).collect();
        edges.sort_unstable();
        for ((a, b), (t, c)) in edges {
            let Some(&(u, d)) = by_edge.get(&(b, a)) else {
                continue;
            };
            if touched[t] || touched[u] || !in_circle(q[a], q[b], q[c], q[d]) {
                continue;
            }
            // The quad a-d-b-c must be strictly convex for the flipped pair to be valid.
            if cross(q[c], q[a], q[d]) <= 0.0 || cross(q[d], q[b], q[c]) <= 0.0 {
                continue;
            }
            triangles[t] = [c, a, d];
            triangles[u] = [d, b, c];
            touched[t] = true;
            touched[u] = true;
            flipped = true;
        }
        if !flipped {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(q: &[[f64; 2]], t: &[[usize; 3]]) -> f64 {
        t.iter()
            .map(|t| 0.5 * cross(q[t[0]], q[t[1]], q[t[2]]))
            .sum()
    }

    #[test]
    fn a_nonconvex_polygon_is_covered_exactly_once() {
        // A comb: its area is known, every triangle must be counter-clockwise.
        let q = vec![
            [0.0, 0.0],
            [5.0, 0.0],
            [5.0, 3.0],
            [4.0, 3.0],
            [4.0, 1.0],
            [3.0, 1.0],
            [3.0, 3.0],
            [2.0, 3.0],
            [2.0, 1.0],
            [1.0, 1.0],
            [1.0, 3.0],
            [0.0, 3.0],
        ];
        let t = triangulate_polygon(&q);
        assert_eq!(t.len(), q.len() - 2);
        assert!(t.iter().all(|t| cross(q[t[0]], q[t[1]], q[t[2]]) > 0.0));
        assert!((area(&q, &t) - 11.0).abs() < 1e-12);
    }

    #[test]
    fn a_circle_with_collinear_runs_gets_a_delaunay_cap() {
        // A 64-gon with extra points on some of its edges (as a plane cut of a fine mesh
        // gives): the triangulation covers it exactly and is Delaunay.
        let mut q = Vec::new();
        for k in 0..64 {
            let a = std::f64::consts::TAU * k as f64 / 64.0;
            let b = std::f64::consts::TAU * (k + 1) as f64 / 64.0;
            let (p, r) = ([a.cos(), a.sin()], [b.cos(), b.sin()]);
            q.push(p);
            if k % 3 == 0 {
                q.push([0.5 * (p[0] + r[0]), 0.5 * (p[1] + r[1])]);
            }
        }
        let t = triangulate_polygon(&q);
        let exact = 0.5 * 64.0 * (std::f64::consts::TAU / 64.0).sin();
        assert!((area(&q, &t) - exact).abs() < 1e-12);
        assert!(t.iter().all(|t| cross(q[t[0]], q[t[1]], q[t[2]]) > 0.0));
        for tri in &t {
            for (i, p) in q.iter().enumerate() {
                if !tri.contains(&i) {
                    assert!(!in_circle(q[tri[0]], q[tri[1]], q[tri[2]], *p));
                }
            }
        }
    }
}
