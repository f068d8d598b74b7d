//! Anatomical measurements of vessel surfaces in millimetres: a centreline with its length
//! and diameter profile for any tubular surface, and the clinical landmarks of an aortic root
//! (annulus, sinus of Valsalva, sinotubular junction, sinus height, ascending aorta).
//!
//! Method (docs/MEASUREMENTS.md has the details and the validation):
//! 1. first guess: for a vessel with branches, the ring centroids along the main path of its
//!    level-set tree ([`vessel_tree`]), from the proximal end; otherwise the ends are the
//!    geodesically farthest vertex pair and the centre points the centroids of the level sets
//!    of the geodesic distance from one end ([`geodesic`]);
//! 2. refinement: at evenly spaced stations the surface is cut by the plane normal to the
//!    smoothed centreline, the closed loop surrounding the centre point is kept (other loops
//!    — the other limb of an arch, a side branch — are ignored) and its area centroid becomes
//!    the new centre point; repeated until the centres stop moving ([`centreline`]);
//! 3. the converged centreline is cut once more at the reported stations ([`measure_vessel`]);
//! 4. for roots, landmarks are found on the diameter profile alone ([`root`]).

pub mod centreline;
pub mod geodesic;
pub mod measurement;
pub mod polyline;
pub mod root;
pub mod sections;
pub mod shape;
pub mod surface;
pub mod tracking;
pub mod vessel_tree;

#[cfg(test)]
mod tests;

use serde::{Deserialize, Serialize};

use crate::geometry::MeshError;
use polyline::Polyline;
pub use root::{RootLandmarks, measure_root, measure_root_with_landmarks};
use surface::Surface;

/// One cross-section of the vessel, normal to the centreline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Station {
    /// Arc length along the centreline from its start.
    pub s_mm: f64,
    /// Centreline point (the cutting plane passes through it).
    pub centre: [f64; 3],
    /// Unit centreline tangent (the cutting plane's normal), pointing towards larger `s_mm`.
    pub tangent: [f64; 3],
    /// Area enclosed by the section loop.
    pub area_mm2: f64,
    /// Area-equivalent diameter √(4A/π).
    pub equivalent_diameter_mm: f64,
    /// Largest distance between two points of the loop (maximal Feret diameter).
    pub max_diameter_mm: f64,
    /// Smallest width of the loop between parallel tangent lines (minimal Feret diameter).
    pub min_diameter_mm: f64,
}

/// A section is taken for the main lumen alone when its maximal Feret diameter is at most
/// this multiple of its minimal one. A plane through a branch ostium cuts up into the branch
/// and its loop is long and thin (2.5–3.5× on the arch of SynthAorta's aortas); a lumen
/// that is round or moderately elliptic stays well below.
pub const SINGLE_LUMEN_MAX_ASPECT: f64 = 1.5;

impl Station {
    /// Whether the section is the main lumen alone, not a lumen merged with a branch ostium
    /// ([`SINGLE_LUMEN_MAX_ASPECT`]).
    pub fn is_single_lumen(&self) -> bool {
        self.max_diameter_mm <= SINGLE_LUMEN_MAX_ASPECT * self.min_diameter_mm
    }
}

/// Centreline length and diameter profile of a tubular surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VesselMeasurements {
    /// Length of the centreline from where it enters to where it leaves the vessel.
    pub centreline_length_mm: f64,
    /// Sections at evenly spaced arc lengths, in order.
    pub stations: Vec<Station>,
}

impl VesselMeasurements {
    /// The largest area-equivalent diameter of the vessel: over the sections of the main
    /// lumen alone ([`Station::is_single_lumen`]), as a clinician leaves the branch ostia
    /// out; over all sections when none qualifies.
    pub fn max_diameter_mm(&self) -> f64 {
        let largest = |single_lumen_only: bool| {
            self.stations
                .iter()
                .filter(|s| !single_lumen_only || s.is_single_lumen())
                .map(|s| s.equivalent_diameter_mm)
                .fold(None, |m: Option<f64>, d| Some(m.map_or(d, |m| m.max(d))))
        };
        largest(true).or_else(|| largest(false)).unwrap_or(0.0)
    }
}

