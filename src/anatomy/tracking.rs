//! Tracking the lumen station by station: from a start point inside the vessel, step along
//! the current tangent, cut the plane normal to it, move to the centroid of the section loop
//! around the stepped point and update the tangent from the path of centroids; stop where the
//! path leaves the vessel. Side branches and the other limb of an arch are separate loops and
//! are never followed.

use super::MeasureError;
use super::polyline::Polyline;
use super::surface::Surface;
use crate::geometry::mesh::{dot, norm, normalized, sub};

/// Where the trusted middle of the rough centre line may start, as fractions of its length
/// from either end (the first candidate that is not on a side-branch ostium is used): level
/// sets there are clean rings, also through an arch; the ends are tracked again.
const TRUSTED: [f64; 5] = [0.15, 0.2, 0.1, 0.25, 0.3];

/// Section centroids from one end of the vessel to the other, the first and last points being
/// where the path leaves the vessel: the trusted middle of `rough` (a polyline of level-set
/// centroids), continued at both ends by tracking the lumen to the vessel's ends.
pub fn track(
    surface: &Surface,
    rough: &Polyline,
    step: f64,
    window: f64,
) -> Result<Polyline, MeasureError> {
    let length = rough.length();
    // The first arc length (of the candidates) whose normal plane gives a wall section.
    let anchor = |fractions: &[f64]| {
        fractions.iter().find_map(|&f| {
            let (p, t) = rough.frame_at(f * length, window);
            surface.wall_section_at(p, t).map(|s| (f * length, s, t))
        })
    };
    let first = anchor(&TRUSTED.map(|f| f));
    let last = anchor(&TRUSTED.map(|f| 1.0 - f));
    let (Some((lo, start, t0)), Some((hi, end, t1))) = (first, last) else {
        return Err(MeasureError::NotTubular(
            "no plane normal to the rough centreline cuts a closed wall section".into(),
        ));
    };
    let budget = (4.0 * length / step) as usize + 10;
    let before = walk(
        surface,
        start.centroid,
        t0.map(|x| -x),
        step,
        window,
        budget,
    );
    let after = walk(surface, end.centroid, t1, step, window, budget);
    let mut points: Vec<[f64; 3]> = before.into_iter().rev().collect();
    points.push(start.centroid);
    let middle = rough
        .points()
        .iter()
        .zip(rough.arc_lengths())
        .filter(|&(_, &s)| s > lo + step && s < hi - step)
        .map(|(p, _)| *p);
    points.extend(middle);
    points.push(end.centroid);
    points.extend(after);
    Ok(Polyline::new(points))
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
        // A plane through a side-branch ostium gives no wall section: look further ahead
        // (up to `window`) before concluding that the vessel ends here.
        let ahead = (1..=lag.max(2)).find_map(|k| {
            let d = k as f64 * step;
            if k > 1 && surface.first_exit(c, t, d).is_some() {
                return Some(None);
            }
            let p: [f64; 3] = std::array::from_fn(|i| c[i] + d * t[i]);
            surface.wall_section_at(p, t).map(Some)
        });
        let Some(Some(section)) = ahead else {
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
