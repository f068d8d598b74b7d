//! Cross-sections of a triangle mesh: iso-contours of a per-vertex scalar (a plane's signed
//! distance, a geodesic distance) chained into connected curves, and the planar measures of
//! one closed section loop (area, centroid, Feret diameters).

use std::collections::HashMap;

use crate::geometry::mesh::{cross, dot, norm, normalized, sub};

/// One connected iso-contour: the crossing points in order along the curve.
#[derive(Debug, Clone, PartialEq)]
pub struct Contour {
    /// Crossing points, one per crossed mesh edge.
    pub points: Vec<[f64; 3]>,
    /// True when the curve returns to its start (it ends at a hole otherwise).
    pub closed: bool,
    /// The triangles the curve crosses.
    pub faces: Vec<usize>,
}

impl Contour {
    /// Length of the curve (including the closing segment when closed).
    pub fn length(&self) -> f64 {
        self.segments().map(|(a, b)| norm(sub(b, a))).sum()
    }

    /// Length-weighted centroid of the curve.
    pub fn centroid(&self) -> [f64; 3] {
        let (mut acc, mut total) = ([0.0; 3], 0.0);
        for (a, b) in self.segments() {
            let l = norm(sub(b, a));
            for i in 0..3 {
                acc[i] += l * 0.5 * (a[i] + b[i]);
            }
            total += l;
        }
        if total > 0.0 {
            acc.map(|c| c / total)
        } else {
            self.points.first().copied().unwrap_or([0.0; 3])
        }
    }

    fn segments(&self) -> impl Iterator<Item = ([f64; 3], [f64; 3])> + '_ {
        let n = self.points.len();
        let count = if self.closed { n } else { n.saturating_sub(1) };
        (0..count).map(move |i| (self.points[i], self.points[(i + 1) % n]))
    }
}

type EdgeKey = (u32, u32);

fn key(a: u32, b: u32) -> EdgeKey {
    (a.min(b), a.max(b))
}

/// The zero set of `value` over the given triangles, chained into connected contours.
///
/// A vertex with value ≥ 0 counts as positive, so a vertex lying exactly on the iso-level
/// never produces a degenerate crossing: every crossed triangle gives one segment between
/// two crossed edges, and segments sharing an edge are joined.
pub fn contours(
    triangles: impl IntoIterator<Item = (usize, [u32; 3])>,
    positions: &[[f64; 3]],
    value: impl Fn(u32) -> f64,
) -> Vec<Contour> {
    let mut points: HashMap<EdgeKey, [f64; 3]> = HashMap::new();
    let mut segments: Vec<[EdgeKey; 2]> = Vec::new();
    let mut faces: Vec<usize> = Vec::new();
    let mut edge_segments: HashMap<EdgeKey, Vec<usize>> = HashMap::new();
    for (face, tri) in triangles {
        let f = tri.map(&value);
        let positive = f.map(|x| x >= 0.0);
        if positive[0] == positive[1] && positive[1] == positive[2] {
            continue;
        }
        let mut crossed = [(0, 0); 2];
        let mut n = 0;
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            if positive[i] == positive[j] {
                continue;
            }
            let (p, q) = if positive[i] { (i, j) } else { (j, i) };
            let k = key(tri[i], tri[j]);
            points.entry(k).or_insert_with(|| {
                let lambda = f[p] / (f[p] - f[q]);
                let (a, b) = (positions[tri[p] as usize], positions[tri[q] as usize]);
                std::array::from_fn(|c| a[c] + lambda * (b[c] - a[c]))
            });
            crossed[n] = k;
            n += 1;
        }
        let id = segments.len();
        segments.push(crossed);
        faces.push(face);
        for k in crossed {
            edge_segments.entry(k).or_default().push(id);
        }
    }
    chain(&segments, &edge_segments)
        .into_iter()
        .map(|(keys, segs, closed)| Contour {
            points: keys.iter().map(|k| points[k]).collect(),
            closed,
            faces: segs.iter().map(|&s| faces[s]).collect(),
        })
        .collect()
}

