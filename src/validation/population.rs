//! A population of shapes a validation compares: a generated cohort, a reference of real
//! patients, or a model's training or held-out shapes. Each member has its features and,
//! when it comes from a mesh, its surface in mm (a measurements table has no surfaces, so
//! the shape-level metrics cannot be computed against it).

use rayon::prelude::*;

use super::features::FeatureValues;
use crate::anatomy::shape::{ShapeAnatomy, measure_shape};
use crate::geometry::TriMesh;

/// One shape of a population.
#[derive(Debug, Clone)]
pub struct Member {
    /// Its name (file stem, table row id, shape index).
    pub name: String,
    /// Its closed surface in mm, in its own frame, if it has one.
    pub surface_mm: Option<TriMesh>,
    /// Its measured features.
    pub features: FeatureValues,
}

/// A generated shape as stored: its surface and what was measured when it was made.
#[derive(Debug, Clone)]
pub struct StoredShape {
    /// Its name (shape index, file stem).
    pub name: String,
    /// Its closed surface in mm.
    pub surface_mm: TriMesh,
    /// Its stored anatomical measurements, if the measurement succeeded.
    pub anatomy: Option<ShapeAnatomy>,
    /// Its stored surface area.
    pub area_mm2: f64,
    /// Its stored enclosed volume.
    pub volume_mm3: f64,
}

/// A named set of shapes.
#[derive(Debug, Clone)]
pub struct Population {
    /// What it is, for the report (`cohort 3`, `held-out shapes`, `reference 2: …`).
    pub label: String,
    /// Its shapes.
    pub members: Vec<Member>,
}

impl Population {
    /// Measures every `(name, mesh in mm)` (in parallel): root and vessel measurements,
    /// area and volume. A shape whose measurement fails keeps its area and volume.
    pub fn from_meshes(label: impl Into<String>, meshes: Vec<(String, TriMesh)>) -> Self {
        let members = meshes
            .into_par_iter()
            .map(|(name, mesh)| {
                let anatomy = measure_shape(&mesh).ok();
                let features =
                    FeatureValues::of_shape(anatomy.as_ref(), mesh.area(), mesh.signed_volume());
                Member {
                    name,
                    surface_mm: Some(mesh),
                    features,
                }
            })
            .collect();
        Self {
            label: label.into(),
            members,
        }
    }

    /// The shapes of a generated cohort with the measurements stored when they were made.
    /// Values measured by an earlier method ([`ShapeAnatomy::is_current`]), or missing, are
    /// measured again from the surface (in parallel): a reference is always measured today,
    /// and the two sides must be measured alike.
    pub fn from_stored(label: impl Into<String>, shapes: Vec<StoredShape>) -> Self {
        let members = shapes
            .into_par_iter()
            .map(|shape| {
                let anatomy = match shape.anatomy {
                    Some(a) if a.is_current() => Some(a),
                    _ => measure_shape(&shape.surface_mm).ok(),
                };
                Member {
                    name: shape.name,
                    features: FeatureValues::of_shape(
                        anatomy.as_ref(),
                        shape.area_mm2,
                        shape.volume_mm3,
                    ),
                    surface_mm: Some(shape.surface_mm),
                }
            })
            .collect();
        Self {
            label: label.into(),
            members,
        }
    }

    /// Number of shapes.
    pub fn len(&self) -> usize {
        self.members.len()
    }

    /// Whether it has no shapes.
    pub fn is_empty(&self) -> bool {
        self.members.is_empty()
    }

    /// Whether every member has a surface (shape-level metrics need one for each).
    pub fn has_surfaces(&self) -> bool {
        !self.members.is_empty() && self.members.iter().all(|m| m.surface_mm.is_some())
    }

    /// The values of one feature over the members that have it.
    pub fn values(&self, feature: super::Feature) -> Vec<f64> {
        self.members
            .iter()
            .filter_map(|m| m.features.get(feature))
            .collect()
    }

    /// Mean unit-ball radius of the surfaces (mm): the distance from each bounding-box
    /// centre to the farthest vertex, as training normalises.
    pub fn mean_radius_mm(&self) -> Option<f64> {
        let radii: Vec<f64> = self
            .members
            .iter()
            .filter_map(|m| m.surface_mm.as_ref())
            .map(|s| {
                crate::geometry::normalize::normalize_to_unit_ball(s)
                    .1
                    .radius
            })
            .collect();
        (!radii.is_empty()).then(|| radii.iter().sum::<f64>() / radii.len() as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::anatomy::measurement::Measurement;
    use crate::synth::generate_root;
    use crate::validation::Feature;

    #[test]
    fn stored_measurements_are_kept_when_current_and_measured_again_when_not() {
        let (_, mesh) = generate_root(3, 1, true);
        let today = measure_shape(&mesh).unwrap();
        let marked = |version: u32| ShapeAnatomy {
            length_mm: 1234.0,
            measurement_version: version,
            ..today.clone()
        };
        let stored = |name: &str, anatomy: Option<ShapeAnatomy>| StoredShape {
            name: name.into(),
            surface_mm: mesh.clone(),
            anatomy,
            area_mm2: 1.0,
            volume_mm3: 2.0,
        };
        let population = Population::from_stored(
            "cohort",
            vec![
                stored("current", Some(marked(today.measurement_version))),
                stored("earlier", Some(marked(1))),
                stored("missing", None),
            ],
        );
        let length = population.values(Feature::Anatomy(Measurement::Length));
        assert_eq!(
            length,
            vec![1234.0, today.length_mm, today.length_mm],
            "the current record is kept, the others measured today"
        );
        assert_eq!(population.values(Feature::Area), vec![1.0; 3]);
    }
}
