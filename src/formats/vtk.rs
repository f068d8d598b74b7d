//! VTK writers of face-labelled surfaces: VTK XML PolyData (`.vtp`, base64 binary arrays,
//! little-endian, UInt32 block headers) and legacy ASCII VTK (`.vtk`, version 4.2, as an
//! unstructured grid of triangles: VTK 9 reads every legacy dataset type, meshio only that
//! one). Each carries the per-cell `ModelFaceID` (SimVascular's
//! convention), 1-based `GlobalNodeID` / `GlobalElementID` (as SimVascular's exported
//! surfaces do) and per-point `Normals`. Coordinates are written as given (mm); the units
//! and provenance go in an XML comment or the legacy header line.

use std::fmt::Write as _;

use super::MeshMetadata;
use super::gltf_write::base64;
use super::labelled::{FacePatch, LabelledWriteError, check_labels};
use crate::geometry::TriMesh;

/// The per-point normals written: the mesh's own, or area-weighted face normals.
fn normals(mesh: &TriMesh) -> Vec<[f32; 3]> {
    mesh.normals
        .clone()
        .unwrap_or_else(|| mesh.compute_vertex_normals())
}

/// One base64 binary data array: a UInt32 byte count, then the little-endian values.
fn binary_array(s: &mut String, kind: &str, name: &str, components: usize, bytes: Vec<u8>) {
    let mut block = (bytes.len() as u32).to_le_bytes().to_vec();
    block.extend(bytes);
    let _ = writeln!(
        s,
        "        <DataArray type=\"{kind}\" Name=\"{name}\" NumberOfComponents=\"{components}\" \
         format=\"binary\">{}</DataArray>",
        base64(&block)
    );
}

fn floats(v: &[[f32; 3]]) -> Vec<u8> {
    v.iter().flatten().flat_map(|x| x.to_le_bytes()).collect()
}

fn ints(v: impl Iterator<Item = i32>) -> Vec<u8> {
    v.flat_map(|x| x.to_le_bytes()).collect()
}

/// The metadata as one line of text that cannot end an XML comment.
fn metadata_line(meta: &MeshMetadata, patches: &[FacePatch]) -> String {
    let mut json = meta.to_json();
    json["faces"] = patches
        .iter()
        .map(|p| serde_json::json!({"id": p.id, "name": p.name}))
        .collect();
    json.to_string().replace("--", "- -")
}

/// VTK XML PolyData with triangles, `ModelFaceID` per cell and `Normals` per point.
pub fn write_vtp(
    mesh: &TriMesh,
    face_ids: &[u32],
    patches: &[FacePatch],
    meta: &MeshMetadata,
) -> Result<Vec<u8>, LabelledWriteError> {
    check_labels(mesh, face_ids, patches, "VTP")?;
    let (n, t) = (mesh.vertex_count(), mesh.triangle_count());
    let mut s = String::with_capacity(64 * (n + t));
    s.push_str("<?xml version=\"1.0\"?>\n");
    let _ = writeln!(s, "<!-- {} -->", metadata_line(meta, patches));
    s.push_str(
        "<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" \
         header_type=\"UInt32\">\n  <PolyData>\n",
    );
    let _ = writeln!(
        s,
        "    <Piece NumberOfPoints=\"{n}\" NumberOfVerts=\"0\" NumberOfLines=\"0\" \
         NumberOfStrips=\"0\" NumberOfPolys=\"{t}\">"
    );
    s.push_str("      <PointData Normals=\"Normals\" Scalars=\"GlobalNodeID\">\n");
    binary_array(&mut s, "Float32", "Normals", 3, floats(&normals(mesh)));
    binary_array(&mut s, "Int32", "GlobalNodeID", 1, ints(1..=n as i32));
    s.push_str("      </PointData>\n      <CellData Scalars=\"ModelFaceID\">\n");
    binary_array(
        &mut s,
        "Int32",
        "ModelFaceID",
        1,
        ints(face_ids.iter().map(|&i| i as i32)),
    );
    binary_array(&mut s, "Int32", "GlobalElementID", 1, ints(1..=t as i32));
    s.push_str("      </CellData>\n      <Points>\n");
    binary_array(&mut s, "Float32", "Points", 3, floats(&mesh.positions));
    s.push_str("      </Points>\n      <Polys>\n");
    let connectivity = mesh.triangles.iter().flatten().map(|&v| v as i32);
    binary_array(&mut s, "Int32", "connectivity", 1, ints(connectivity));
    binary_array(
        &mut s,
        "Int32",
        "offsets",
        1,
        ints((1..=t as i32).map(|k| 3 * k)),
    );
    s.push_str("      </Polys>\n    </Piece>\n  </PolyData>\n</VTKFile>\n");
    Ok(s.into_bytes())
}

/// Legacy ASCII VTK (an UNSTRUCTURED_GRID of triangles) with the same arrays as
/// [`write_vtp`].
pub fn write_legacy_vtk(
    mesh: &TriMesh,
    face_ids: &[u32],
    patches: &[FacePatch],
    meta: &MeshMetadata,
) -> Result<Vec<u8>, LabelledWriteError> {
    check_labels(mesh, face_ids, patches, "VTK")?;
    let (n, t) = (mesh.vertex_count(), mesh.triangle_count());
    let mut s = String::with_capacity(48 * (n + t));
    s.push_str("# vtk DataFile Version 4.2\n");
    // The title line holds at most 256 characters.
    let title = format!(
        "{}, units {}, faces in ModelFaceID",
        meta.generator, meta.units
    );
    let _ = writeln!(s, "{}", title.chars().take(255).collect::<String>());
    let _ = writeln!(s, "ASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS {n} float");
    for p in &mesh.positions {
        let _ = writeln!(s, "{} {} {}", p[0], p[1], p[2]);
    }
    let _ = writeln!(s, "CELLS {t} {}", 4 * t);
    for tri in &mesh.triangles {
        let _ = writeln!(s, "3 {} {} {}", tri[0], tri[1], tri[2]);
    }
    // Cell type 5 is VTK_TRIANGLE.
    let _ = writeln!(s, "CELL_TYPES {t}");
    for _ in 0..t {
        s.push_str("5\n");
    }
    let _ = writeln!(s, "CELL_DATA {t}\nFIELD FieldData 2\nModelFaceID 1 {t} int");
    for id in face_ids {
        let _ = writeln!(s, "{id}");
    }
    let _ = writeln!(s, "GlobalElementID 1 {t} int");
    for k in 1..=t {
        let _ = writeln!(s, "{k}");
    }
    // A FIELD rather than a NORMALS section: meshio reads only FIELD arrays.
    let _ = writeln!(s, "POINT_DATA {n}\nFIELD FieldData 1\nNormals 3 {n} float");
    for v in normals(mesh) {
        let _ = writeln!(s, "{} {} {}", v[0], v[1], v[2]);
    }
    Ok(s.into_bytes())
}
