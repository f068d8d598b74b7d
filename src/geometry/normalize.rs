//! Unit-ball normalisation: every shape is learned in a common frame where its farthest
//! vertex lies on the unit sphere, and the per-shape transform is kept so results can be
//! returned in the shape's own units (mm for SynthAorta, where one unit ≈ 105 mm).

use super::mesh::TriMesh;

/// Maps mesh units to the unit ball: `to_unit(p) = (p − centre) / radius`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct UnitBallTransform {
    /// Point of mesh space that becomes the origin (the bounding-box centre).
    pub centre: [f64; 3],
    /// Mesh-space length that becomes one unit (distance of the farthest vertex).
    pub radius: f64,
}

/// Why a set of transforms cannot be blended.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BlendError {
    /// Nothing to blend.
    #[error("cannot blend an empty list of transforms")]
    Empty,
    /// A weight is negative or not finite.
    #[error("weight {index} is {weight}, but weights must be finite and ≥ 0")]
    BadWeight {
        /// Position of the offending weight.
        index: usize,
        /// Its value.
        weight: f64,
    },
    /// The weights do not sum to one.
    #[error("weights sum to {sum}, but must sum to 1 (within {BLEND_WEIGHT_TOLERANCE})")]
    WeightSum {
        /// The actual sum.
        sum: f64,
    },
    /// A transform has a non-positive or non-finite radius.
    #[error("transform {index} has radius {radius}, but a radius must be finite and > 0")]
    BadRadius {
        /// Position of the offending transform.
        index: usize,
        /// Its radius.
        radius: f64,
    },
}

/// How far the blend weights may sum from one (DESIGN §4 uses the same tolerance).
pub const BLEND_WEIGHT_TOLERANCE: f64 = 1e-6;

impl UnitBallTransform {
    /// The transform that changes nothing.
    pub const IDENTITY: Self = Self {
        centre: [0.0; 3],
        radius: 1.0,
    };

    /// Mesh units → unit ball.
    pub fn to_unit(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| (p[i] - self.centre[i]) / self.radius)
    }

    /// Unit ball → mesh units.
    pub fn to_mesh_units(&self, q: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| q[i] * self.radius + self.centre[i])
    }

    /// The transform whose `to_unit` is this one's `to_mesh_units`.
    pub fn inverse(&self) -> Self {
        Self {
            centre: self.centre.map(|c| -c / self.radius),
            radius: 1.0 / self.radius,
        }
    }

    /// A copy of `mesh` moved into the unit ball (normals unchanged: the scale is positive).
    pub fn mesh_to_unit(&self, mesh: &TriMesh) -> TriMesh {
        let mut out = mesh.clone();
        out.scale_and_translate(1.0 / self.radius, self.centre.map(|c| -c / self.radius));
        out
    }

    /// A copy of a unit-ball `mesh` returned to mesh units.
    pub fn mesh_to_mesh_units(&self, mesh: &TriMesh) -> TriMesh {
        let mut out = mesh.clone();
        out.scale_and_translate(self.radius, self.centre);
        out
    }

    /// Convex combination of transforms (centres and radii averaged with the same weights),
    /// used to give a generated shape the units of the training shapes it blends.
    pub fn blend(parts: &[(f64, &UnitBallTransform)]) -> Result<Self, BlendError> {
        if parts.is_empty() {
            return Err(BlendError::Empty);
        }
        for (index, (weight, t)) in parts.iter().enumerate() {
            if !weight.is_finite() || *weight < 0.0 {
                return Err(BlendError::BadWeight {
                    index,
                    weight: *weight,
                });
            }
            if !t.radius.is_finite() || t.radius <= 0.0 {
                return Err(BlendError::BadRadius {
                    index,
                    radius: t.radius,
                });
            }
        }
        let sum: f64 = parts.iter().map(|(w, _)| w).sum();
        if (sum - 1.0).abs() > BLEND_WEIGHT_TOLERANCE {
            return Err(BlendError::WeightSum { sum });
        }
        let mut centre = [0.0; 3];
        let mut radius = 0.0;
        for (w, t) in parts {
            for (c, tc) in centre.iter_mut().zip(t.centre) {
                *c += w / sum * tc;
            }
            radius += w / sum * t.radius;
        }
        Ok(Self { centre, radius })
    }
}

