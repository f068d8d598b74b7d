//! The ends and branches of a vessel surface, found from its topology rather than from
//! distances: the level sets of the geodesic distance from one end are rings around the
//! tubes; where a branch leaves, one ring splits into two. Linking the rings of neighbouring
//! levels that the surface between them connects gives a tree (a discrete Reeb graph) whose
//! leaves are the vessel's ends. The two widest ends are the main vessel's; the others are
//! branches, ordered by where they leave the main path.

use std::collections::VecDeque;

use super::MeasureError;
use super::geodesic::{Graph, farthest, seed_vertex};
use super::sections::contours;
use super::surface::Surface;
use crate::geometry::mesh::{norm, sub};

/// One end of the vessel: the ring centres from the end inward (to the first junction).
#[derive(Debug, Clone, PartialEq)]
pub struct VesselEnd {
    /// Ring centroids, the first next to the end.
    pub centres: Vec<[f64; 3]>,
    /// Geodesic distance of each ring from the end's last ring, mm.
    pub depths: Vec<f64>,
    /// Median ring radius (perimeter / 2π) over the middle half of the chain, mm.
    pub radius_mm: f64,
}

/// The ends of a vessel: the two main ends and the branches in proximal-to-distal order.
#[derive(Debug, Clone, PartialEq)]
pub struct VesselEnds {
    /// The main end nearer to the branches (the ascending aorta); for a tube the wider end.
    pub proximal: VesselEnd,
    /// The other main end (the descending aorta).
    pub distal: VesselEnd,
    /// Branch ends ordered by where they leave the main path, from the proximal end on.
    pub branches: Vec<VesselEnd>,
    /// The rings along the main path, from the proximal end to the distal one: a first
    /// guess of the main vessel's centreline that never turns into a branch.
    pub main_path: Vec<PathRing>,
}

/// One ring of the main path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathRing {
    /// Centroid of the ring's curve.
    pub centre: [f64; 3],
    /// Perimeter / 2π, mm: the tube's radius where the ring goes round it, less over an end
    /// cap.
    pub radius_mm: f64,
    /// Whether the ring splits or merges with another between its level and the next: it
    /// goes round the main vessel and a branch's base, its centroid off the main axis.
    pub junction: bool,
}

/// A ring: one connected curve of a level set.
struct Ring {
    level: usize,
    centroid: [f64; 3],
    perimeter: f64,
    faces: Vec<usize>,
}

/// Rings linked to the rings of the neighbouring levels.
struct RingGraph {
    rings: Vec<Ring>,
    links: Vec<Vec<usize>>,
    spacing: f64,
}

/// Finds the ends of `surface` with level sets every `spacing` mm.
pub fn vessel_ends(surface: &Surface, spacing: f64) -> Result<VesselEnds, MeasureError> {
    let graph = build(surface, spacing)?;
    let mut alive = vec![true; graph.rings.len()];
    let ends = prune(&graph, &mut alive);
    if ends.len() < 2 {
        return Err(MeasureError::NotTubular(format!(
            "the surface has {} end(s); a vessel has at least two",
            ends.len()
        )));
    }
    let chains: Vec<Chain> = ends.iter().map(|&e| chain(&graph, &alive, e)).collect();
    let mut by_width: Vec<usize> = (0..chains.len()).collect();
    by_width.sort_by(|&a, &b| chains[b].radius.total_cmp(&chains[a].radius));
    let (a, b) = (by_width[0], by_width[1]);
    let path = shortest_path(&graph, &alive, chains[a].nodes[0], chains[b].nodes[0])
        .ok_or_else(|| MeasureError::NotTubular("the main ends are not connected".into()))?;
    let along = cumulative(&graph, &path);
    let mut branches: Vec<(f64, usize)> = by_width[2..]
        .iter()
        .map(|&c| {
            (
                attach_position(&graph, &alive, &chains[c], &path, &along),
                c,
            )
        })
        .collect();
    branches.sort_by(|x, y| x.0.total_cmp(&y.0));
    let total = along.last().copied().unwrap_or(0.0);
    // The ascending aorta is short next to the descending one: the branches sit nearer to it.
    let a_is_proximal = match branches.first() {
        Some(&(first, _)) => {
            let last = branches.last().map_or(first, |b| b.0);
            first <= total - last
        }
        None => true,
    };
    let (proximal, distal) = if a_is_proximal { (a, b) } else { (b, a) };
    let mut main_path: Vec<PathRing> = path
        .iter()
        .map(|&n| PathRing {
            centre: graph.rings[n].centroid,
            radius_mm: graph.rings[n].perimeter / std::f64::consts::TAU,
            junction: live_links(&graph, &alive, n).count() > 2,
        })
        .collect();
    if !a_is_proximal {
        branches.reverse();
        main_path.reverse();
    }
    Ok(VesselEnds {
        proximal: chains[proximal].to_end(&graph),
        distal: chains[distal].to_end(&graph),
        branches: branches
            .iter()
            .map(|&(_, c)| chains[c].to_end(&graph))
            .collect(),
        main_path,
    })
}