/// Landmark diameters and heights of an aortic root.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RootMeasurements {
    /// Maximal Feret diameter of the annulus section.
    pub annulus_major_mm: f64,
    /// Minimal Feret diameter of the annulus section.
    pub annulus_minor_mm: f64,
    /// Mean of the annulus major and minor diameters.
    pub annulus_mean_mm: f64,
    /// Twice the largest distance from the root axis to the wall between annulus and STJ.
    pub sinus_diameter_mm: f64,
    /// Area-equivalent diameter at the sinotubular junction.
    pub stj_diameter_mm: f64,
    /// Centreline distance from the annulus plane to the sinotubular junction.
    pub sinus_height_mm: f64,
    /// Median area-equivalent diameter of the distal half of the segment above the STJ.
    pub ascending_diameter_mm: f64,
}

/// Tuning of the centreline computation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeasureOptions {
    /// Target distance between stations (the actual spacing divides the length evenly).
    pub station_spacing_mm: f64,
    /// Half-width of the window of the local quadratic fit that smooths the centreline.
    pub smoothing_mm: f64,
    /// Most slicing/re-centring passes (stops earlier once converged).
    pub iterations: usize,
}

impl Default for MeasureOptions {
    /// 1 mm stations, 5 mm smoothing (a fifth of an aortic diameter), up to 4 passes.
    fn default() -> Self {
        Self {
            station_spacing_mm: 1.0,
            smoothing_mm: 10.0,
            iterations: 4,
        }
    }
}

impl MeasureOptions {
    fn validate(&self) -> Result<(), MeasureError> {
        let bad = |what: String| Err(MeasureError::BadOptions(what));
        if !(self.station_spacing_mm.is_finite() && self.station_spacing_mm > 0.0) {
            return bad(format!(
                "station_spacing_mm = {} must be a positive number",
                self.station_spacing_mm
            ));
        }
        if !(self.smoothing_mm.is_finite() && self.smoothing_mm > 0.0) {
            return bad(format!(
                "smoothing_mm = {} must be a positive number",
                self.smoothing_mm
            ));
        }
        if !(1..=20).contains(&self.iterations) {
            return bad(format!("iterations = {} must be 1–20", self.iterations));
        }
        Ok(())
    }
}

/// Why a surface could not be measured.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeasureError {
    /// The mesh itself is unusable (empty, non-finite, bad indices).
    #[error("invalid mesh: {0}")]
    InvalidMesh(#[from] MeshError),
    /// The options are out of range.
    #[error("invalid measurement options: {0}")]
    BadOptions(String),
    /// The surface is not a tube: no consistent closed sections along a centreline.
    #[error("not a tubular vessel: {0}")]
    NotTubular(String),
    /// The diameter profile lacks a landmark of an aortic root.
    #[error("not an aortic root: {0}")]
    NotARoot(String),
}

/// The converged centreline of a prepared surface.
pub(crate) fn vessel_centreline(
    surface: &Surface,
    opts: &MeasureOptions,
) -> Result<centreline::Centreline, MeasureError> {
    opts.validate()?;
    let rough = rough_centreline(surface, 2.0 * opts.station_spacing_mm)?;
    let tracked = tracking::track(
        surface,
        &rough.points,
        opts.station_spacing_mm,
        opts.smoothing_mm,
    )?;
    let initial = centreline::Centreline::from_path(surface, tracked, opts)
        .starting_proximal(rough.starts_proximal);
    centreline::refine(surface, initial, opts)
}

