//! The indexed triangle mesh every other module exchanges, with the checks that make
//! a mesh safe to sample, measure and serialise.

use std::collections::HashMap;

/// An indexed triangle mesh: shared vertices, counter-clockwise triangles seen from
/// outside (so face normals point outward), optional per-vertex unit normals.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TriMesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Triangles as three indices into `positions`.
    pub triangles: Vec<[u32; 3]>,
    /// Optional per-vertex unit normals, one per position.
    pub normals: Option<Vec<[f32; 3]>>,
}

/// Why a mesh is unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    /// No vertices or no triangles at all.
    #[error("mesh is empty ({vertices} vertices, {triangles} triangles)")]
    Empty {
        /// Number of vertices found.
        vertices: usize,
        /// Number of triangles found.
        triangles: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("vertex {vertex} has a non-finite coordinate {value:?}")]
    NonFinite {
        /// Index of the offending vertex.
        vertex: usize,
        /// Its position.
        value: [f32; 3],
    },
    /// A triangle refers to a vertex that does not exist.
    #[error("triangle {triangle} refers to vertex {index}, but there are only {vertices} vertices")]
    IndexOutOfRange {
        /// Index of the offending triangle.
        triangle: usize,
        /// The bad vertex index.
        index: u32,
        /// Number of vertices.
        vertices: usize,
    },
    /// Normals are present but not one per vertex, or not finite.
    #[error("normals: {0}")]
    BadNormals(String),
    /// Every triangle has zero area.
    #[error("all {0} triangles are degenerate (zero area)")]
    AllDegenerate(usize),
}

/// Axis-aligned bounding box.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Aabb {
    /// Smallest corner.
    pub min: [f64; 3],
    /// Largest corner.
    pub max: [f64; 3],
}

impl Aabb {
    /// Centre of the box.
    pub fn centre(&self) -> [f64; 3] {
        std::array::from_fn(|i| 0.5 * (self.min[i] + self.max[i]))
    }
    /// Edge lengths of the box.
    pub fn size(&self) -> [f64; 3] {
        std::array::from_fn(|i| self.max[i] - self.min[i])
    }
}

/// Edge-use summary of a mesh: how its edges are shared between triangles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EdgeReport {
    /// Distinct undirected edges.
    pub edges: usize,
    /// Edges used by exactly one triangle (holes).
    pub boundary_edges: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Edges used twice in the same direction (neighbouring triangles disagree on orientation).
    pub inconsistently_oriented_edges: usize,
}

impl EdgeReport {
    /// Every edge in exactly two triangles, traversed once in each direction.
    pub fn is_closed_and_oriented(&self) -> bool {
        self.boundary_edges == 0
            && self.non_manifold_edges == 0
            && self.inconsistently_oriented_edges == 0
    }
}

impl TriMesh {
    /// A mesh without normals.
    pub fn new(positions: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>) -> Self {
        Self {
            positions,
            triangles,
            normals: None,
        }
    }

