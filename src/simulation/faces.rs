//! A mesh whose triangles carry face ids (wall, inlet, outlets), and the boundary-condition
//! data of each face that a solver set-up needs: area, centroid, outward normal,
//! equivalent diameter and perimeter, in millimetres.

use std::collections::HashMap;

use serde::{Deserialize, Serialize};

use super::extension::EXTENSION_BASE;
use super::opening::WALL_ID;

/// Whether face `id` is the cap of an opening (not the wall or a flow-extension wall).
pub fn is_cap(id: u32) -> bool {
    id != WALL_ID && id < EXTENSION_BASE
}
use crate::geometry::TriMesh;
use crate::geometry::mesh::{cross, norm, normalized, sub};

/// A face id and its name.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FaceName {
    /// The id stored per triangle (`ModelFaceID`).
    pub id: u32,
    /// `wall`, `inlet`, `outlet`, `outlet_descending`, `branch_1`, …
    pub name: String,
}

/// A triangle mesh with one face id per triangle.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelledMesh {
    /// The surface, mm, triangles outward, with vertex normals.
    pub mesh: TriMesh,
    /// Face id of each triangle.
    pub face_ids: Vec<u32>,
    /// Every face id used, in increasing order, with its name.
    pub faces: Vec<FaceName>,
}

/// Boundary-condition data of one face, mm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FaceData {
    /// Face id.
    pub id: u32,
    /// Face name.
    pub name: String,
    /// Number of triangles.
    pub triangles: usize,
    /// Surface area, mm².
    pub area_mm2: f64,
    /// Area-weighted centroid, mm.
    pub centroid_mm: [f64; 3],
    /// Unit normal of the summed area vectors, pointing out of the vessel (for a flat cap
    /// its plane's normal; for the curved wall only an average).
    pub normal: [f64; 3],
    /// √(4·area/π): the diameter of the circle of the same area (meaningful for caps).
    pub equivalent_diameter_mm: f64,
    /// Length of the face's border with other faces and open boundaries, mm.
    pub perimeter_mm: f64,
}

impl LabelledMesh {
    /// The name of face `id`, if it is used.
    pub fn name_of(&self, id: u32) -> Option<&str> {
        self.faces
            .iter()
            .find(|f| f.id == id)
            .map(|f| f.name.as_str())
    }

    /// The triangles of one face as their own mesh (shared vertices kept, others dropped).
    pub fn submesh(&self, id: u32) -> TriMesh {
        let picked: Vec<usize> = (0..self.face_ids.len())
            .filter(|&t| self.face_ids[t] == id)
            .collect();
        self.submesh_of(&picked)
    }

    /// The given triangles as their own mesh, in their order.
    fn submesh_of(&self, triangles: &[usize]) -> TriMesh {
        let picked = triangles.iter().map(|&t| self.mesh.triangles[t]);
        let mut map: HashMap<u32, u32> = HashMap::new();
        let mut out = TriMesh::default();
        let normals = self.mesh.normals.as_ref();
        let mut out_normals = Vec::new();
        for t in picked {
            out.triangles.push(t.map(|v| {
                *map.entry(v).or_insert_with(|| {
                    out.positions.push(self.mesh.positions[v as usize]);
                    if let Some(n) = normals {
                        out_normals.push(n[v as usize]);
                    }
                    (out.positions.len() - 1) as u32
                })
            }));
        }
        out.normals = normals.map(|_| out_normals);
        out
    }

    /// The open variant: the wall (and any flow-extension walls) without the caps, with a
    /// boundary loop at every opening.
    pub fn wall_only(&self) -> LabelledMesh {
        let keep: Vec<u32> = self
            .faces
            .iter()
            .map(|f| f.id)
            .filter(|&id| !is_cap(id))
            .collect();
        let picked: Vec<usize> = (0..self.face_ids.len())
            .filter(|&t| keep.contains(&self.face_ids[t]))
            .collect();
        LabelledMesh {
            mesh: self.submesh_of(&picked),
            face_ids: picked.iter().map(|&t| self.face_ids[t]).collect(),
            faces: self
                .faces
                .iter()
                .filter(|f| keep.contains(&f.id))
                .cloned()
                .collect(),
        }
    }

    /// Boundary-condition data of every face, in id order.
    pub fn face_table(&self) -> Vec<FaceData> {
        let perimeters = self.border_lengths();
        self.faces
            .iter()
            .map(|face| {
                let (mut area, mut centroid, mut vector, mut count) = (0.0, [0.0; 3], [0.0; 3], 0);
                for (t, _) in self
                    .face_ids
                    .iter()
                    .enumerate()
                    .filter(|&(_, &f)| f == face.id)
                {
                    let [a, b, c] = self.mesh.corners(t);
                    let n = cross(sub(b, a), sub(c, a));
                    let da = 0.5 * norm(n);
                    for i in 0..3 {
                        centroid[i] += da * (a[i] + b[i] + c[i]) / 3.0;
                        vector[i] += 0.5 * n[i];
                    }
                    area += da;
                    count += 1;
                }
                FaceData {
                    id: face.id,
                    name: face.name.clone(),
                    triangles: count,
                    area_mm2: area,
                    centroid_mm: centroid.map(|c| if area > 0.0 { c / area } else { 0.0 }),
                    normal: normalized(vector),
                    equivalent_diameter_mm: (4.0 * area / std::f64::consts::PI).sqrt(),
                    perimeter_mm: perimeters.get(&face.id).copied().unwrap_or(0.0),
                }
            })
            .collect()
    }

    /// Per face id, the length of its edges that border another face or nothing.
    fn border_lengths(&self) -> HashMap<u32, f64> {
        let mut users: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
        for (t, &id) in self.mesh.triangles.iter().zip(&self.face_ids) {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                users.entry((a.min(b), a.max(b))).or_default().push(id);
            }
        }
        let mut out = HashMap::new();
        // Edges in a fixed order, so the sums come out the same on every run.
        let mut edges: Vec<(&(u32, u32), &Vec<u32>)> = users.iter().collect();
        edges.sort_unstable_by_key(|(k, _)| **k);
        for (&(a, b), ids) in edges {
            let border = ids.len() == 1 || ids.iter().any(|&i| i != ids[0]);
            if !border {
                continue;
            }
            let p = |v: u32| self.mesh.positions[v as usize].map(f64::from);
            let length = norm(sub(p(a), p(b)));
            let mut counted: Vec<u32> = ids.clone();
            counted.sort_unstable();
            counted.dedup();
            for id in counted {
                *out.entry(id).or_insert(0.0) += length;
            }
        }
        out
    }
}
