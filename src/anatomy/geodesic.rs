//! The first guess of a centreline, from geodesic distances on the surface: the two ends are
//! the geodesically farthest pair of vertices, and the level sets of the distance from one end
//! are rings around the tube whose centroids follow the lumen, through bends and past side
//! branches (at a branch the level set splits; the longest piece is the main vessel's ring).

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::MeasureError;
use super::polyline::Polyline;
use super::sections::contours;
use super::surface::Surface;
use crate::geometry::mesh::{norm, sub};

/// Vertex adjacency with edge lengths, in compressed rows.
pub(crate) struct Graph {
    offsets: Vec<usize>,
    targets: Vec<(u32, f64)>,
}

impl Graph {
    /// The edge graph of `surface`.
    pub(crate) fn new(surface: &Surface) -> Self {
        let n = surface.positions.len();
        let mut edges: Vec<(u32, u32)> = surface
            .triangles
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .flat_map(|(a, b)| [(a, b), (b, a)])
            .collect();
        edges.sort_unstable();
        edges.dedup();
        let mut offsets = vec![0; n + 1];
        for &(a, _) in &edges {
            offsets[a as usize + 1] += 1;
        }
        for i in 0..n {
            offsets[i + 1] += offsets[i];
        }
        let p = &surface.positions;
        let targets = edges
            .iter()
            .map(|&(a, b)| (b, norm(sub(p[a as usize], p[b as usize]))))
            .collect();
        Self { offsets, targets }
    }

    /// Shortest edge-path distances from `source` (infinite where unreachable).
    pub(crate) fn distances(&self, source: usize) -> Vec<f64> {
        let mut dist = vec![f64::INFINITY; self.offsets.len() - 1];
        let mut heap = BinaryHeap::new();
        dist[source] = 0.0;
        heap.push(Reverse((0u64, source)));
        while let Some(Reverse((bits, v))) = heap.pop() {
            let d = f64::from_bits(bits);
            if d > dist[v] {
                continue;
            }
            for &(w, len) in &self.targets[self.offsets[v]..self.offsets[v + 1]] {
                let nd = d + len;
                if nd < dist[w as usize] {
                    dist[w as usize] = nd;
                    // Non-negative floats order like their bit patterns.
                    heap.push(Reverse((nd.to_bits(), w as usize)));
                }
            }
        }
        dist
    }
}

/// The vertex with the largest finite distance.
pub(crate) fn farthest(dist: &[f64]) -> usize {
    (0..dist.len())
        .filter(|&i| dist[i].is_finite())
        .max_by(|&a, &b| dist[a].total_cmp(&dist[b]))
        .unwrap_or(0)
}

/// A vertex of the largest connected piece of the surface (by vertex count).
pub(crate) fn seed_vertex(surface: &Surface) -> usize {
    let n = surface.positions.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    for t in &surface.triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2])] {
            let (ra, rb) = (root(&mut parent, a as usize), root(&mut parent, b as usize));
            parent[ra] = rb;
        }
    }
    let mut size = vec![0usize; n];
    let used: Vec<bool> = {
        let mut u = vec![false; n];
        surface
            .triangles
            .iter()
            .flatten()
            .for_each(|&v| u[v as usize] = true);
        u
    };
    for v in (0..n).filter(|&v| used[v]) {
        let r = root(&mut parent, v);
        size[r] += 1;
    }
    let biggest = (0..n).max_by_key(|&r| size[r]).unwrap_or(0);
    (0..n)
        .find(|&v| used[v] && root(&mut parent, v) == biggest)
        .unwrap_or(0)
}

/// Rough centre points: centroids of the longest level-set curve of the geodesic distance
/// from one end, every `step` mm, where the ends are the geodesically farthest vertex pair
/// (double sweep) and levels within a ring diameter of either end are left out.
pub fn level_set_centres(surface: &Surface, step: f64) -> Result<Polyline, MeasureError> {
    let graph = Graph::new(surface);
    let a = farthest(&graph.distances(seed_vertex(surface)));
    let dist = graph.distances(a);
    let b = farthest(&dist);
    let span = dist[b];
    if span.is_nan() || span <= 0.0 {
        return Err(MeasureError::NotTubular(
            "the surface has no extent between its farthest vertices".into(),
        ));
    }
    let step = step.max(span / 2000.0);
    let reachable: Vec<(usize, [u32; 3])> = surface
        .triangles
        .iter()
        .copied()
        .enumerate()
        .filter(|(_, t)| t.iter().all(|&v| dist[v as usize].is_finite()))
        .collect();
    // Near an end the level sets are arcs around the end vertex, not rings around the tube:
    // a level is kept once it is farther than a ring diameter (perimeter / π) from both ends.
    let mut points = Vec::new();
    let mut level = step;
    while level < span {
        let within = reachable.iter().copied().filter(|(_, t)| {
            let (lo, hi) = t.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &v| {
                (lo.min(dist[v as usize]), hi.max(dist[v as usize]))
            });
            lo <= level && level <= hi
        });
        let rings = contours(within, &surface.positions, |v| dist[v as usize] - level);
        if let Some(ring) = rings
            .iter()
            .max_by(|x, y| x.length().total_cmp(&y.length()))
        {
            let diameter = ring.length() / std::f64::consts::PI;
            if ring.closed && level >= diameter && span - level >= diameter {
                points.push(ring.centroid());
            }
        }
        level += step;
    }
    if points.len() < 2 {
        return Err(MeasureError::NotTubular(format!(
            "the surface is no longer than it is wide (geodesic extent {span:.2} mm)"
        )));
    }
    Ok(Polyline::new(points))
}