    /// Checks finite coordinates, indices in range, matching normals and at least one
    /// non-degenerate triangle.
    pub fn validate(&self) -> Result<(), MeshError> {
        if self.positions.is_empty() || self.triangles.is_empty() {
            return Err(MeshError::Empty {
                vertices: self.positions.len(),
                triangles: self.triangles.len(),
            });
        }
        if let Some((vertex, p)) = self
            .positions
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|c| !c.is_finite()))
        {
            return Err(MeshError::NonFinite { vertex, value: *p });
        }
        let n = self.positions.len();
        for (triangle, t) in self.triangles.iter().enumerate() {
            if let Some(&index) = t.iter().find(|&&i| i as usize >= n) {
                return Err(MeshError::IndexOutOfRange {
                    triangle,
                    index,
                    vertices: n,
                });
            }
        }
        if let Some(normals) = &self.normals {
            if normals.len() != n {
                return Err(MeshError::BadNormals(format!(
                    "{} normals for {n} vertices",
                    normals.len()
                )));
            }
            if let Some(i) = normals
                .iter()
                .position(|v| v.iter().any(|c| !c.is_finite()))
            {
                return Err(MeshError::BadNormals(format!("normal {i} is not finite")));
            }
        }
        if (0..self.triangles.len()).all(|t| self.triangle_area(t) <= 0.0) {
            return Err(MeshError::AllDegenerate(self.triangles.len()));
        }
        Ok(())
    }

    /// The cube `[0,1]³` as 8 shared vertices and 12 outward triangles: the smallest closed,
    /// oriented mesh with exactly known area (6) and volume (1), for checks and examples.
    pub fn unit_cube() -> Self {
        let positions = (0..8)
            .map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32])
            .collect();
        let triangles = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        Self::new(positions, triangles)
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// The three corners of triangle `t` in f64.
    pub fn corners(&self, t: usize) -> [[f64; 3]; 3] {
        self.triangles[t].map(|i| self.positions[i as usize].map(f64::from))
    }

    /// Area of triangle `t`.
    pub fn triangle_area(&self, t: usize) -> f64 {
        let [a, b, c] = self.corners(t);
        0.5 * norm(cross(sub(b, a), sub(c, a)))
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| self.triangle_area(t))
            .sum()
    }

    /// Signed enclosed volume (divergence theorem); positive for a closed mesh whose
    /// triangles face outward. Meaningless for an open mesh.
    pub fn signed_volume(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.corners(t);
                dot(a, cross(b, c)) / 6.0
            })
            .sum()
    }

    /// Bounding box of the vertices (`None` for an empty mesh).
    pub fn bounding_box(&self) -> Option<Aabb> {
        let first = self.positions.first()?.map(f64::from);
        let mut bb = Aabb {
            min: first,
            max: first,
        };
        for p in &self.positions {
            for (i, &c) in p.iter().enumerate() {
                bb.min[i] = bb.min[i].min(f64::from(c));
                bb.max[i] = bb.max[i].max(f64::from(c));
            }
        }
        Some(bb)
    }

    /// How edges are shared: closed, boundary, non-manifold, orientation.
    pub fn edge_report(&self) -> EdgeReport {
        // Count each directed edge; an undirected edge is closed and oriented when it
        // appears exactly once in each direction.
        let mut directed: HashMap<(u32, u32), u32> =
            HashMap::with_capacity(self.triangles.len() * 3);
        for t in &self.triangles {
            for k in 0..3 {
                *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        let mut report = EdgeReport {
            edges: 0,
            boundary_edges: 0,
            non_manifold_edges: 0,
            inconsistently_oriented_edges: 0,
        };
        for (&(a, b), &forward) in &directed {
            let backward = directed.get(&(b, a)).copied().unwrap_or(0);
            if (a, b) > (b, a) && backward > 0 {
                continue; // counted from the other direction
            }
            report.edges += 1;
            match forward + backward {
                1 => report.boundary_edges += 1,
                2 if forward == 1 => {}
                2 => report.inconsistently_oriented_edges += 1,
                _ => report.non_manifold_edges += 1,
            }
        }
        report
    }

    /// Euler characteristic V − E + F (2 for a sphere, 0 for a torus).
    pub fn euler_characteristic(&self) -> i64 {
        let e = self.edge_report().edges as i64;
        self.positions.len() as i64 - e + self.triangles.len() as i64
    }

    /// Unit face normal of triangle `t` (zero for a degenerate triangle).
    pub fn face_normal(&self, t: usize) -> [f64; 3] {
        let [a, b, c] = self.corners(t);
        normalized(cross(sub(b, a), sub(c, a)))
    }

    /// Area-weighted vertex normals computed from the faces.
    pub fn compute_vertex_normals(&self) -> Vec<[f32; 3]> {
        let mut acc = vec![[0.0f64; 3]; self.positions.len()];
        for (t, tri) in self.triangles.iter().enumerate() {
            let [a, b, c] = self.corners(t);
            let n = cross(sub(b, a), sub(c, a)); // length = 2 × area
            for &i in tri {
                for k in 0..3 {
                    acc[i as usize][k] += n[k];
                }
            }
        }
        acc.into_iter()
            .map(|n| normalized(n).map(|c| c as f32))
            .collect()
    }

    /// Triangles as position triples, each rotated to start at its smallest vertex
    /// (orientation kept), sorted: two meshes are the same surface, whatever their vertex
    /// numbering, when these lists match.
    pub fn canonical_triangles(&self) -> Vec<[[f32; 3]; 3]> {
        let key = |p: &[f32; 3]| p.map(f32::to_bits);
        let mut out: Vec<[[f32; 3]; 3]> = self
            .triangles
            .iter()
            .map(|t| {
                let p = t.map(|v| self.positions[v as usize]);
                let first = (0..3).min_by_key(|&k| key(&p[k])).unwrap_or(0);
                std::array::from_fn(|k| p[(first + k) % 3])
            })
            .collect();
        out.sort_by_key(|t| t.map(|p| key(&p)));
        out
    }

    /// Largest coordinate difference between two meshes' canonical triangles, or `None`
    /// when their vertex or triangle counts differ.
    pub fn max_surface_difference(&self, other: &TriMesh) -> Option<f32> {
        if self.vertex_count() != other.vertex_count()
            || self.triangle_count() != other.triangle_count()
        {
            return None;
        }
        let (a, b) = (self.canonical_triangles(), other.canonical_triangles());
        Some(
            a.iter()
                .zip(&b)
                .flat_map(|(s, d)| s.iter().zip(d).flat_map(|(p, q)| p.iter().zip(q)))
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max),
        )
    }

    /// Applies `p ↦ p·scale + offset` to every vertex (normals are unchanged for scale > 0).
    pub fn scale_and_translate(&mut self, scale: f64, offset: [f64; 3]) {
        for p in &mut self.positions {
            *p = std::array::from_fn(|i| (f64::from(p[i]) * scale + offset[i]) as f32);
        }
    }
}

