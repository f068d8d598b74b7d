//! The measurements stored with every generated shape: the aortic-root landmarks when the
//! shape has them, otherwise the centreline length and diameters of a plain vessel.

use serde::{Deserialize, Serialize};

use super::{MeasureError, MeasureOptions, VesselMeasurements, measure_vessel};
use crate::geometry::TriMesh;

/// Anatomical measurements of one shape in millimetres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ShapeAnatomy {
    /// `root` when the aortic-root landmarks were found, `vessel` when only the centreline
    /// and its diameter profile were (the landmark fields are then null).
    pub method: String,
    /// Mean of the annulus' major and minor (Feret) diameters.
    pub annulus_mm: Option<f64>,
    /// Sinus of Valsalva diameter.
    pub sinus_mm: Option<f64>,
    /// Area-equivalent diameter at the sinotubular junction.
    pub stj_mm: Option<f64>,
    /// Centreline distance from the annulus to the sinotubular junction.
    pub sinus_height_mm: Option<f64>,
    /// Ascending aorta diameter (median of the distal half above the junction).
    pub ascending_mm: Option<f64>,
    /// Centreline length.
    pub length_mm: f64,
    /// Largest area-equivalent diameter along the centreline, branch ostia left out
    /// (sections more than 1.5× as long as wide).
    pub max_diameter_mm: f64,
    /// Why the root landmarks are missing (`method` = `vessel`).
    pub root_error: Option<String>,
    /// The version of the measurement method ([`MEASUREMENT_VERSION`]); 1 when absent
    /// (stored before the method had versions).
    #[serde(default = "first_measurement_version")]
    pub measurement_version: u32,
}

/// The version of the measurement method. Values measured by another version are not
/// comparable with today's and are measured again before they are compared:
/// - 1: centreline from the geodesically farthest vertex pair (it could end in a branch),
///   maximum diameter over every section;
/// - 2: centreline along the main path of the vessel's level-set tree, smoothed over
///   windows with centre points on both sides (across runs of missing sections), a sinus
///   only near the proximal end, maximum diameter with the branch ostia left out.
pub const MEASUREMENT_VERSION: u32 = 2;

/// The version of records written before the method had versions (serde's default).
pub(crate) fn first_measurement_version() -> u32 {
    1
}

impl ShapeAnatomy {
    /// Whether these values were measured by today's method.
    pub fn is_current(&self) -> bool {
        self.measurement_version == MEASUREMENT_VERSION
    }
}

/// Measures a shape given in millimetres: [`super::measure_root`] first, falling back to
/// [`measure_vessel`]; the error is the vessel measurement's when both fail.
pub fn measure_shape(mesh_mm: &TriMesh) -> Result<ShapeAnatomy, MeasureError> {
    match super::root::measure_root_with_profile(mesh_mm) {
        Ok((root, _, profile)) => Ok(ShapeAnatomy {
            method: "root".into(),
            annulus_mm: Some(root.annulus_mean_mm),
            sinus_mm: Some(root.sinus_diameter_mm),
            stj_mm: Some(root.stj_diameter_mm),
            sinus_height_mm: Some(root.sinus_height_mm),
            ascending_mm: Some(root.ascending_diameter_mm),
            ..vessel_only(&profile, None)
        }),
        Err(root_error) => {
            let profile = measure_vessel(mesh_mm, &MeasureOptions::default())?;
            Ok(vessel_only(&profile, Some(root_error.to_string())))
        }
    }
}

fn vessel_only(profile: &VesselMeasurements, root_error: Option<String>) -> ShapeAnatomy {
    ShapeAnatomy {
        method: "vessel".into(),
        annulus_mm: None,
        sinus_mm: None,
        stj_mm: None,
        sinus_height_mm: None,
        ascending_mm: None,
        length_mm: profile.centreline_length_mm,
        max_diameter_mm: profile.max_diameter_mm(),
        root_error,
        measurement_version: MEASUREMENT_VERSION,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::anatomy::measure_root;
    use crate::geometry::test_shapes;
    use crate::synth::generate_root;

    #[test]
    fn a_parametric_root_gets_its_landmarks_and_length() {
        let (params, mesh) = generate_root(3, 1, true);
        let a = measure_shape(&mesh).unwrap();
        let root = measure_root(&mesh).unwrap();
        assert_eq!(a.method, "root");
        assert_eq!(a.annulus_mm, Some(root.annulus_mean_mm));
        assert_eq!(a.stj_mm, Some(root.stj_diameter_mm));
        assert_eq!(a.sinus_height_mm, Some(root.sinus_height_mm));
        assert!(a.root_error.is_none());
        assert!(a.length_mm > root.sinus_height_mm, "{a:?}");
        assert!(
            a.max_diameter_mm >= root.stj_diameter_mm,
            "{a:?} {params:?}"
        );
    }

    #[test]
    fn values_stored_without_a_version_are_from_the_first_method() {
        let (_, mesh) = generate_root(3, 1, true);
        let a = measure_shape(&mesh).unwrap();
        assert!(a.is_current());
        let mut stored = serde_json::to_value(&a).unwrap();
        stored
            .as_object_mut()
            .unwrap()
            .remove("measurement_version");
        let old: ShapeAnatomy = serde_json::from_value(stored).unwrap();
        assert_eq!(old.measurement_version, 1);
        assert!(!old.is_current());
    }

    #[test]
    fn a_sphere_is_not_a_vessel() {
        let sphere = test_shapes::uv_sphere(15.0, [0.0; 3], 24, 48);
        assert!(measure_shape(&sphere).is_err());
    }
}
