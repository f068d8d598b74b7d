//! Round trips of the face-labelled writers: what is written parses back (with this
//! crate's readers where it has one, with a small decoder of the VTK layouts otherwise)
//! with the same points, triangles, face ids and normals.

use super::*;
use crate::geometry::TriMesh;

/// The unit cube labelled like a vessel: bottom = inlet (1), top = outlet (2), sides = wall.
fn labelled_cube() -> (TriMesh, Vec<u32>, Vec<FacePatch>) {
    let mut mesh = TriMesh::unit_cube();
    mesh.normals = Some(mesh.compute_vertex_normals());
    let ids = (0..mesh.triangle_count())
        .map(|t| match mesh.face_normal(t)[2] {
            z if z < -0.5 => 1,
            z if z > 0.5 => 2,
            _ => 0,
        })
        .collect();
    let names = ["wall", "inlet", "outlet"];
    let patches = (0..3)
        .map(|id| FacePatch {
            id,
            name: names[id as usize].into(),
        })
        .collect();
    (mesh, ids, patches)
}

fn decode_base64(s: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        _ => 63,
    };
    let clean: Vec<u8> = s.bytes().filter(|c| !c.is_ascii_whitespace()).collect();
    let mut out = Vec::new();
    for chunk in clean.chunks(4) {
        let pad = chunk.iter().filter(|&&c| c == b'=').count();
        let n = chunk
            .iter()
            .map(|&c| if c == b'=' { 0 } else { u32::from(value(c)) })
            .fold(0u32, |acc, v| (acc << 6) | v);
        out.extend(&n.to_be_bytes()[1..4 - pad]);
    }
    out
}

/// The bytes of the VTP data array called `name` (after its UInt32 length header).
fn vtp_array(xml: &str, name: &str) -> Vec<u8> {
    let tag = format!("Name=\"{name}\"");
    let at = xml.find(&tag).unwrap_or_else(|| panic!("no array {name}"));
    let start = at + xml[at..].find('>').unwrap() + 1;
    let end = start + xml[start..].find("</DataArray>").unwrap();
    let bytes = decode_base64(&xml[start..end]);
    let len = u32::from_le_bytes(bytes[..4].try_into().unwrap()) as usize;
    assert_eq!(len, bytes.len() - 4, "{name}: header length");
    bytes[4..].to_vec()
}

