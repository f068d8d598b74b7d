//! Cutting a closed vessel surface open at its openings: each plane removes only the end
//! beyond it that the section loop around the opening's centre bounds (the same plane may
//! cross the other limb of an arch or a branch elsewhere; those stay). New vertices lie on
//! the plane; the result has one boundary loop per opening.

use std::collections::{HashMap, HashSet, VecDeque};

use super::SimulationError;
use super::opening::Opening;
use crate::anatomy::sections::{PlaneFrame, contours, polygon_area_centroid, polygon_contains};
use crate::geometry::mesh::{norm, sub};

/// Vertices closer to the plane than this fraction of the mean edge length are moved onto
/// it, so the cut never makes slivers next to a vertex.
const SNAP_FRACTION: f64 = 0.05;

/// A surface in f64 being cut.
#[derive(Debug, Clone, PartialEq)]
pub struct OpenSurface {
    /// Vertex positions, mm.
    pub positions: Vec<[f64; 3]>,
    /// Outward triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Face id of each triangle (the wall, or a flow extension).
    pub face_ids: Vec<u32>,
    /// Per opening (in the order given), its boundary loop in the direction the wall's
    /// triangles run along it.
    pub loops: Vec<Vec<u32>>,
}

/// Cuts `positions`/`triangles` (closed or open, outward) at every opening.
pub fn cut_openings(
    positions: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    openings: &[Opening],
) -> Result<OpenSurface, SimulationError> {
    let mut surface = OpenSurface {
        positions,
        triangles,
        face_ids: Vec::new(),
        loops: Vec::new(),
    };
    let snap = SNAP_FRACTION * mean_edge_length(&surface.positions, &surface.triangles);
    for opening in openings {
        cut_one(&mut surface, opening, snap)?;
    }
    compact(&mut surface);
    surface.face_ids = vec![super::WALL_ID; surface.triangles.len()];
    surface.loops = assign_loops(&surface, openings)?;
    Ok(surface)
}

fn mean_edge_length(p: &[[f64; 3]], t: &[[u32; 3]]) -> f64 {
    let total: f64 = t
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
        .map(|(a, b)| norm(sub(p[a as usize], p[b as usize])))
        .sum();
    total / (3 * t.len().max(1)) as f64
}

/// The faces crossed by the closed section loop that surrounds the opening's centre (the
/// smallest one if several do).
fn loop_faces(
    s: &OpenSurface,
    frame: &PlaneFrame,
    heights: &[f64],
    name: &str,
) -> Result<Vec<usize>, SimulationError> {
    let crossing = s.triangles.iter().enumerate().filter_map(|(i, t)| {
        let positive = t.iter().filter(|&&v| heights[v as usize] >= 0.0).count();
        (positive == 1 || positive == 2).then_some((i, *t))
    });
    let mut best: Option<(f64, Vec<usize>)> = None;
    for c in contours(crossing, &s.positions, |v| heights[v as usize]) {
        let q: Vec<[f64; 2]> = c.points.iter().map(|&p| frame.project(p)).collect();
        if !c.closed || q.len() < 3 || !polygon_contains(&q, [0.0, 0.0]) {
            continue;
        }
        let area = polygon_area_centroid(&q).0.abs();
        if best.as_ref().is_none_or(|(a, _)| area < *a) {
            best = Some((area, c.faces));
        }
    }
    best.map(|(_, f)| f)
        .ok_or_else(|| SimulationError::CutMissesSurface {
            opening: name.to_owned(),
            message: "no closed section loop of the plane surrounds the opening's centre".into(),
        })
}

