//! Flow extensions: a straight cylinder appended at an opening so that the flow develops
//! before it reaches the region of interest. The extension starts from the opening's own
//! boundary loop, blends its shape into a circle of the loop's equivalent radius over the
//! first diameter (smoothstep, so the wall turns into the cylinder without a kink), then
//! runs straight along the opening's normal; the cap moves to the far end. Extension walls
//! get their own face ids ([`EXTENSION_BASE`] + the opening's id, named
//! `<opening>_extension`) so that solvers can treat them as wall or leave them out.

use super::SimulationError;
use super::cut::OpenSurface;
use super::opening::Opening;
use crate::anatomy::sections::{PlaneFrame, polygon_area_centroid};
use crate::geometry::mesh::{norm, sub};

/// Face id offset of flow-extension walls.
pub const EXTENSION_BASE: u32 = 100;

/// Appends an extension of `diameters` × the opening's diameter at every loop of `open`;
/// returns the openings moved to the extensions' far ends.
pub fn extend_openings(
    open: &mut OpenSurface,
    openings: &[Opening],
    diameters: f64,
) -> Result<Vec<Opening>, SimulationError> {
    let mut moved = Vec::with_capacity(openings.len());
    for (k, opening) in openings.iter().enumerate() {
        let ring = open.loops[k].clone();
        let (far, radius, origin) = extend_one(open, &ring, opening, diameters);
        open.loops[k] = far;
        moved.push(Opening {
            origin,
            radius_mm: radius,
            ..opening.clone()
        });
    }
    Ok(moved)
}

fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Builds one extension; returns its far loop (running like `ring`), its radius and the
/// centre of its far end.
fn extend_one(
    open: &mut OpenSurface,
    ring: &[u32],
    opening: &Opening,
    diameters: f64,
) -> (Vec<u32>, f64, [f64; 3]) {
    let frame = PlaneFrame::new(opening.origin, opening.normal);
    let q: Vec<[f64; 2]> = ring
        .iter()
        .map(|&v| frame.project(open.positions[v as usize]))
        .collect();
    let (area, c) = polygon_area_centroid(&q);
    let radius = (area.abs() / std::f64::consts::PI).sqrt();
    let n = q.len();
    // Target angles evenly spaced, running the way the loop runs, with the smallest twist.
    let direction = if area > 0.0 { 1.0 } else { -1.0 };
    let angle = |p: [f64; 2]| (p[1] - c[1]).atan2(p[0] - c[0]);
    let step = direction * std::f64::consts::TAU / n as f64;
    let (s, co) = q.iter().enumerate().fold((0.0, 0.0), |(s, co), (i, &p)| {
        let a = angle(p) - step * i as f64;
        (s + a.sin(), co + a.cos())
    });
    let start = s.atan2(co);
    let perimeter: f64 = (0..n)
        .map(|i| {
            norm(sub(
                open.positions[ring[i] as usize],
                open.positions[ring[(i + 1) % n] as usize],
            ))
        })
        .sum();
    let length = diameters * 2.0 * radius;
    let rings = ((length / (perimeter / n as f64)).ceil() as usize).max(2);
    let id = EXTENSION_BASE + opening.id;
    let mut previous: Vec<u32> = ring.to_vec();
    for j in 1..=rings {
        let z = length * j as f64 / rings as f64;
        let w = smoothstep(z / (2.0 * radius));
        let current: Vec<u32> = (0..n)
            .map(|i| {
                let a = start + step * i as f64;
                let target = [c[0] + radius * a.cos(), c[1] + radius * a.sin()];
                let p2 = [
                    (1.0 - w) * q[i][0] + w * target[0],
                    (1.0 - w) * q[i][1] + w * target[1],
                ];
                let base = frame.lift(p2);
                open.positions
                    .push(std::array::from_fn(|k| base[k] + z * frame.normal[k]));
                (open.positions.len() - 1) as u32
            })
            .collect();
        for i in 0..n {
            let (a, b) = (previous[i], previous[(i + 1) % n]);
            let (a2, b2) = (current[i], current[(i + 1) % n]);
            open.triangles.push([b, a, a2]);
            open.triangles.push([b, a2, b2]);
            open.face_ids.extend([id, id]);
        }
        previous = current;
    }
    let centre = frame.lift(c);
    let far = std::array::from_fn(|k| centre[k] + length * frame.normal[k]);
    (previous, radius, far)
}