fn as_i32(b: &[u8]) -> Vec<i32> {
    b.chunks(4)
        .map(|c| i32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

fn as_f32(b: &[u8]) -> Vec<f32> {
    b.chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

#[test]
fn vtp_holds_the_points_triangles_face_ids_and_unit_normals() {
    let (mesh, ids, patches) = labelled_cube();
    let xml =
        String::from_utf8(write_vtp(&mesh, &ids, &patches, &MeshMetadata::new("mm")).unwrap())
            .unwrap();
    assert!(xml.contains("\"units\":\"mm\""));
    let points = as_f32(&vtp_array(&xml, "Points"));
    assert_eq!(
        points,
        mesh.positions.iter().flatten().copied().collect::<Vec<_>>()
    );
    let conn = as_i32(&vtp_array(&xml, "connectivity"));
    assert_eq!(
        conn,
        mesh.triangles
            .iter()
            .flatten()
            .map(|&v| v as i32)
            .collect::<Vec<_>>()
    );
    assert_eq!(
        as_i32(&vtp_array(&xml, "offsets")),
        (1..=12).map(|k| 3 * k).collect::<Vec<_>>()
    );
    let faces = as_i32(&vtp_array(&xml, "ModelFaceID"));
    assert_eq!(faces, ids.iter().map(|&i| i as i32).collect::<Vec<_>>());
    let normals = as_f32(&vtp_array(&xml, "Normals"));
    assert_eq!(normals.len(), 3 * mesh.vertex_count());
    for n in normals.chunks(3) {
        assert!((n.iter().map(|c| c * c).sum::<f32>() - 1.0).abs() < 1e-5);
    }
    assert_eq!(
        as_i32(&vtp_array(&xml, "GlobalNodeID")),
        (1..=8).collect::<Vec<_>>()
    );
}

#[test]
fn legacy_vtk_lists_the_same_mesh_in_text() {
    let (mesh, ids, patches) = labelled_cube();
    let text = String::from_utf8(
        write_legacy_vtk(&mesh, &ids, &patches, &MeshMetadata::new("mm")).unwrap(),
    )
    .unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "# vtk DataFile Version 4.2");
    let after = |key: &str| lines.iter().position(|l| l.starts_with(key)).unwrap();
    let p = after("POINTS 8 float");
    let points: Vec<f32> = lines[p + 1..p + 9]
        .iter()
        .flat_map(|l| l.split_whitespace().map(|x| x.parse::<f32>().unwrap()))
        .collect();
    assert_eq!(
        points,
        mesh.positions.iter().flatten().copied().collect::<Vec<_>>()
    );
    let q = after("CELLS 12 48");
    assert!(text.contains("CELL_TYPES 12\n5\n"));
    for (k, t) in mesh.triangles.iter().enumerate() {
        assert_eq!(lines[q + 1 + k], format!("3 {} {} {}", t[0], t[1], t[2]));
    }
    let f = after("ModelFaceID 1 12 int");
    let read: Vec<u32> = lines[f + 1..f + 13]
        .iter()
        .map(|l| l.parse().unwrap())
        .collect();
    assert_eq!(read, ids);
}

#[test]
fn multi_solid_stl_has_one_solid_per_face_that_reads_back() {
    let (mesh, ids, patches) = labelled_cube();
    let text = String::from_utf8(write_multi_solid_stl(&mesh, &ids, &patches).unwrap()).unwrap();
    let mut total_area = 0.0;
    for p in &patches {
        let start = text.find(&format!("solid {}\n", p.name)).unwrap();
        let end_tag = format!("endsolid {}\n", p.name);
        let end = text.find(&end_tag).unwrap() + end_tag.len();
        let solid =
            read_mesh_bytes(&text.as_bytes()[start..end], MeshFormat::Stl, "x.stl").unwrap();
        let expected = ids.iter().filter(|&&i| i == p.id).count();
        assert_eq!(solid.triangle_count(), expected, "{}", p.name);
        total_area += solid.area();
    }
    assert!((total_area - 6.0).abs() < 1e-6);
    assert_eq!(text.matches("endsolid").count(), 3);
}

#[test]
fn grouped_obj_reads_back_as_the_same_mesh_with_one_group_per_face() {
    let (mesh, ids, patches) = labelled_cube();
    let bytes = write_grouped_obj(&mesh, &ids, &patches, &MeshMetadata::new("mm")).unwrap();
    let back = load_mesh_bytes(&bytes, MeshFormat::Obj, "x.obj").unwrap();
    assert_eq!(back.units.as_deref(), Some("mm"));
    assert_eq!(back.mesh.canonical_triangles(), mesh.canonical_triangles());
    let text = String::from_utf8(bytes).unwrap();
    for p in &patches {
        let start = text.find(&format!("g {}\n", p.name)).unwrap();
        let faces = text[start..]
            .lines()
            .skip(1)
            .take_while(|l| l.starts_with("f "))
            .count();
        assert_eq!(faces, ids.iter().filter(|&&i| i == p.id).count());
    }
}

#[test]
fn per_face_glb_has_one_named_primitive_per_face() {
    let (mesh, ids, patches) = labelled_cube();
    let bytes = write_faces_glb(&mesh, &ids, &patches, &MeshMetadata::new("mm")).unwrap();
    let gltf = ::gltf::Gltf::from_slice(&bytes).unwrap();
    let primitives: Vec<_> = gltf.meshes().flat_map(|m| m.primitives()).collect();
    assert_eq!(primitives.len(), 3);
    for (prim, p) in primitives.iter().zip(&patches) {
        let extras: serde_json::Value =
            serde_json::from_str(prim.extras().as_ref().unwrap().get()).unwrap();
        assert_eq!(extras["face_id"], p.id);
        assert_eq!(extras["name"], p.name.as_str());
        let expected = ids.iter().filter(|&&i| i == p.id).count();
        assert_eq!(prim.indices().unwrap().count(), 3 * expected);
    }
    let back = read_mesh_bytes(&bytes, MeshFormat::Glb, "x.glb").unwrap();
    assert_eq!(back.triangle_count(), 12);
    assert!((back.area() - 6.0).abs() < 1e-6);
}

#[test]
fn a_face_id_without_a_name_is_refused() {
    let (mesh, mut ids, patches) = labelled_cube();
    ids[0] = 7;
    let err = write_vtp(&mesh, &ids, &patches, &MeshMetadata::new("mm")).unwrap_err();
    assert!(err.to_string().contains("face id 7"), "{err}");
    let err = write_multi_solid_stl(&mesh, &ids[1..], &patches).unwrap_err();
    assert!(
        err.to_string().contains("11 face ids for 12 triangles"),
        "{err}"
    );
}
