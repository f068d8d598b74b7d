//! Closest points on the surface being remeshed: a bounding-volume hierarchy over the
//! original triangles of one face (wall, cap, extension), and the original border curves
//! between two faces, so that remeshed vertices go back onto the face they belong to and
//! rim vertices back onto their rim.

use crate::geometry::mesh::{dot, norm, sub};

type P = [f64; 3];

/// The point of triangle (a, b, c) closest to `p` (Voronoi regions of the vertices, edges
/// and face, after Ericson's Real-Time Collision Detection §5.1.5).
pub fn closest_on_triangle(p: P, a: P, b: P, c: P) -> P {
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let at = |u: P, s: f64, w: P| std::array::from_fn(|i| u[i] + s * w[i]);
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return at(a, d1 / (d1 - d3), ab);
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return at(a, d2 / (d2 - d6), ac);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return at(b, (d4 - d3) / ((d4 - d3) + (d5 - d6)), sub(c, b));
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    std::array::from_fn(|i| a[i] + ab[i] * v + ac[i] * w)
}

/// The point of segment a–b closest to `p`.
pub fn closest_on_segment(p: P, a: P, b: P) -> P {
    let ab = sub(b, a);
    let len2 = dot(ab, ab);
    let t = if len2 > 0.0 {
        (dot(sub(p, a), ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    std::array::from_fn(|i| a[i] + t * ab[i])
}

#[derive(Debug, Clone)]
struct Node {
    lo: P,
    hi: P,
    /// Children, or (start, end) into `order` for a leaf (marked by `leaf`).
    a: usize,
    b: usize,
    leaf: bool,
}

/// Triangles with a bounding-box hierarchy for closest-point queries.
#[derive(Debug, Clone)]
pub struct TriangleTree {
    corners: Vec<[P; 3]>,
    order: Vec<usize>,
    nodes: Vec<Node>,
}

const LEAF: usize = 8;

impl TriangleTree {
    /// The tree of the given triangles (each as its three corners).
    pub fn new(corners: Vec<[P; 3]>) -> Self {
        let mut tree = Self {
            order: (0..corners.len()).collect(),
            corners,
            nodes: Vec::new(),
        };
        if !tree.corners.is_empty() {
            tree.build(0, tree.corners.len());
        }
        tree
    }

    fn bounds(&self, range: &[usize]) -> (P, P) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for &t in range {
            for p in &self.corners[t] {
                for i in 0..3 {
                    lo[i] = lo[i].min(p[i]);
                    hi[i] = hi[i].max(p[i]);
                }
            }
        }
        (lo, hi)
    }

    fn build(&mut self, start: usize, end: usize) -> usize {
        let (lo, hi) = self.bounds(&self.order[start..end]);
        let id = self.nodes.len();
        self.nodes.push(Node {
            lo,
            hi,
            a: start,
            b: end,
            leaf: true,
        });
        if end - start <= LEAF {
            return id;
        }
        let axis = (0..3)
            .max_by(|&x, &y| (hi[x] - lo[x]).total_cmp(&(hi[y] - lo[y])))
            .unwrap_or(0);
        let centre = |t: usize| self.corners[t].iter().map(|p| p[axis]).sum::<f64>();
        let mid = start + (end - start) / 2;
        let mut part = self.order[start..end].to_vec();
        part.select_nth_unstable_by(mid - start, |&x, &y| centre(x).total_cmp(&centre(y)));
        self.order[start..end].copy_from_slice(&part);
        let left = self.build(start, mid);
        let right = self.build(mid, end);
        self.nodes[id] = Node {
            lo,
            hi,
            a: left,
            b: right,
            leaf: false,
        };
        id
    }

    /// The closest point of the triangles to `p` and its distance (`None` when empty).
    pub fn closest(&self, p: P) -> Option<(P, f64)> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut best: (P, f64) = (p, f64::INFINITY);
        let mut stack = vec![0usize];
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n];
            let gap: f64 = (0..3)
                .map(|i| (node.lo[i] - p[i]).max(p[i] - node.hi[i]).max(0.0).powi(2))
                .sum::<f64>()
                .sqrt();
            if gap >= best.1 {
                continue;
            }
            if node.leaf {
                for &t in &self.order[node.a..node.b] {
                    let [a, b, c] = self.corners[t];
                    let q = closest_on_triangle(p, a, b, c);
                    let d = norm(sub(q, p));
                    if d < best.1 {
                        best = (q, d);
                    }
                }
            } else {
                stack.push(node.a);
                stack.push(node.b);
            }
        }
        Some(best)
    }
}

/// The closest point to `p` on a set of segments, and its distance.
pub fn closest_on_curve(p: P, segments: &[(P, P)]) -> Option<(P, f64)> {
    segments
        .iter()
        .map(|&(a, b)| {
            let q = closest_on_segment(p, a, b);
            (q, norm(sub(q, p)))
        })
        .min_by(|x, y| x.1.total_cmp(&y.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_points_match_brute_force_sampling() {
        let (a, b, c) = ([0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.3, 1.5, 0.2]);
        let tree = TriangleTree::new(vec![[a, b, c]]);
        for p in [
            [0.5, 0.5, 1.0],
            [-1.0, -1.0, 0.0],
            [3.0, 0.2, -0.4],
            [1.2, 1.2, 0.0],
            [0.1, 3.0, 0.3],
        ] {
            let (q, d) = tree.closest(p).unwrap();
            let mut brute = f64::INFINITY;
            let n = 400;
            for i in 0..=n {
                for j in 0..=n - i {
                    let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                    let s: P =
                        std::array::from_fn(|k| a[k] + u * (b[k] - a[k]) + v * (c[k] - a[k]));
                    brute = brute.min(norm(sub(s, p)));
                }
            }
            assert!(
                d <= brute + 1e-12 && brute - d < 0.01,
                "{p:?}: {d} vs {brute}"
            );
            assert!((norm(sub(q, p)) - d).abs() < 1e-12);
        }
    }
}
