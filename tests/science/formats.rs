//! Mesh formats: round trips through every writer and reader, hand-built files in the
//! encodings our writers do not produce, and malformed input that must give a located error.

use std::path::Path;

use aortagen::formats::{
    FormatError, MeshFormat, MeshMetadata, load_mesh_bytes, load_mesh_file, read_mesh_bytes,
    read_mesh_file, write_mesh, write_mesh_file,
};
use aortagen::geometry::TriMesh;

#[path = "malformed.rs"]
mod malformed;

/// Unit cube, outward triangles, 8 shared vertices.
fn cube() -> TriMesh {
    TriMesh::unit_cube()
}

/// A cube with coordinates that are not exactly representable in short decimals, plus
/// unit normals pointing away from the centre, to test exactness.
fn odd_cube_with_normals() -> TriMesh {
    let mut m = cube();
    for (i, p) in m.positions.iter_mut().enumerate() {
        *p = p.map(|c| c * 0.1 + 1.0 / 3.0 + i as f32 * 1e-7);
    }
    let normals = cube()
        .positions
        .iter()
        .map(|p| {
            let d = p.map(|c| c - 0.5);
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            d.map(|c| c / n)
        })
        .collect();
    m.normals = Some(normals);
    m
}

/// Same triangles, corner by corner, with bit-identical positions (and normals when
/// `normals` is set), whatever the vertex numbering.
fn assert_same_surface(expected: &TriMesh, got: &TriMesh, normals: bool) {
    assert_eq!(got.triangle_count(), expected.triangle_count());
    assert_eq!(got.vertex_count(), expected.vertex_count());
    for (t, (a, b)) in expected.triangles.iter().zip(&got.triangles).enumerate() {
        for k in 0..3 {
            let (pa, pb) = (
                expected.positions[a[k] as usize],
                got.positions[b[k] as usize],
            );
            assert_eq!(
                pa.map(f32::to_bits),
                pb.map(f32::to_bits),
                "triangle {t} corner {k}"
            );
            if normals {
                let (na, nb) = (
                    expected.normals.as_ref().unwrap()[a[k] as usize],
                    got.normals.as_ref().expect("normals were lost")[b[k] as usize],
                );
                assert_eq!(
                    na.map(f32::to_bits),
                    nb.map(f32::to_bits),
                    "normal of triangle {t} corner {k}"
                );
            }
        }
    }
}

fn meta_mm() -> MeshMetadata {
    MeshMetadata {
        extras: serde_json::json!({"model": "m1", "seed": 7, "weights": [0.25, 0.75]}),
        ..MeshMetadata::new("mm")
    }
}

#[test]
fn every_format_round_trips_positions_triangles_and_units_exactly() {
    for mesh in [cube(), odd_cube_with_normals()] {
        for format in MeshFormat::ALL {
            let bytes = write_mesh(&mesh, format, &meta_mm()).unwrap();
            let loaded = load_mesh_bytes(&bytes, format, &format!("rt.{}", format.extension()))
                .unwrap_or_else(|e| panic!("{format}: {e}"));
            assert_eq!(loaded.format, format);
            assert_eq!(loaded.units.as_deref(), Some("mm"), "{format}");
            let carries_normals = format != MeshFormat::Stl && mesh.normals.is_some();
            assert_same_surface(&mesh, &loaded.mesh, carries_normals);
            assert_eq!(loaded.mesh.normals.is_some(), carries_normals, "{format}");
            assert!(
                loaded.mesh.edge_report().is_closed_and_oriented(),
                "{format}"
            );
        }
    }
}

#[test]
fn gltf_carries_metadata_and_provenance_in_extras() {
    for format in [MeshFormat::Glb, MeshFormat::Gltf] {
        let bytes = write_mesh(&cube(), format, &meta_mm()).unwrap();
        let extras = load_mesh_bytes(&bytes, format, "m")
            .unwrap()
            .extras
            .unwrap();
        assert_eq!(extras["units"], "mm");
        assert_eq!(extras["provenance"]["seed"], 7);
        assert!(
            extras["sign_convention"]
                .as_str()
                .unwrap()
                .contains("f < 0 inside")
        );
        assert!(
            extras["coordinate_frame"]
                .as_str()
                .unwrap()
                .contains("right-handed")
        );
    }
}

