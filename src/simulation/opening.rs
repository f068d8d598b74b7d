//! Openings: the planes where a closed vessel surface is cut open for a solver, with their
//! face labels, and the distances (mm) that place them.
//!
//! Face ids are fixed per kind of shape so that every shape of a model carries the same
//! labels: `wall` = 0, `inlet` = 1, then the outlets — for an aortic root the ascending
//! outlet (2); for a branched aorta the descending outlet (2) and then one outlet per
//! supra-aortic branch from proximal to distal (3, 4, …); for a plain tube the far end (2).

use serde::{Deserialize, Serialize};

use super::SimulationError;

/// Face id of the vessel wall.
pub const WALL_ID: u32 = 0;
/// Face id of the inlet.
pub const INLET_ID: u32 = 1;
/// Face id of the first outlet (the ascending outlet of a root, the descending outlet of an
/// aorta, the far end of a tube); branch outlets follow.
pub const FIRST_OUTLET_ID: u32 = 2;

/// What kind of shape the openings are placed on, and so by which rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ShapeKind {
    /// An aortic root (outflow tract, sinus, STJ, ascending aorta): openings relative to the
    /// annulus and the sinotubular junction.
    Root,
    /// A thoracic aorta with supra-aortic branches: ascending inlet, descending outlet and
    /// one outlet per branch, each a stated distance in from its end.
    Aorta,
    /// An unbranched tube: inlet at the wider end, outlet at the other, trimmed like an aorta.
    Tube,
}

/// One opening: a plane through the vessel at an anatomical end, with its label.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Opening {
    /// Face id the cap of this opening gets.
    pub id: u32,
    /// Face name (`inlet`, `outlet`, `outlet_descending`, `branch_1`, …).
    pub name: String,
    /// Centre of the vessel section in the plane (area centroid), mm.
    pub origin: [f64; 3],
    /// Unit normal along the centreline tangent, pointing out of the vessel.
    pub normal: [f64; 3],
    /// Area-equivalent radius of the section, mm.
    pub radius_mm: f64,
}

/// Where the openings go, in millimetres along the centreline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct OpeningOptions {
    /// Root inlet: distance below the annulus plane, into the left-ventricular outflow tract.
    /// 0 puts the inlet on the annulus, the basal ring of the valve where root models start.
    pub inlet_below_annulus_mm: f64,
    /// Root outlet: distance above the sinotubular junction, in the tubular ascending aorta.
    /// 20 mm is about two thirds of an ascending diameter: past the junction's waist, below
    /// the arch.
    pub outlet_above_stj_mm: f64,
    /// Aorta and tube: distance of the inlet and the main outlet in from the vessel's ends.
    /// A reconstructed shape closes each end with a rounded cap about one radius long; 20 mm
    /// (about one aortic radius and a half) cuts into the full-width vessel behind it.
    pub end_trim_mm: f64,
    /// Aorta: distance of each branch outlet in from the branch's end (supra-aortic vessels
    /// are 6–14 mm wide, their rounded ends 3–7 mm long).
    pub branch_trim_mm: f64,
    /// Level spacing of the geodesic rings that find the ends and branches of an aorta.
    pub ring_spacing_mm: f64,
}

impl Default for OpeningOptions {
    fn default() -> Self {
        Self {
            inlet_below_annulus_mm: 0.0,
            outlet_above_stj_mm: 20.0,
            end_trim_mm: 20.0,
            branch_trim_mm: 8.0,
            ring_spacing_mm: 1.5,
        }
    }
}

/// Accepted values of the options that place openings, mm: (option, smallest, largest).
/// The service's query parameters carry the same names and ranges.
pub const OPTION_RANGES_MM: [(&str, f64, f64); 5] = [
    ("inlet_below_annulus_mm", 0.0, 50.0),
    ("outlet_above_stj_mm", 0.0, 200.0),
    ("end_trim_mm", 0.5, 200.0),
    ("branch_trim_mm", 0.5, 100.0),
    ("ring_spacing_mm", 0.1, 10.0),
];

impl OpeningOptions {
    /// Every distance finite and within a range that keeps it inside a human aorta.
    pub fn validate(&self) -> Result<(), SimulationError> {
        let check = |field: &'static str, value: f64, lo: f64, hi: f64| {
            if value.is_finite() && (lo..=hi).contains(&value) {
                Ok(())
            } else {
                Err(SimulationError::option(
                    field,
                    format!("{value} mm must lie within {lo}–{hi} mm"),
                ))
            }
        };
        let bounded = |field: &'static str, value: f64| {
            let (lo, hi) = OPTION_RANGES_MM
                .iter()
                .find(|(name, ..)| *name == field)
                .map(|&(_, lo, hi)| (lo, hi))
                .expect("every opening option has a range");
            check(field, value, lo, hi)
        };
        bounded("inlet_below_annulus_mm", self.inlet_below_annulus_mm)?;
        bounded("outlet_above_stj_mm", self.outlet_above_stj_mm)?;
        bounded("end_trim_mm", self.end_trim_mm)?;
        bounded("branch_trim_mm", self.branch_trim_mm)?;
        bounded("ring_spacing_mm", self.ring_spacing_mm)
    }
}