/// The first guess of the main vessel's centreline. For a vessel with side branches, the
/// ring centroids along the main path of the level-set tree ([`vessel_tree`]) from the
/// proximal end (the ascending aorta) to the descending one: it never turns into a branch,
/// however long the branch is, and follows the ascending aorta to its end. Otherwise the
/// level sets from the geodesically farthest vertex pair ([`geodesic`]).
pub fn rough_centreline(surface: &Surface, step: f64) -> Result<RoughCentreline, MeasureError> {
    let farthest_pair = || {
        geodesic::level_set_centres(surface, step).map(|points| RoughCentreline {
            points,
            starts_proximal: false,
        })
    };
    // Without side branches the farthest pair are the tube's two ends.
    let ends = match vessel_tree::vessel_ends(surface, step) {
        Ok(ends) if !ends.branches.is_empty() => ends,
        _ => return farthest_pair(),
    };
    // Over an end cap the level sets are arcs round the cap's centre, not rings round the
    // tube: rings narrower than most of the path are left out at both ends (the ends are
    // tracked again from the interior).
    let rings = &ends.main_path;
    let mut radii: Vec<f64> = rings.iter().map(|r| r.radius_mm).collect();
    radii.sort_by(f64::total_cmp);
    let Some(&median) = radii.get(radii.len() / 2) else {
        return farthest_pair();
    };
    let round = |r: &vessel_tree::PathRing| r.radius_mm >= 0.7 * median;
    let first = rings.iter().position(round).unwrap_or(0);
    let last = rings.iter().rposition(round).unwrap_or(0);
    if last < first + 3 {
        return farthest_pair();
    }
    // Where a branch leaves, a ring goes round both vessels: its centroid is off the axis.
    let centres = rings[first..=last]
        .iter()
        .filter(|r| !r.junction)
        .map(|r| r.centre)
        .collect();
    Ok(RoughCentreline {
        points: Polyline::new(centres),
        starts_proximal: true,
    })
}

/// A first guess of the centreline, and whether it is known to start at the proximal end.
#[derive(Debug, Clone)]
pub struct RoughCentreline {
    /// Centre points from one end of the vessel to the other.
    pub points: Polyline,
    /// True when the first point is at the proximal end (an aorta with branches).
    pub starts_proximal: bool,
}

/// The station of `line` at arc length `s`, or `None` when no closed loop surrounds it.
pub(crate) fn station_at(
    surface: &Surface,
    line: &centreline::Centreline,
    s: f64,
) -> Option<Station> {
    let (centre, tangent) = line.frame_at(s);
    let section = surface.wall_section_at(centre, tangent)?;
    let (max, min) = section.feret();
    Some(Station {
        s_mm: s,
        centre,
        tangent,
        area_mm2: section.area,
        equivalent_diameter_mm: (4.0 * section.area / std::f64::consts::PI).sqrt(),
        max_diameter_mm: max,
        min_diameter_mm: min,
    })
}

/// Stations of a prepared surface along its converged centreline.
pub(crate) fn measure_prepared(
    surface: &Surface,
    opts: &MeasureOptions,
) -> Result<(centreline::Centreline, VesselMeasurements), MeasureError> {
    let line = vessel_centreline(surface, opts)?;
    let positions = centreline::station_positions(line.length(), opts.station_spacing_mm);
    let stations: Vec<Station> = positions
        .iter()
        .filter_map(|&s| station_at(surface, &line, s))
        .collect();
    if stations.len() * 4 < positions.len() * 3 {
        return Err(MeasureError::NotTubular(format!(
            "only {} of {} stations have a closed section around the centreline",
            stations.len(),
            positions.len()
        )));
    }
    let mut diameters: Vec<f64> = stations.iter().map(|s| s.equivalent_diameter_mm).collect();
    diameters.sort_by(f64::total_cmp);
    let median = diameters[diameters.len() / 2];
    if line.length() < median {
        return Err(MeasureError::NotTubular(format!(
            "the centreline ({:.2} mm) is shorter than the median diameter ({median:.2} mm)",
            line.length()
        )));
    }
    let measurements = VesselMeasurements {
        centreline_length_mm: line.smoothed_length(0.25 * opts.station_spacing_mm),
        stations,
    };
    Ok((line, measurements))
}

/// Centreline length and diameter profile of a tubular surface in millimetres (closed with
/// caps or open at its ends).
pub fn measure_vessel(
    mesh: &crate::geometry::TriMesh,
    opts: &MeasureOptions,
) -> Result<VesselMeasurements, MeasureError> {
    let surface = Surface::new(mesh)?;
    measure_prepared(&surface, opts).map(|(_, m)| m)
}