#[test]
fn written_glb_parses_with_the_gltf_crate_and_has_position_bounds() {
    let mesh = odd_cube_with_normals();
    let bytes = write_mesh(&mesh, MeshFormat::Glb, &meta_mm()).unwrap();
    assert_eq!(&bytes[..4], b"glTF");
    assert_eq!(
        u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize,
        bytes.len()
    );
    let gltf = gltf::Gltf::from_slice(&bytes).unwrap();
    let buffers = gltf::import_buffers(&gltf.document, None, gltf.blob.clone()).unwrap();
    assert_eq!(
        gltf.document.as_json().asset.generator.as_deref(),
        Some(format!("aortagen {}", aortagen::VERSION).as_str())
    );
    for view in gltf.document.views() {
        assert_eq!(
            view.offset() % 4,
            0,
            "buffer view {} is not 4-byte aligned",
            view.index()
        );
    }
    let primitive = gltf
        .document
        .meshes()
        .next()
        .unwrap()
        .primitives()
        .next()
        .unwrap();
    let bb = primitive.bounding_box();
    let aabb = mesh.bounding_box().unwrap();
    assert_eq!(bb.min.map(f64::from), aabb.min);
    assert_eq!(bb.max.map(f64::from), aabb.max);
    let reader = primitive.reader(|b| Some(&buffers[b.index()]));
    assert_eq!(reader.read_positions().unwrap().count(), 8);
    assert_eq!(reader.read_normals().unwrap().count(), 8);
    assert!(matches!(
        reader.read_indices().unwrap(),
        gltf::mesh::util::ReadIndices::U32(_)
    ));
}

/// PLY header for the cube: float positions, a face list with the given types and name.
fn ply_header(encoding: &str, face_list: &str) -> String {
    format!(
        "ply\nformat {encoding} 1.0\ncomment made by hand, units mm\nelement vertex 8\n\
         property double x\nproperty double y\nproperty double z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         element face 6\nproperty {face_list}\nend_header\n"
    )
}

/// The cube as six quads (split by the reader into the twelve triangles of `cube()`).
const QUADS: [[u32; 4]; 6] = [
    [0, 2, 3, 1],
    [4, 5, 7, 6],
    [0, 1, 5, 4],
    [2, 6, 7, 3],
    [0, 4, 6, 2],
    [1, 3, 7, 5],
];

fn cube_normal(i: usize) -> [f32; 3] {
    [
        (i & 1) as f32 * 2.0 - 1.0,
        ((i >> 1) & 1) as f32 * 2.0 - 1.0,
        ((i >> 2) & 1) as f32 * 2.0 - 1.0,
    ]
}

fn binary_ply(big_endian: bool) -> Vec<u8> {
    let encoding = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let mut out = ply_header(encoding, "list uchar ushort vertex_index").into_bytes();
    let mut put = |bytes: &[u8]| {
        let mut b = bytes.to_vec();
        if big_endian {
            b.reverse();
        }
        out.extend_from_slice(&b);
    };
    for (i, p) in cube().positions.iter().enumerate() {
        for c in p {
            put(&f64::from(*c).to_le_bytes());
        }
        for c in cube_normal(i) {
            put(&c.to_le_bytes());
        }
    }
    for q in QUADS {
        put(&[4]);
        for i in q {
            put(&(i as u16).to_le_bytes());
        }
    }
    out
}

fn ascii_ply() -> Vec<u8> {
    let mut s = ply_header("ascii", "list uchar int vertex_indices");
    for (i, p) in cube().positions.iter().enumerate() {
        let n = cube_normal(i);
        s += &format!("{} {} {} {} {} {}\n", p[0], p[1], p[2], n[0], n[1], n[2]);
    }
    for q in QUADS {
        s += &format!("4 {} {} {} {}\n", q[0], q[1], q[2], q[3]);
    }
    s.into_bytes()
}

/// The cube as `QUADS` split into fans, as the PLY reader must produce it.
fn quad_cube() -> TriMesh {
    let triangles = QUADS
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    TriMesh::new(cube().positions, triangles)
}