/// Moves `mesh` into the unit ball: centre = bounding-box centre, radius = distance of the
/// farthest vertex from it, so that vertex lands on the unit sphere.
///
/// An empty mesh gets the identity transform; a mesh whose vertices all coincide is only
/// translated (radius 1), so the transform is always invertible.
pub fn normalize_to_unit_ball(mesh: &TriMesh) -> (TriMesh, UnitBallTransform) {
    let Some(bb) = mesh.bounding_box() else {
        return (mesh.clone(), UnitBallTransform::IDENTITY);
    };
    let centre = bb.centre();
    let radius = mesh
        .positions
        .iter()
        .map(|p| {
            let d: [f64; 3] = std::array::from_fn(|i| f64::from(p[i]) - centre[i]);
            super::mesh::norm(d)
        })
        .fold(0.0, f64::max);
    let radius = if radius > 0.0 && radius.is_finite() {
        radius
    } else {
        1.0
    };
    let transform = UnitBallTransform { centre, radius };
    (transform.mesh_to_unit(mesh), transform)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn skewed_box() -> TriMesh {
        let positions = (0..8)
            .map(|i| {
                let b = |k: u32| ((i >> k) & 1) as f32;
                [
                    12.0 + 40.0 * b(0),
                    -7.0 + 25.0 * b(1) + 3.0 * b(0),
                    100.0 + 80.0 * b(2),
                ]
            })
            .collect();
        let triangles = vec![[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6]];
        TriMesh::new(positions, triangles)
    }

    #[test]
    fn farthest_vertex_lands_on_the_unit_sphere() {
        let (unit, t) = normalize_to_unit_ball(&skewed_box());
        let radii: Vec<f64> = unit
            .positions
            .iter()
            .map(|p| super::super::mesh::norm(p.map(f64::from)))
            .collect();
        let max = radii.iter().copied().fold(0.0, f64::max);
        assert!((max - 1.0).abs() < 1e-6, "farthest radius {max}");
        let bb = unit.bounding_box().unwrap();
        for c in bb.centre() {
            assert!(c.abs() < 1e-6, "box centre {c}");
        }
        assert!((t.centre[0] - 32.0).abs() < 1e-12);
    }

    #[test]
    fn round_trip_restores_the_mesh() {
        let original = skewed_box();
        let (unit, t) = normalize_to_unit_ball(&original);
        let back = t.mesh_to_mesh_units(&unit);
        for (a, b) in original.positions.iter().zip(&back.positions) {
            for k in 0..3 {
                assert!(
                    (a[k] - b[k]).abs() < 1e-4 * a[k].abs().max(1.0),
                    "{a:?} vs {b:?}"
                );
            }
        }
        let p = [3.5, -2.0, 41.0];
        let q = t.to_mesh_units(t.to_unit(p));
        let r = t.inverse().to_unit(t.to_unit(p));
        for k in 0..3 {
            assert!((p[k] - q[k]).abs() < 1e-12 && (p[k] - r[k]).abs() < 1e-12);
        }
    }

    #[test]
    fn blend_of_identical_transforms_is_that_transform() {
        let t = UnitBallTransform {
            centre: [1.0, -2.0, 3.5],
            radius: 104.7,
        };
        let b = UnitBallTransform::blend(&[(0.2, &t), (0.3, &t), (0.5, &t)]).unwrap();
        for k in 0..3 {
            assert!((b.centre[k] - t.centre[k]).abs() < 1e-12);
        }
        assert!((b.radius - t.radius).abs() < 1e-12);
    }

    #[test]
    fn blend_is_the_weighted_mean() {
        let a = UnitBallTransform {
            centre: [0.0, 10.0, -4.0],
            radius: 100.0,
        };
        let b = UnitBallTransform {
            centre: [8.0, 0.0, 4.0],
            radius: 120.0,
        };
        let m = UnitBallTransform::blend(&[(0.25, &a), (0.75, &b)]).unwrap();
        assert_eq!(m.centre, [6.0, 2.5, 2.0]);
        assert!((m.radius - 115.0).abs() < 1e-12);
    }

    #[test]
    fn blend_rejects_bad_weights_by_name() {
        let t = UnitBallTransform::IDENTITY;
        assert_eq!(UnitBallTransform::blend(&[]), Err(BlendError::Empty));
        assert_eq!(
            UnitBallTransform::blend(&[(1.5, &t), (-0.5, &t)]),
            Err(BlendError::BadWeight {
                index: 1,
                weight: -0.5
            })
        );
        assert!(matches!(
            UnitBallTransform::blend(&[(0.5, &t), (0.4, &t)]),
            Err(BlendError::WeightSum { .. })
        ));
    }

    #[test]
    fn degenerate_meshes_get_an_invertible_transform() {
        let (_, t) = normalize_to_unit_ball(&TriMesh::default());
        assert_eq!(t, UnitBallTransform::IDENTITY);
        let point = TriMesh::new(vec![[5.0, 5.0, 5.0]; 3], vec![[0, 1, 2]]);
        let (unit, t) = normalize_to_unit_ball(&point);
        assert_eq!(t.radius, 1.0);
        assert_eq!(unit.positions[0], [0.0; 3]);
    }
}