/// Level-set rings of the geodesic distance from a vessel end, linked across levels.
fn build(surface: &Surface, spacing: f64) -> Result<RingGraph, MeasureError> {
    let edges = Graph::new(surface);
    let seed = farthest(&edges.distances(seed_vertex(surface)));
    let d = edges.distances(seed);
    let span = d
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max);
    let levels = (span / spacing - 0.5).floor().max(0.0) as usize;
    if levels < 4 {
        return Err(MeasureError::NotTubular(format!(
            "the surface spans only {span:.1} mm between its farthest points"
        )));
    }
    let level_at = |k: usize| (k as f64 + 0.5) * spacing;
    // The levels L_k each triangle meets.
    let range = |lo: f64, hi: f64| {
        let first = (lo / spacing - 0.5).ceil().max(0.0) as usize;
        let last = ((hi / spacing - 0.5).floor().max(-1.0) + 1.0) as usize;
        first..last.min(levels)
    };
    let tris = &surface.triangles;
    let reach = |t: &[u32; 3]| t.iter().all(|&v| d[v as usize].is_finite());
    let extent = |t: &[u32; 3]| {
        t.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &v| {
            (lo.min(d[v as usize]), hi.max(d[v as usize]))
        })
    };
    let mut at_level: Vec<Vec<usize>> = vec![Vec::new(); levels];
    for (i, t) in tris.iter().enumerate().filter(|(_, t)| reach(t)) {
        let (lo, hi) = extent(t);
        for k in range(lo, hi) {
            at_level[k].push(i);
        }
    }
    let mut rings = Vec::new();
    let mut first_ring = vec![0usize; levels + 1];
    for (k, faces) in at_level.iter().enumerate() {
        first_ring[k] = rings.len();
        let level = level_at(k);
        for c in contours(
            faces.iter().map(|&f| (f, tris[f])),
            &surface.positions,
            |v| d[v as usize] - level,
        ) {
            rings.push(Ring {
                level: k,
                centroid: c.centroid(),
                perimeter: c.length(),
                faces: c.faces,
            });
        }
    }
    first_ring[levels] = rings.len();
    let links = link_levels(surface, &d, &rings, &first_ring, spacing, levels);
    Ok(RingGraph {
        rings,
        links,
        spacing,
    })
}

/// Links rings of levels k and k + 1 that the surface between the two levels connects.
fn link_levels(
    surface: &Surface,
    d: &[f64],
    rings: &[Ring],
    first_ring: &[usize],
    spacing: f64,
    levels: usize,
) -> Vec<Vec<usize>> {
    let adjacency = face_adjacency(&surface.triangles);
    let mut bands: Vec<Vec<(usize, usize)>> = vec![Vec::new(); levels];
    for &(a, b, f, g) in &adjacency {
        let (lo, hi) = (
            d[a as usize].min(d[b as usize]),
            d[a as usize].max(d[b as usize]),
        );
        if !hi.is_finite() {
            continue;
        }
        let first = (lo / spacing - 1.5).ceil().max(0.0) as usize;
        let last = ((hi / spacing - 0.5).floor() + 1.0).max(0.0) as usize;
        for band in bands.iter_mut().take(last.min(levels)).skip(first) {
            band.push((f, g));
        }
    }
    let mut parent: Vec<usize> = (0..surface.triangles.len()).collect();
    let mut links = vec![Vec::new(); rings.len()];
    for k in 0..levels.saturating_sub(1) {
        for &(f, g) in &bands[k] {
            let (rf, rg) = (find(&mut parent, f), find(&mut parent, g));
            parent[rf] = rg;
        }
        for lower in first_ring[k]..first_ring[k + 1] {
            let root = find(&mut parent, rings[lower].faces[0]);
            for upper in first_ring[k + 1]..first_ring[k + 2] {
                if find(&mut parent, rings[upper].faces[0]) == root {
                    links[lower].push(upper);
                    links[upper].push(lower);
                }
            }
        }
        // Reset the faces this band touched before the next band.
        for &(f, g) in &bands[k] {
            parent[f] = f;
            parent[g] = g;
        }
    }
    links
}