#[test]
fn ply_reads_ascii_and_both_binary_endians_with_quads_and_normals() {
    let mut expected = quad_cube();
    expected.normals = Some((0..8).map(cube_normal).collect());
    for (label, bytes) in [
        ("ascii", ascii_ply()),
        ("big", binary_ply(true)),
        ("little", binary_ply(false)),
    ] {
        let loaded = load_mesh_bytes(&bytes, MeshFormat::Ply, label)
            .unwrap_or_else(|e| panic!("{label}: {e}"));
        assert_same_surface(&expected, &loaded.mesh, true);
        assert_eq!(loaded.units.as_deref(), Some("mm"), "{label}");
        assert!(
            loaded.mesh.edge_report().is_closed_and_oriented(),
            "{label}"
        );
        assert!((loaded.mesh.signed_volume() - 1.0).abs() < 1e-12, "{label}");
    }
}

fn cube_stl_ascii() -> String {
    let m = cube();
    let mut s = String::from("solid cube units mm\n");
    for t in &m.triangles {
        s += "  facet normal 0 0 0\n    outer loop\n";
        for &i in t {
            let p = m.positions[i as usize];
            s += &format!("      vertex {} {} {}\n", p[0], p[1], p[2]);
        }
        s += "    endloop\n  endfacet\n";
    }
    s + "endsolid cube\n"
}

#[test]
fn stl_ascii_and_binary_with_a_solid_header_are_welded_into_a_closed_mesh() {
    let ascii = cube_stl_ascii();
    let loaded = load_mesh_bytes(ascii.as_bytes(), MeshFormat::Stl, "a.stl").unwrap();
    assert_same_surface(&cube(), &loaded.mesh, false);
    assert_eq!(loaded.units.as_deref(), Some("mm"));
    assert_eq!(loaded.mesh.euler_characteristic(), 2);

    let mut binary = write_mesh(&cube(), MeshFormat::Stl, &meta_mm()).unwrap();
    binary[..80].fill(b' ');
    binary[..20].copy_from_slice(b"solid exported model");
    let mesh = read_mesh_bytes(&binary, MeshFormat::Stl, "b.stl").unwrap();
    assert_same_surface(&cube(), &mesh, false);
}

#[test]
fn stl_welds_negative_and_positive_zero_together() {
    let ascii = cube_stl_ascii().replacen("vertex 0 0 0", "vertex -0 0 -0", 1);
    let mesh = read_mesh_bytes(ascii.as_bytes(), MeshFormat::Stl, "z.stl").unwrap();
    assert_eq!(mesh.vertex_count(), 8);
    assert!(mesh.edge_report().is_closed_and_oriented());
}

