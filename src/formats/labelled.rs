//! Writers of face-labelled surfaces (a face id per triangle, e.g. wall / inlet / outlets):
//! a multi-solid ASCII STL with one `solid <name> … endsolid <name>` block per face (the
//! patches OpenFOAM's snappyHexMesh expects) and an OBJ with one group per face. Both keep
//! millimetres as given; the OBJ states units and provenance in `#` comments like every
//! other OBJ the project writes (ASCII STL has no place for comments: the sidecar JSON
//! beside the file carries them).

use std::fmt::Write as _;

use super::MeshMetadata;
use crate::geometry::TriMesh;

/// Why a labelled surface could not be written (the mesh is invalid, a face id is missing
/// or unnamed, the encoder failed).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("cannot write {format}: {message}")]
pub struct LabelledWriteError {
    /// The output format (`VTP`, `VTK`, `STL`, `OBJ`, `GLB`).
    pub format: &'static str,
    /// Why.
    pub message: String,
}

/// A face id and the name its patch, group or primitive is given.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FacePatch {
    /// The id stored per triangle.
    pub id: u32,
    /// Patch name: letters, digits and `_` (anything else becomes `_`).
    pub name: String,
}

impl FacePatch {
    /// The name with every character outside `[A-Za-z0-9_]` replaced by `_`.
    pub fn safe_name(&self) -> String {
        self.name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect()
    }
}

/// Checks that there is one face id per triangle and every id has a patch.
pub(super) fn check_labels(
    mesh: &TriMesh,
    face_ids: &[u32],
    patches: &[FacePatch],
    format: &'static str,
) -> Result<(), LabelledWriteError> {
    let fail = |message: String| Err(LabelledWriteError { format, message });
    mesh.validate().map_err(|e| LabelledWriteError {
        format,
        message: e.to_string(),
    })?;
    if face_ids.len() != mesh.triangles.len() {
        return fail(format!(
            "{} face ids for {} triangles",
            face_ids.len(),
            mesh.triangles.len()
        ));
    }
    if let Some(id) = face_ids
        .iter()
        .find(|&&id| !patches.iter().any(|p| p.id == id))
    {
        return fail(format!("face id {id} has no name"));
    }
    Ok(())
}

/// Triangles of each patch, in patch order.
pub(super) fn triangles_by_patch<'a>(
    face_ids: &'a [u32],
    patches: &'a [FacePatch],
) -> impl Iterator<Item = (&'a FacePatch, Vec<usize>)> + 'a {
    patches.iter().map(move |p| {
        let tris = (0..face_ids.len())
            .filter(|&t| face_ids[t] == p.id)
            .collect();
        (p, tris)
    })
}

/// ASCII STL with one solid per face, face normals from the geometry.
pub fn write_multi_solid_stl(
    mesh: &TriMesh,
    face_ids: &[u32],
    patches: &[FacePatch],
) -> Result<Vec<u8>, LabelledWriteError> {
    check_labels(mesh, face_ids, patches, "STL")?;
    let mut s = String::with_capacity(260 * mesh.triangles.len());
    for (patch, tris) in triangles_by_patch(face_ids, patches) {
        let name = patch.safe_name();
        let _ = writeln!(s, "solid {name}");
        for t in tris {
            let n = mesh.face_normal(t);
            let _ = writeln!(s, "  facet normal {:e} {:e} {:e}", n[0], n[1], n[2]);
            s.push_str("    outer loop\n");
            for v in mesh.triangles[t] {
                let p = mesh.positions[v as usize];
                let _ = writeln!(s, "      vertex {:e} {:e} {:e}", p[0], p[1], p[2]);
            }
            s.push_str("    endloop\n  endfacet\n");
        }
        let _ = writeln!(s, "endsolid {name}");
    }
    Ok(s.into_bytes())
}

/// OBJ with shared vertices (and normals, when present) and one `g <name>` group per face.
pub fn write_grouped_obj(
    mesh: &TriMesh,
    face_ids: &[u32],
    patches: &[FacePatch],
    meta: &MeshMetadata,
) -> Result<Vec<u8>, LabelledWriteError> {
    check_labels(mesh, face_ids, patches, "OBJ")?;
    let mut s = String::with_capacity(40 * (mesh.vertex_count() + mesh.triangle_count()));
    for line in meta.comment_lines() {
        let _ = writeln!(s, "# {line}");
    }
    for p in patches {
        let _ = writeln!(s, "# face {} {}", p.id, p.safe_name());
    }
    s.push_str("o aorta\n");
    for p in &mesh.positions {
        let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
    }
    for n in mesh.normals.iter().flatten() {
        let _ = writeln!(s, "vn {} {} {}", n[0], n[1], n[2]);
    }
    let with_normals = mesh.normals.is_some();
    for (patch, tris) in triangles_by_patch(face_ids, patches) {
        let _ = writeln!(s, "g {}", patch.safe_name());
        for t in tris {
            let [a, b, c] = mesh.triangles[t].map(|i| i + 1);
            let _ = if with_normals {
                writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}")
            } else {
                writeln!(s, "f {a} {b} {c}")
            };
        }
    }
    Ok(s.into_bytes())
}