fn find(parent: &mut [usize], mut x: usize) -> usize {
    while parent[x] != x {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    x
}

/// Interior edges as (a, b, face, face).
fn face_adjacency(triangles: &[[u32; 3]]) -> Vec<(u32, u32, usize, usize)> {
    let mut half: Vec<(u32, u32, usize)> = triangles
        .iter()
        .enumerate()
        .flat_map(|(i, t)| (0..3).map(move |k| (t[k], t[(k + 1) % 3], i)))
        .map(|(a, b, i)| (a.min(b), a.max(b), i))
        .collect();
    half.sort_unstable();
    half.windows(2)
        .filter(|w| w[0].0 == w[1].0 && w[0].1 == w[1].1)
        .map(|w| (w[0].0, w[0].1, w[0].2, w[1].2))
        .collect()
}

/// A chain of rings from an end to its first junction.
struct Chain {
    nodes: Vec<usize>,
    radius: f64,
}

impl Chain {
    fn to_end(&self, graph: &RingGraph) -> VesselEnd {
        let base = graph.rings[self.nodes[0]].level as f64;
        VesselEnd {
            centres: self
                .nodes
                .iter()
                .map(|&n| graph.rings[n].centroid)
                .collect(),
            depths: self
                .nodes
                .iter()
                .map(|&n| (graph.rings[n].level as f64 - base).abs() * graph.spacing)
                .collect(),
            radius_mm: self.radius,
        }
    }
}

fn live_links<'a>(
    graph: &'a RingGraph,
    alive: &'a [bool],
    n: usize,
) -> impl Iterator<Item = usize> + 'a {
    graph.links[n].iter().copied().filter(|&m| alive[m])
}

/// The chain from end `start` inward while the rings neither split nor merge.
fn chain(graph: &RingGraph, alive: &[bool], start: usize) -> Chain {
    let mut nodes = vec![start];
    let (mut prev, mut cur) = (usize::MAX, start);
    loop {
        let next: Vec<usize> = live_links(graph, alive, cur)
            .filter(|&m| m != prev)
            .collect();
        // Stop before a ring that splits, merges or is another end.
        let [n] = next[..] else { break };
        if live_links(graph, alive, n).count() != 2 {
            break;
        }
        nodes.push(n);
        (prev, cur) = (cur, n);
    }
    let mut radii: Vec<f64> = nodes
        .iter()
        .map(|&n| graph.rings[n].perimeter / std::f64::consts::TAU)
        .collect();
    let (q1, q3) = (radii.len() / 4, (3 * radii.len()).div_ceil(4).max(1));
    let middle = &mut radii[q1..q3.max(q1 + 1).min(nodes.len())];
    middle.sort_by(f64::total_cmp);
    let radius = middle[middle.len() / 2];
    Chain { nodes, radius }
}

/// Shortest end kept, mm: shorter ones are bumps of the wall (the level sets of a bump close
/// within a few levels), not vessels.
const MIN_END_LENGTH: f64 = 4.0;

/// Removes ends shorter than [`MIN_END_LENGTH`] until every remaining end is a real one;
/// returns the remaining ends.
fn prune(graph: &RingGraph, alive: &mut [bool]) -> Vec<usize> {
    loop {
        let ends: Vec<usize> = (0..graph.rings.len())
            .filter(|&n| alive[n] && live_links(graph, alive, n).count() == 1)
            .collect();
        let short: Vec<Chain> = ends
            .iter()
            .map(|&e| chain(graph, alive, e))
            .filter(|c| {
                c.nodes.len() as f64 * graph.spacing < MIN_END_LENGTH.max(3.0 * graph.spacing)
            })
            .collect();
        // Never prune below two ends: a short tube is still a tube.
        if short.is_empty() || ends.len() <= 2 {
            return ends;
        }
        for c in short {
            for n in c.nodes {
                alive[n] = false;
            }
        }
    }
}

fn shortest_path(graph: &RingGraph, alive: &[bool], from: usize, to: usize) -> Option<Vec<usize>> {
    let mut back = vec![usize::MAX; graph.rings.len()];
    let mut queue = VecDeque::from([from]);
    back[from] = from;
    while let Some(n) = queue.pop_front() {
        if n == to {
            let mut path = vec![to];
            while *path.last()? != from {
                path.push(back[*path.last()?]);
            }
            path.reverse();
            return Some(path);
        }
        for m in live_links(graph, alive, n) {
            if back[m] == usize::MAX {
                back[m] = n;
                queue.push_back(m);
            }
        }
    }
    None
}

fn cumulative(graph: &RingGraph, path: &[usize]) -> Vec<f64> {
    let mut s = vec![0.0];
    for w in path.windows(2) {
        let step = norm(sub(graph.rings[w[1]].centroid, graph.rings[w[0]].centroid));
        s.push(s[s.len() - 1] + step);
    }
    s
}

/// Arc length along the main path where a branch chain joins it.
fn attach_position(
    graph: &RingGraph,
    alive: &[bool],
    branch: &Chain,
    path: &[usize],
    along: &[f64],
) -> f64 {
    let last = branch.nodes[branch.nodes.len() - 1];
    let on_path = |n: usize| path.iter().position(|&p| p == n);
    let mut seen = vec![false; graph.rings.len()];
    let mut queue = VecDeque::from([last]);
    seen[last] = true;
    while let Some(n) = queue.pop_front() {
        if let Some(i) = on_path(n) {
            return along[i];
        }
        for m in live_links(graph, alive, n) {
            if !seen[m] {
                seen[m] = true;
                queue.push_back(m);
            }
        }
    }
    f64::INFINITY
}