#[test]
fn obj_triangulates_polygons_resolves_relative_indices_and_welds_objects() {
    let mut s = String::from("# units: mm\nmtllib missing.mtl\n");
    for p in &cube().positions {
        s += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    // Three quads in one object (one with relative indices), three in another.
    for (k, q) in QUADS.iter().enumerate() {
        if k == 3 {
            s += "o second\nusemtl none\n";
        }
        if k == 1 {
            let rel: Vec<String> = q.iter().map(|&i| (i as i64 - 8).to_string()).collect();
            s += &format!("f {}\n", rel.join(" "));
        } else {
            s += &format!("f {} {} {} {}\n", q[0] + 1, q[1] + 1, q[2] + 1, q[3] + 1);
        }
    }
    let loaded = load_mesh_bytes(s.as_bytes(), MeshFormat::Obj, "q.obj").unwrap();
    assert_eq!(loaded.units.as_deref(), Some("mm"));
    let m = &loaded.mesh;
    assert_eq!((m.vertex_count(), m.triangle_count()), (8, 12));
    assert!(m.edge_report().is_closed_and_oriented());
    assert!((m.signed_volume() - 1.0).abs() < 1e-12);
    assert!((m.area() - 6.0).abs() < 1e-12);
}

/// A glTF JSON document (buffer as data URI) with the node's transform replaced.
fn gltf_with_node(node: serde_json::Value) -> Vec<u8> {
    let bytes = write_mesh(&cube(), MeshFormat::Gltf, &MeshMetadata::default()).unwrap();
    let mut doc: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    let mut n = node;
    n["mesh"] = 0.into();
    doc["nodes"] = serde_json::json!([{"children": [1], "translation": [0.0, 0.0, 10.0]}, n]);
    doc["scenes"] = serde_json::json!([{"nodes": [0]}]);
    serde_json::to_vec(&doc).unwrap()
}

#[test]
fn gltf_node_transforms_are_applied_through_the_hierarchy() {
    let bytes = gltf_with_node(
        serde_json::json!({"translation": [1.0, 2.0, 3.0], "scale": [2.0, 2.0, 2.0]}),
    );
    let m = read_mesh_bytes(&bytes, MeshFormat::Gltf, "t.gltf").unwrap();
    let bb = m.bounding_box().unwrap();
    assert_eq!(bb.min, [1.0, 2.0, 13.0]);
    assert_eq!(bb.max, [3.0, 4.0, 15.0]);
    assert!((m.signed_volume() - 8.0).abs() < 1e-9);

    // A mirror keeps the surface outward-facing (volume stays positive).
    let mirrored = gltf_with_node(serde_json::json!({"scale": [-1.0, 1.0, 1.0]}));
    let m = read_mesh_bytes(&mirrored, MeshFormat::Gltf, "m.gltf").unwrap();
    assert_eq!(m.bounding_box().unwrap().min, [-1.0, 0.0, 10.0]);
    assert!((m.signed_volume() - 1.0).abs() < 1e-9);
}

/// The cube's buffer moved to an external file `cube.bin` next to `cube.gltf`.
fn external_gltf(uri: &str) -> (Vec<u8>, Vec<u8>) {
    let bytes = write_mesh(&cube(), MeshFormat::Glb, &MeshMetadata::default()).unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).unwrap();
    let mut doc = serde_json::to_value(gltf.document.as_json()).unwrap();
    doc["buffers"][0]["uri"] = uri.into();
    (serde_json::to_vec(&doc).unwrap(), gltf.blob.unwrap())
}

#[test]
fn gltf_external_buffers_need_the_files_directory() {
    let (json, bin) = external_gltf("cube.bin");
    let err = read_mesh_bytes(&json, MeshFormat::Gltf, "cube.gltf").unwrap_err();
    assert!(matches!(err, FormatError::Unsupported { .. }), "{err}");
    assert!(
        err.to_string().contains("external file \"cube.bin\""),
        "{err}"
    );

    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.gltf"), &json).unwrap();
    std::fs::write(dir.path().join("cube.bin"), &bin).unwrap();
    let m = read_mesh_file(&dir.path().join("cube.gltf")).unwrap();
    assert_same_surface(&cube(), &m, false);

    let (escaping, _) = external_gltf("../cube.bin");
    std::fs::write(dir.path().join("escape.gltf"), escaping).unwrap();
    let err = read_mesh_file(&dir.path().join("escape.gltf")).unwrap_err();
    assert!(
        err.to_string()
            .contains("not a file inside the glTF's directory"),
        "{err}"
    );
}

#[test]
fn files_are_written_and_read_by_extension_in_any_case() {
    let dir = tempfile::tempdir().unwrap();
    for ext in ["GLB", "gltf", "Stl", "obj", "PLY"] {
        let path = dir.path().join(format!("cube.{ext}"));
        write_mesh_file(&path, &cube(), &meta_mm()).unwrap();
        let loaded = load_mesh_file(&path).unwrap();
        assert_eq!(loaded.format, ext.parse().unwrap());
        assert_same_surface(&cube(), &loaded.mesh, false);
    }
    let err = write_mesh_file(Path::new("cube.step"), &cube(), &meta_mm()).unwrap_err();
    assert!(
        err.to_string().contains("unknown mesh format \"step\""),
        "{err}"
    );
    let err = read_mesh_file(&dir.path().join("missing.ply")).unwrap_err();
    assert!(
        !err.is_bad_input() && err.to_string().starts_with("missing.ply: cannot read file"),
        "{err}"
    );
}

