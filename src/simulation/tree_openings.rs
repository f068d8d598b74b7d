//! Openings of a branched aorta or a plain tube, placed a stated distance in from each end:
//! the ends come from the vessel's level-set tree ([`crate::anatomy::vessel_tree`]), the planes from
//! sections of the lumen near each end, perpendicular to the local centreline.

use super::SimulationError;
use super::opening::{FIRST_OUTLET_ID, INLET_ID, Opening, OpeningOptions, ShapeKind};
use crate::anatomy::MeasureError;
use crate::anatomy::geodesic::Graph;
use crate::anatomy::sections::contours;
use crate::anatomy::surface::Surface;
use crate::anatomy::vessel_tree::{self, VesselEnd, VesselEnds};
use crate::geometry::mesh::{dot, norm, normalized, sub};

/// Refinement passes of an end plane (each re-centres the plane and re-measures the tangent).
const PASSES: usize = 6;

/// The vessel's ends ([`vessel_tree::vessel_ends`]); a surface without two ends has no
/// openings to place.
pub fn vessel_ends(surface: &Surface, spacing: f64) -> Result<VesselEnds, SimulationError> {
    vessel_tree::vessel_ends(surface, spacing).map_err(|e| match e {
        MeasureError::NotTubular(why) => SimulationError::OpeningsNotFound(why),
        other => SimulationError::Measure(other),
    })
}

/// Openings of an aorta (inlet, descending outlet, one outlet per branch) or of a tube
/// (inlet at the wider end, outlet at the other; a tube with branches is refused).
pub fn tree_openings(
    surface: &Surface,
    kind: ShapeKind,
    opts: &OpeningOptions,
) -> Result<Vec<Opening>, SimulationError> {
    opts.validate()?;
    let ends = vessel_ends(surface, opts.ring_spacing_mm)?;
    let graph = Graph::new(surface);
    check_branches(&ends, kind)?;
    let (inlet, outlet) = match kind {
        ShapeKind::Aorta => ("inlet", "outlet_descending"),
        _ => ("inlet", "outlet"),
    };
    let mut out = vec![
        end_opening(
            surface,
            &graph,
            &ends.proximal,
            opts.end_trim_mm,
            INLET_ID,
            inlet,
        )?,
        end_opening(
            surface,
            &graph,
            &ends.distal,
            opts.end_trim_mm,
            FIRST_OUTLET_ID,
            outlet,
        )?,
    ];
    for (k, branch) in ends.branches.iter().enumerate() {
        let name = format!("branch_{}", k + 1);
        let id = FIRST_OUTLET_ID + 1 + k as u32;
        out.push(end_opening(
            surface,
            &graph,
            branch,
            opts.branch_trim_mm,
            id,
            &name,
        )?);
    }
    Ok(out)
}

fn check_branches(ends: &VesselEnds, kind: ShapeKind) -> Result<(), SimulationError> {
    match (kind, ends.branches.len()) {
        (ShapeKind::Tube, n) if n > 0 => Err(SimulationError::OpeningsNotFound(format!(
            "a tube has two ends, this surface has {}",
            n + 2
        ))),
        (ShapeKind::Aorta, 0) => Err(SimulationError::OpeningsNotFound(
            "no branch leaves the main vessel: not a branched aorta".into(),
        )),
        _ => Ok(()),
    }
}

/// The plane `trim` mm in from the end: section centroids a little before and after it give
/// the tangent, the ray along it the distance to where the centreline leaves the vessel.
fn end_opening(
    surface: &Surface,
    graph: &Graph,
    end: &VesselEnd,
    trim: f64,
    id: u32,
    name: &str,
) -> Result<Opening, SimulationError> {
    let lost = |message: String| SimulationError::OutsideVessel {
        opening: name.to_owned(),
        message,
    };
    let reach = end.depths.last().copied().unwrap_or(0.0);
    let (mut p, mut t) = match first_frame(surface, graph, end, trim) {
        Some(frame) => frame,
        None => {
            let start = end.depths.len() / 2;
            let ahead = (start + 1).min(end.centres.len() - 1);
            (
                end.centres[start],
                normalized(sub(
                    end.centres[start.saturating_sub(2)],
                    end.centres[ahead],
                )),
            )
        }
    };
    if dot(t, t) == 0.0 {
        return Err(lost("the end is too short to find its direction".into()));
    }
    let delta = (0.35 * end.radius_mm).min(0.4 * trim).max(0.1);
    let too_short = || {
        lost(format!(
            "no closed wall section {trim:.1} mm from the end (the vessel there is about \
             {reach:.1} mm long before it meets another)"
        ))
    };
    for _ in 0..PASSES {
        let exit = surface
            .ray_hit(p, t)
            .ok_or_else(|| lost("the centreline does not leave the vessel here".into()))?;
        p = std::array::from_fn(|i| p[i] + (exit - trim) * t[i]);
        let at = |q: [f64; 3], dir: [f64; 3]| surface.wall_section_at(q, dir);
        p = at(p, t).ok_or_else(too_short)?.centroid;
        let shifted = |s: f64| std::array::from_fn(|i| p[i] + s * t[i]);
        let (Some(behind), Some(front)) = (at(shifted(-delta), t), at(shifted(delta), t)) else {
            return Err(too_short());
        };
        let next = normalized(sub(front.centroid, behind.centroid));
        if dot(next, t) < 0.5 {
            return Err(lost("the centreline turns back near the end".into()));
        }
        t = next;
    }
    let exit = surface.ray_hit(p, t).ok_or_else(too_short)?;
    p = std::array::from_fn(|i| p[i] + (exit - trim) * t[i]);
    let section = surface
        .wall_section_at(p, t)
        .ok_or_else(|| lost(format!("no closed wall section {trim:.1} mm from the end")))?;
    Ok(Opening {
        id,
        name: name.to_owned(),
        origin: section.centroid,
        normal: t,
        radius_mm: (section.area / std::f64::consts::PI).sqrt(),
    })
}

/// A first centre and direction (towards the end) from rings of the geodesic distance from
/// the end's own tip, which near the end cross the vessel almost perpendicularly (the rings
/// of the tree's single distance run obliquely through bends and near flat ends).
fn first_frame(
    surface: &Surface,
    graph: &Graph,
    end: &VesselEnd,
    trim: f64,
) -> Option<([f64; 3], [f64; 3])> {
    let near = end.centres[0];
    let tip = (0..surface.positions.len()).min_by(|&a, &b| {
        let d = |v: usize| norm(sub(surface.positions[v], near));
        d(a).total_cmp(&d(b))
    })?;
    let d = graph.distances(tip);
    let ring = |level: f64| -> Option<[f64; 3]> {
        let crossing = surface.triangles.iter().enumerate().filter(|(_, t)| {
            let (lo, hi) = t.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &v| {
                (lo.min(d[v as usize]), hi.max(d[v as usize]))
            });
            lo <= level && level <= hi
        });
        contours(crossing.map(|(i, t)| (i, *t)), &surface.positions, |v| {
            d[v as usize] - level
        })
        .into_iter()
        .filter(|c| c.closed)
        .map(|c| c.centroid())
        .min_by(|a, b| norm(sub(*a, near)).total_cmp(&norm(sub(*b, near))))
    };
    let (depth, step) = (trim + end.radius_mm, 0.35 * end.radius_mm);
    let (inner, centre, outer) = (ring(depth + step)?, ring(depth)?, ring(depth - step)?);
    Some((centre, normalized(sub(outer, inner))))
}