fn cut_one(s: &mut OpenSurface, opening: &Opening, snap: f64) -> Result<(), SimulationError> {
    let frame = PlaneFrame::new(opening.origin, opening.normal);
    let mut h: Vec<f64> = s.positions.iter().map(|&p| frame.height(p)).collect();
    let faces = loop_faces(s, &frame, &h, &opening.name)?;
    for &f in &faces {
        for v in s.triangles[f] {
            let v = v as usize;
            if h[v].abs() < snap {
                s.positions[v] =
                    std::array::from_fn(|i| s.positions[v][i] - h[v] * frame.normal[i]);
                h[v] = 0.0;
            }
        }
    }
    let removed = beyond(s, &h, &faces);
    let loop_set: HashSet<usize> = faces.iter().copied().collect();
    let crosses = |t: &[u32; 3]| {
        t.iter().any(|&v| h[v as usize] < 0.0) && t.iter().any(|&v| h[v as usize] > 0.0)
    };
    if let Some(&stray) = removed
        .iter()
        .find(|&&t| crosses(&s.triangles[t]) && !loop_set.contains(&t))
    {
        let at = s.triangles[stray].map(|v| s.positions[v as usize]);
        return Err(SimulationError::CutNotLocal {
            opening: opening.name.clone(),
            message: format!(
                "beyond the opening the plane also crosses the surface near ({:.1}, {:.1}, \
                 {:.1}); move the opening farther from the other vessel",
                at[0][0], at[0][1], at[0][2]
            ),
        });
    }
    clip(s, &h, &frame, &removed.into_iter().collect());
    Ok(())
}

/// Triangles with a part beyond the plane that connect to the loop's faces without
/// crossing the plane.
fn beyond(s: &OpenSurface, h: &[f64], seeds: &[usize]) -> Vec<usize> {
    let mut by_edge: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (i, t) in s.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            by_edge.entry((a.min(b), a.max(b))).or_default().push(i);
        }
    }
    let positive = |t: usize| s.triangles[t].iter().any(|&v| h[v as usize] > 0.0);
    // Start from every triangle beyond the plane at a vertex of the loop's faces: when the
    // loop runs through vertices on the plane, its own faces may lie wholly on the kept side.
    let loop_vertices: HashSet<u32> = seeds.iter().flat_map(|&t| s.triangles[t]).collect();
    let mut seen: HashSet<usize> = (0..s.triangles.len())
        .filter(|&t| positive(t) && s.triangles[t].iter().any(|v| loop_vertices.contains(v)))
        .collect();
    let mut queue: VecDeque<usize> = seen.iter().copied().collect();
    while let Some(t) = queue.pop_front() {
        let tri = s.triangles[t];
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            if h[a as usize].max(h[b as usize]) <= 0.0 {
                continue;
            }
            for &n in &by_edge[&(a.min(b), a.max(b))] {
                if positive(n) && seen.insert(n) {
                    queue.push_back(n);
                }
            }
        }
    }
    let mut out: Vec<usize> = seen.into_iter().collect();
    out.sort_unstable();
    out
}

/// Replaces the removed triangles by their parts on the kept side (h ≤ 0).
fn clip(s: &mut OpenSurface, h: &[f64], frame: &PlaneFrame, removed: &HashSet<usize>) {
    let mut cut_vertex: HashMap<(u32, u32), u32> = HashMap::new();
    let mut kept = Vec::with_capacity(s.triangles.len());
    let old = std::mem::take(&mut s.triangles);
    for (i, t) in old.into_iter().enumerate() {
        if !removed.contains(&i) {
            kept.push(t);
            continue;
        }
        let mut polygon: Vec<u32> = Vec::with_capacity(4);
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let (ha, hb) = (h[a as usize], h[b as usize]);
            if ha <= 0.0 {
                polygon.push(a);
            }
            if (ha < 0.0 && hb > 0.0) || (ha > 0.0 && hb < 0.0) {
                let key = (a.min(b), a.max(b));
                let v = *cut_vertex.entry(key).or_insert_with(|| {
                    let (pa, pb) = (s.positions[a as usize], s.positions[b as usize]);
                    let lambda = ha / (ha - hb);
                    let p: [f64; 3] = std::array::from_fn(|c| pa[c] + lambda * (pb[c] - pa[c]));
                    let off = frame.height(p);
                    s.positions
                        .push(std::array::from_fn(|c| p[c] - off * frame.normal[c]));
                    (s.positions.len() - 1) as u32
                });
                polygon.push(v);
            }
        }
        if polygon
            .iter()
            .any(|&v| (v as usize) < h.len() && h[v as usize] < 0.0)
        {
            for j in 1..polygon.len().saturating_sub(1) {
                kept.push([polygon[0], polygon[j], polygon[j + 1]]);
            }
        }
    }
    s.triangles = kept;
}