#[test]
fn writing_an_invalid_mesh_is_refused() {
    let mut m = cube();
    m.positions[3][1] = f32::NAN;
    let err = write_mesh(&m, MeshFormat::Glb, &meta_mm()).unwrap_err();
    assert!(
        err.to_string()
            .contains("vertex 3 has a non-finite coordinate"),
        "{err}"
    );
}

#[test]
fn gltf_primitives_sharing_a_position_accessor_share_vertices() {
    let bytes = write_mesh(&cube(), MeshFormat::Gltf, &MeshMetadata::default()).unwrap();
    let mut doc: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    // Split the 36 indices into two accessors of 18 and give each its own primitive.
    let mut second = doc["accessors"][1].clone();
    doc["accessors"][1]["count"] = 18.into();
    second["count"] = 18.into();
    second["byteOffset"] = 72.into();
    doc["accessors"].as_array_mut().unwrap().push(second);
    let mut primitive = doc["meshes"][0]["primitives"][0].clone();
    primitive["indices"] = 2.into();
    doc["meshes"][0]["primitives"]
        .as_array_mut()
        .unwrap()
        .push(primitive);
    let m = read_mesh_bytes(
        &serde_json::to_vec(&doc).unwrap(),
        MeshFormat::Gltf,
        "two.gltf",
    )
    .unwrap();
    assert_same_surface(&cube(), &m, false);
    assert!(m.edge_report().is_closed_and_oriented());
}

fn run_mesh_command(args: &[&std::ffi::OsStr]) -> (bool, serde_json::Value, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_aortagen"))
        .arg("mesh")
        .args(args)
        .output()
        .unwrap();
    let json = serde_json::from_slice(&out.stdout).unwrap_or(serde_json::Value::Null);
    (
        out.status.success(),
        json,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn mesh_command_reports_measures_and_converts_with_units() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("cube.ply");
    let glb = dir.path().join("cube.glb");
    write_mesh_file(&ply, &cube(), &meta_mm()).unwrap();
    let (ok, r, err) = run_mesh_command(&[
        ply.as_os_str(),
        "--json".as_ref(),
        "--convert".as_ref(),
        glb.as_os_str(),
    ]);
    assert!(ok, "{err}");
    assert_eq!(
        (r["format"].as_str(), r["units"].as_str()),
        (Some("ply"), Some("mm"))
    );
    assert_eq!(
        (r["vertices"].as_u64(), r["triangles"].as_u64()),
        (Some(8), Some(12))
    );
    assert!((r["surface_area"].as_f64().unwrap() - 6.0).abs() < 1e-12);
    assert!((r["enclosed_volume"].as_f64().unwrap() - 1.0).abs() < 1e-12);
    assert_eq!(
        (r["closed"].as_bool(), r["euler_characteristic"].as_i64()),
        (Some(true), Some(2))
    );
    assert_eq!(r["bbox_size"], serde_json::json!([1.0, 1.0, 1.0]));
    assert_eq!(r["converted_to"]["format"], "glb");

    let converted = load_mesh_file(&glb).unwrap();
    assert_eq!(converted.units.as_deref(), Some("mm"));
    assert_eq!(
        converted.extras.unwrap()["provenance"]["converted_from"],
        "cube.ply"
    );
    assert_same_surface(&cube(), &converted.mesh, false);

    // An open surface: volume is withheld, the hole is counted.
    let mut open = cube();
    open.triangles.pop();
    let obj = dir.path().join("open.obj");
    write_mesh_file(&obj, &open, &meta_mm()).unwrap();
    let (ok, r, _) = run_mesh_command(&[obj.as_os_str(), "--json".as_ref()]);
    assert!(ok);
    assert_eq!(
        (r["closed"].as_bool(), r["boundary_edges"].as_u64()),
        (Some(false), Some(3))
    );
    assert!(r["enclosed_volume"].is_null());
}

#[test]
fn mesh_command_fails_with_the_reason_on_a_bad_file() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.ply");
    std::fs::write(&bad, b"not a mesh").unwrap();
    let (ok, _, err) = run_mesh_command(&[bad.as_os_str()]);
    assert!(!ok);
    assert!(
        err.contains("bad.ply: PLY parse error in header line 1"),
        "{err}"
    );
}