/// a − b.
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
/// a × b.
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
/// a · b.
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
/// ‖a‖.
pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}
/// a / ‖a‖, or zero for a zero vector.
pub fn normalized(a: [f64; 3]) -> [f64; 3] {
    let n = norm(a);
    if n > 0.0 { a.map(|c| c / n) } else { [0.0; 3] }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube() -> TriMesh {
        TriMesh::unit_cube()
    }

    #[test]
    fn unit_cube_measures_exactly() {
        let m = cube();
        m.validate().unwrap();
        assert!((m.area() - 6.0).abs() < 1e-12);
        assert!((m.signed_volume() - 1.0).abs() < 1e-12);
        let r = m.edge_report();
        assert_eq!(r.edges, 18);
        assert!(r.is_closed_and_oriented(), "{r:?}");
        assert_eq!(m.euler_characteristic(), 2);
    }

    #[test]
    fn flipped_triangle_and_hole_are_reported() {
        let mut m = cube();
        m.triangles[0] = [0, 1, 2];
        assert_eq!(m.edge_report().inconsistently_oriented_edges, 3);
        m.triangles.pop();
        assert_eq!(m.edge_report().boundary_edges, 3);
    }

    #[test]
    fn validation_names_the_problem() {
        let mut m = cube();
        m.positions[3][1] = f32::NAN;
        assert!(matches!(
            m.validate(),
            Err(MeshError::NonFinite { vertex: 3, .. })
        ));
        let mut m = cube();
        m.triangles[5][2] = 99;
        assert_eq!(
            m.validate(),
            Err(MeshError::IndexOutOfRange {
                triangle: 5,
                index: 99,
                vertices: 8
            })
        );
        let m = TriMesh::new(vec![[0.0; 3]; 3], vec![[0, 1, 2]]);
        assert_eq!(m.validate(), Err(MeshError::AllDegenerate(1)));
        assert!(matches!(
            TriMesh::default().validate(),
            Err(MeshError::Empty { .. })
        ));
    }
}
