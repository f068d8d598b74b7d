//! Tracking the lumen station by station: from a start point inside the vessel, step along
//! the current tangent, cut the plane normal to it, move to the centroid of the section loop
//! around the stepped point and update the tangent from the path of centroids; stop where the
//! path leaves the vessel. Side branches and the other limb of an arch are separate loops and
//! are never followed.

use super::MeasureError;
use super::polyline::Polyline;
use super::surface::Surface;
use crate::geometry::mesh::{dot, norm, normalized, sub};

/// Start candidates along the rough centre line, as fractions of its length: the middle
/// first, then alternately further out (a start on a branch ostium is skipped).
const START_FRACTIONS: [f64; 7] = [0.5, 0.4, 0.6, 0.3, 0.7, 0.2, 0.8];

/// Section centroids from one end of the vessel to the other, and the two end points, found
/// by tracking both ways from a point of `rough` (a polyline roughly inside the lumen).
pub fn track(
    surface: &Surface,
    rough: &Polyline,
    step: f64,
    window: f64,
) -> Result<Polyline, MeasureError> {
    let length = rough.length();
    for fraction in START_FRACTIONS {
        let s = fraction * length;
        let (p, t) = rough.frame_at(s, window);
        let Some(section) = surface.wall_section_at(p, t) else {
            continue;
        };
        let c = section.centroid;
        let budget = (4.0 * length / step) as usize + 10;
        let forward = walk(surface, c, t, step, window, budget);
        let backward = walk(surface, c, t.map(|x| -x), step, window, budget);
        let mut points: Vec<[f64; 3]> = backward.into_iter().rev().collect();
        points.push(c);
        points.extend(forward);
        return Ok(Polyline::new(points));
    }
    Err(MeasureError::NotTubular(
        "no plane normal to the rough centreline cuts a closed wall section".into(),
    ))
}

/// Centroids (ending with the exit point) walking from `start` along `dir`.
fn walk(
    surface: &Surface,
    start: [f64; 3],
    dir: [f64; 3],
    step: f64,
    window: f64,
    budget: usize,
) -> Vec<[f64; 3]> {
    let lag = ((window / step).ceil() as usize).max(1);
    let mut path = vec![start];
    let mut t = dir;
    for _ in 0..budget {
        let c = path[path.len() - 1];
        if let Some(d) = surface.first_exit(c, t, step) {
            path.push(std::array::from_fn(|i| c[i] + d * t[i]));
            break;
        }
        let p: [f64; 3] = std::array::from_fn(|i| c[i] + step * t[i]);
        let Some(section) = surface.wall_section_at(p, t) else {
            // The plane reaches an end cap: finish along the tangent.
            let d = surface.first_exit(c, t, f64::INFINITY).unwrap_or(0.0);
            path.push(std::array::from_fn(|i| c[i] + d * t[i]));
            break;
        };
        path.push(section.centroid);
        let back = path[path.len().saturating_sub(1 + lag)];
        let chord = sub(section.centroid, back);
        if norm(chord) >= step {
            let next = normalized(chord);
            if dot(next, t) < 0.5 {
                break; // the path turned back on itself: lost the lumen
            }
            t = next;
        }
    }
    path.remove(0);
    path
}
