//! A population of shapes a validation compares: a generated cohort, a reference of real
//! patients, or a model's training or held-out shapes. Each member has its features and,
//! when it comes from a mesh, its surface in mm (a measurements table has no surfaces, so
//! the shape-level metrics cannot be computed against it).

use rayon::prelude::*;

use super::features::FeatureValues;
use crate::anatomy::shape::measure_shape;
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