/// Drops vertices no triangle uses.
fn compact(s: &mut OpenSurface) {
    let mut map = vec![u32::MAX; s.positions.len()];
    let mut positions = Vec::with_capacity(s.positions.len());
    for t in &mut s.triangles {
        for v in t.iter_mut() {
            if map[*v as usize] == u32::MAX {
                map[*v as usize] = positions.len() as u32;
                positions.push(s.positions[*v as usize]);
            }
            *v = map[*v as usize];
        }
    }
    s.positions = positions;
}

/// Boundary loops as the wall's triangles traverse them (each directed edge a → b used
/// once, its reverse not at all).
pub fn boundary_loops(triangles: &[[u32; 3]]) -> Result<Vec<Vec<u32>>, SimulationError> {
    let mut directed: HashSet<(u32, u32)> = HashSet::new();
    for t in triangles {
        for k in 0..3 {
            directed.insert((t[k], t[(k + 1) % 3]));
        }
    }
    let mut next: HashMap<u32, u32> = HashMap::new();
    let mut starts: Vec<u32> = Vec::new();
    for &(a, b) in &directed {
        if !directed.contains(&(b, a)) {
            if next.insert(a, b).is_some() {
                return Err(SimulationError::Topology(format!(
                    "vertex {a} starts two boundary edges (a pinched boundary)"
                )));
            }
            starts.push(a);
        }
    }
    starts.sort_unstable();
    let mut seen: HashSet<u32> = HashSet::new();
    let mut loops = Vec::new();
    for start in starts {
        if seen.contains(&start) {
            continue;
        }
        let mut ring = vec![start];
        seen.insert(start);
        let mut cur = next[&start];
        while cur != start {
            if !seen.insert(cur) {
                return Err(SimulationError::Topology(
                    "a boundary loop is not simple".into(),
                ));
            }
            ring.push(cur);
            cur = *next.get(&cur).ok_or_else(|| {
                SimulationError::Topology("a boundary edge chain does not close".into())
            })?;
        }
        loops.push(ring);
    }
    Ok(loops)
}

/// Matches every boundary loop to the opening whose plane holds it.
fn assign_loops(s: &OpenSurface, openings: &[Opening]) -> Result<Vec<Vec<u32>>, SimulationError> {
    let mut out: Vec<Option<Vec<u32>>> = vec![None; openings.len()];
    for ring in boundary_loops(&s.triangles)? {
        let off_plane = |o: &Opening| {
            let frame = PlaneFrame::new(o.origin, o.normal);
            ring.iter()
                .map(|&v| frame.height(s.positions[v as usize]).abs())
                .fold(0.0, f64::max)
        };
        let owner = (0..openings.len())
            .filter(|&i| off_plane(&openings[i]) < 1e-6 * (1.0 + openings[i].radius_mm))
            .min_by(|&a, &b| {
                let d = |i: usize| norm(sub(s.positions[ring[0] as usize], openings[i].origin));
                d(a).total_cmp(&d(b))
            });
        match owner {
            Some(i) if out[i].is_none() => out[i] = Some(ring),
            Some(i) => {
                return Err(SimulationError::Topology(format!(
                    "opening `{}` has more than one boundary loop",
                    openings[i].name
                )));
            }
            None => {
                return Err(SimulationError::Topology(format!(
                    "the surface has a hole of {} vertices that is no opening",
                    ring.len()
                )));
            }
        }
    }
    out.into_iter()
        .zip(openings)
        .map(|(ring, o)| {
            ring.ok_or_else(|| {
                SimulationError::Topology(format!("opening `{}` has no loop", o.name))
            })
        })
        .collect()
}