/// Joins segments that share an edge into chains of edge keys.
fn chain(
    segments: &[[EdgeKey; 2]],
    edge_segments: &HashMap<EdgeKey, Vec<usize>>,
) -> Vec<(Vec<EdgeKey>, Vec<usize>, bool)> {
    let mut used = vec![false; segments.len()];
    let mut out = Vec::new();
    // The unused segment other than `from` across edge `e`.
    let next = |e: EdgeKey, from: usize, used: &[bool]| -> Option<usize> {
        edge_segments[&e]
            .iter()
            .copied()
            .find(|&s| s != from && !used[s])
    };
    for start in 0..segments.len() {
        if used[start] {
            continue;
        }
        used[start] = true;
        let mut keys = std::collections::VecDeque::from(segments[start].to_vec());
        let mut members = vec![start];
        let mut closed = false;
        let (mut cur, mut e) = (start, segments[start][1]);
        loop {
            if e == segments[start][0] && cur != start {
                closed = true;
                keys.pop_back();
                break;
            }
            let Some(s) = next(e, cur, &used) else { break };
            used[s] = true;
            members.push(s);
            e = if segments[s][0] == e {
                segments[s][1]
            } else {
                segments[s][0]
            };
            keys.push_back(e);
            cur = s;
        }
        if !closed {
            let (mut cur, mut e) = (start, segments[start][0]);
            while let Some(s) = next(e, cur, &used) {
                used[s] = true;
                members.push(s);
                e = if segments[s][0] == e {
                    segments[s][1]
                } else {
                    segments[s][0]
                };
                keys.push_front(e);
                cur = s;
            }
        }
        out.push((keys.into_iter().collect(), members, closed));
    }
    out
}

/// An orthonormal frame of a cutting plane: `origin` in the plane, `normal` across it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneFrame {
    /// A point of the plane (the in-plane coordinates' origin).
    pub origin: [f64; 3],
    /// First in-plane axis.
    pub u: [f64; 3],
    /// Second in-plane axis.
    pub v: [f64; 3],
    /// Unit normal.
    pub normal: [f64; 3],
}

impl PlaneFrame {
    /// The plane through `origin` with normal `normal` (need not be unit, must be non-zero).
    pub fn new(origin: [f64; 3], normal: [f64; 3]) -> Self {
        let n = normalized(normal);
        let axis = if n[0].abs() < 0.6 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let u = normalized(cross(n, axis));
        let v = cross(n, u);
        Self {
            origin,
            u,
            v,
            normal: n,
        }
    }

    /// Signed distance of `p` from the plane.
    pub fn height(&self, p: [f64; 3]) -> f64 {
        dot(sub(p, self.origin), self.normal)
    }

    /// In-plane coordinates of `p`.
    pub fn project(&self, p: [f64; 3]) -> [f64; 2] {
        let d = sub(p, self.origin);
        [dot(d, self.u), dot(d, self.v)]
    }

    /// The 3-D point at in-plane coordinates `q`.
    pub fn lift(&self, q: [f64; 2]) -> [f64; 3] {
        std::array::from_fn(|i| self.origin[i] + q[0] * self.u[i] + q[1] * self.v[i])
    }
}

/// Signed area and area centroid of a simple polygon (shoelace).
pub fn polygon_area_centroid(q: &[[f64; 2]]) -> (f64, [f64; 2]) {
    let n = q.len();
    let (mut a2, mut cx, mut cy) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let (p, r) = (q[i], q[(i + 1) % n]);
        let w = p[0] * r[1] - r[0] * p[1];
        a2 += w;
        cx += (p[0] + r[0]) * w;
        cy += (p[1] + r[1]) * w;
    }
    if a2.abs() < f64::MIN_POSITIVE {
        return (0.0, q.first().copied().unwrap_or([0.0; 2]));
    }
    (0.5 * a2, [cx / (3.0 * a2), cy / (3.0 * a2)])
}

/// Whether `p` lies inside the polygon `q` (even–odd rule).
pub fn polygon_contains(q: &[[f64; 2]], p: [f64; 2]) -> bool {
    let n = q.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (q[i], q[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

fn cross2(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Convex hull, counter-clockwise (Andrew's monotone chain).
pub fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p = points.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross2(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// Largest distance between two points (maximal Feret diameter) and smallest width between
/// two parallel supporting lines (minimal Feret diameter) of a convex polygon.
pub fn feret_diameters(hull: &[[f64; 2]]) -> (f64, f64) {
    let n = hull.len();
    let dist = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
    let mut max = 0.0f64;
    for i in 0..n {
        for j in i + 1..n {
            max = max.max(dist(hull[i], hull[j]));
        }
    }
    let mut min = f64::INFINITY;
    for i in 0..n {
        let (a, b) = (hull[i], hull[(i + 1) % n]);
        let len = dist(a, b);
        if len == 0.0 {
            continue;
        }
        let width = hull
            .iter()
            .map(|&p| cross2(a, b, p).abs() / len)
            .fold(0.0, f64::max);
        min = min.min(width);
    }
    (max, if min.is_finite() { min } else { 0.0 })
}
