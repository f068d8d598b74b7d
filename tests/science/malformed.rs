//! Malformed input: each case must fail with an error naming the file, the format and
//! the fact that is wrong; nothing may panic.

use super::*;

/// Deterministic junk bytes (a linear congruential generator).
fn garbage(len: usize, seed: u32) -> Vec<u8> {
    let mut x = seed;
    (0..len)
        .map(|_| {
            x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (x >> 24) as u8
        })
        .collect()
}

/// Byte offset of the BIN chunk's data in a GLB.
fn glb_bin_start(glb: &[u8]) -> usize {
    20 + u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize + 8
}

fn obj_text(mesh: &TriMesh) -> String {
    String::from_utf8(write_mesh(mesh, MeshFormat::Obj, &meta_mm()).unwrap()).unwrap()
}

/// One malformed input and the facts its error message must state.
struct Case {
    label: &'static str,
    format: MeshFormat,
    bytes: Vec<u8>,
    facts: &'static [&'static str],
}

fn malformed_cases() -> Vec<Case> {
    use MeshFormat::*;
    let stl = write_mesh(&cube(), Stl, &meta_mm()).unwrap();
    let glb = write_mesh(&cube(), Glb, &meta_mm()).unwrap();
    let ply = write_mesh(&cube(), Ply, &meta_mm()).unwrap();
    let ply_body = ply.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let mut stl_nan = stl.clone();
    stl_nan[84 + 50 * 2 + 12..84 + 50 * 2 + 16].copy_from_slice(&f32::NAN.to_le_bytes());
    let mut glb_nan = glb.clone();
    let bin = glb_bin_start(&glb);
    glb_nan[bin + 4..bin + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    let mut glb_index = glb.clone();
    glb_index[bin + 96 + 8..bin + 96 + 12].copy_from_slice(&40u32.to_le_bytes());
    let mut ply_nan = ply.clone();
    ply_nan[ply_body + 12 * 5 + 8..ply_body + 12 * 5 + 12].copy_from_slice(&f32::NAN.to_le_bytes());
    let ascii_ply = String::from_utf8(ascii_ply()).unwrap();
    let obj = obj_text(&cube());
    let gltf = String::from_utf8(write_mesh(&cube(), Gltf, &meta_mm()).unwrap()).unwrap();
    let case = |label, format, bytes: Vec<u8>, facts| Case {
        label,
        format,
        bytes,
        facts,
    };
    vec![
        // STL
        case("stl empty", Stl, vec![], &["x.stl", "STL", "empty file"]),
        case(
            "stl truncated",
            Stl,
            stl[..84 + 50 * 3 + 17].to_vec(),
            &["truncated binary STL: header says 12 triangles, file holds bytes for 3"],
        ),
        case(
            "stl short header",
            Stl,
            stl[..40].to_vec(),
            &["truncated binary STL: 40 bytes"],
        ),
        case(
            "stl garbage",
            Stl,
            garbage(300, 1),
            &["truncated binary STL: header says"],
        ),
        case(
            "stl nan binary",
            Stl,
            stl_nan,
            &["facet 2 (byte offset 184)", "non-finite"],
        ),
        case(
            "stl nan ascii",
            Stl,
            cube_stl_ascii()
                .replacen("vertex 1 0 0", "vertex nan 0 0", 1)
                .into_bytes(),
            &["facet 0", "finite"],
        ),
        case(
            "stl ascii broken facet",
            Stl,
            cube_stl_ascii()
                .replacen("outer loop", "outer lop", 1)
                .into_bytes(),
            &["facet 0", "outer"],
        ),
        // OBJ
        case("obj empty", Obj, vec![], &["x.obj", "empty file"]),
        case(
            "obj truncated",
            Obj,
            obj.as_bytes()[..obj.find("v 1 0 0").unwrap() + 5].to_vec(),
            &["line 8", "position parse error"],
        ),
        case(
            "obj garbage",
            Obj,
            garbage(300, 2),
            &["OBJ", "line 1", "read error"],
        ),
        case(
            "obj nan",
            Obj,
            obj.replacen("v 1 0 0", "v 1 NaN 0", 1).into_bytes(),
            &["invalid OBJ mesh", "non-finite coordinate"],
        ),
        case(
            "obj index",
            Obj,
            obj.replacen("f 6 8 7", "f 6 40 7", 1).into_bytes(),
            &["line 18", "vertex 40 but only 8 exist"],
        ),
        case(
            "obj no faces",
            Obj,
            b"v 0 0 0\nv 1 0 0\n".to_vec(),
            &["mesh is empty"],
        ),
        // PLY
        case("ply empty", Ply, vec![], &["x.ply", "empty file"]),
        case(
            "ply truncated",
            Ply,
            ply[..ply.len() - 20].to_vec(),
            &["element 'face'", "12 'face' elements", "truncated"],
        ),
        case(
            "ply garbage",
            Ply,
            garbage(300, 3),
            &["PLY parse error in header line 1", "magic number 'ply'"],
        ),
        case(
            "ply non-utf8 header",
            Ply,
            [
                b"ply\nformat ascii 1.0\ncomment ".as_slice(),
                &[0xff, 0xfe, b'\n'],
            ]
            .concat(),
            &["header line 3", "UTF-8"],
        ),
        case(
            "ply bad header",
            Ply,
            ascii_ply
                .replacen("element face 6", "element face six", 1)
                .into_bytes(),
            &["header line 11"],
        ),
        case(
            "ply nan",
            Ply,
            ply_nan,
            &["vertex 5 has a non-finite coordinate"],
        ),
        case(
            "ply index",
            Ply,
            ascii_ply
                .replacen("4 0 2 3 1", "4 0 2 40 1", 1)
                .into_bytes(),
            &["face 0", "vertex 40 but only 8 exist"],
        ),
        case(
            "ply ascii short line",
            Ply,
            ascii_ply.replacen("4 1 3 7 5", "4 1 3", 1).into_bytes(),
            &["line 27", "element 'face'"],
        ),
        case(
            "ply two-vertex face",
            Ply,
            ascii_ply.replacen("4 1 3 7 5", "2 1 3", 1).into_bytes(),
            &["face 5", "at least 3 vertices"],
        ),
        // GLB
        case("glb empty", Glb, vec![], &["x.glb", "GLB", "empty file"]),
        case(
            "glb truncated",
            Glb,
            glb[..glb.len() - 30].to_vec(),
            &[
                "GLB parse error in GLB header",
                "truncated GLB: header declares",
            ],
        ),
        case(
            "glb truncated header",
            Glb,
            glb[..10].to_vec(),
            &["truncated GLB: 10 bytes"],
        ),
        case(
            "glb garbage",
            Glb,
            [b"glTF".as_slice(), &garbage(300, 4)].concat(),
            &["GLB parse error", "GLB version"],
        ),
        case(
            "glb bad chunk",
            Glb,
            [&glb[..8], &312u32.to_le_bytes(), &garbage(300, 6)].concat(),
            &["GLB parse error"],
        ),
        case(
            "glb nan",
            Glb,
            glb_nan,
            &["invalid GLB mesh", "vertex 0 has a non-finite coordinate"],
        ),
        case(
            "glb index",
            Glb,
            glb_index,
            &["mesh 0 primitive 0", "vertex 40 but only 8 exist"],
        ),
        // glTF JSON
        case(
            "gltf empty",
            Gltf,
            vec![],
            &["x.gltf", "glTF", "empty file"],
        ),
        case(
            "gltf truncated",
            Gltf,
            gltf.as_bytes()[..gltf.len() / 2].to_vec(),
            &["glTF parse error", "EOF"],
        ),
        case("gltf garbage", Gltf, garbage(300, 5), &["glTF parse error"]),
        case(
            "gltf nan literal",
            Gltf,
            gltf.replacen("\"min\": [\n", "\"min\": [NaN,\n", 1)
                .into_bytes(),
            &["glTF parse error", "line"],
        ),
        case(
            "gltf index",
            Gltf,
            gltf.replacen("\"count\": 36", "\"count\": 40", 1)
                .into_bytes(),
            &[
                "mesh 0 primitive 0",
                "indices: 40 elements of 4 bytes from offset 0 do not fit in the buffer view's 144 bytes",
            ],
        ),
        // gltf's readers compute an accessor's end without checking it: these underflowed,
        // overflowed or read elements overlapping each other.
        case(
            "gltf empty positions",
            Gltf,
            gltf.replacen("\"count\": 8", "\"count\": 0", 1)
                .into_bytes(),
            &["mesh 0 primitive 0", "Positions: the accessor has count 0"],
        ),
        case(
            "gltf huge count",
            Gltf,
            gltf.replacen("\"count\": 36", "\"count\": 9223372036854775807", 1)
                .into_bytes(),
            &[
                "indices: 9223372036854775807 elements of 4 bytes",
                "do not fit",
            ],
        ),
        case(
            "gltf short stride",
            Gltf,
            gltf.replacen(
                "\"byteOffset\": 0,",
                "\"byteOffset\": 0, \"byteStride\": 8,",
                1,
            )
            .into_bytes(),
            &["Positions: the buffer view's stride 8 is smaller than the element size 12"],
        ),
        // Found by fuzzing: float indices made the glTF crate reach `unreachable!`.
        case(
            "gltf float indices",
            Gltf,
            gltf.replacen("\"componentType\": 5125", "\"componentType\": 5126", 1)
                .into_bytes(),
            &[
                "mesh 0 primitive 0",
                "indices must be unsigned integers",
                "F32",
            ],
        ),
    ]
}

#[test]
fn malformed_input_gives_an_error_that_names_file_format_and_place() {
    let mut failures = Vec::new();
    for case in malformed_cases() {
        let name = format!("x.{}", case.format.extension());
        match read_mesh_bytes(&case.bytes, case.format, &name) {
            Ok(m) => failures.push(format!(
                "{}: accepted ({} triangles)",
                case.label,
                m.triangle_count()
            )),
            Err(e) => {
                let msg = e.to_string();
                let missing: Vec<_> = case.facts.iter().filter(|f| !msg.contains(**f)).collect();
                if !msg.starts_with(&name) || !missing.is_empty() || !e.is_bad_input() {
                    failures.push(format!("{}: {msg:?} lacks {missing:?}", case.label));
                }
            }
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

/// Every prefix and many single-byte corruptions of each format's file either read as a
/// valid mesh or fail with an error that names the file: never a panic.
#[test]
fn truncated_and_corrupted_files_never_panic() {
    let mesh = odd_cube_with_normals();
    for format in MeshFormat::ALL {
        let good = write_mesh(&mesh, format, &meta_mm()).unwrap();
        let name = format!("f.{}", format.extension());
        let mut inputs: Vec<Vec<u8>> = (0..good.len()).map(|n| good[..n].to_vec()).collect();
        let noise = garbage(4 * 400, format as u32 + 10);
        for k in noise.chunks_exact(4) {
            let mut bad = good.clone();
            let at = u32::from_le_bytes([k[0], k[1], k[2], 0]) as usize % bad.len();
            bad[at] = k[3];
            inputs.push(bad);
        }
        for (i, input) in inputs.iter().enumerate() {
            match read_mesh_bytes(input, format, &name) {
                Ok(m) => assert!(m.validate().is_ok(), "{format} input {i}"),
                Err(e) => {
                    let msg = e.to_string();
                    assert!(
                        msg.starts_with(&name) && !msg.contains("parser failed"),
                        "{format} input {i}: {msg}"
                    );
                }
            }
        }
    }
}

/// Inputs that made a fuzz target fail: each must give an error naming the file.
#[test]
fn inputs_found_by_fuzzing_are_errors() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/formats/fuzz_found");
    for (file, format, expected) in [
        // tobj multiplies a huge texture index without overflow checks; the reader checks
        // indices before tobj sees them.
        (
            "tobj_texcoord_overflow.obj",
            MeshFormat::Obj,
            "face refers to texture coordinate",
        ),
        (
            "float_indices.glb",
            MeshFormat::Glb,
            "indices must be unsigned integers",
        ),
        // gltf's attribute reader asserts the element size of a mistyped NORMAL accessor.
        (
            "scalar_normals.gltf",
            MeshFormat::Gltf,
            "Normals: the accessor must be VEC3 of FLOAT",
        ),
        // No accessors (the key is misspelt) and invalid UTF-8 in a field the parser skips:
        // gltf's validation indexed the empty accessor list.
        (
            "dangling_position_invalid_utf8.gltf",
            MeshFormat::Gltf,
            "refers to accessor 1, but there are only 0",
        ),
        // A NORMAL accessor with count 0: gltf's reader computed its end as `count − 1`.
        (
            "empty_normal_accessor.glb",
            MeshFormat::Glb,
            "Normals: the accessor has count 0",
        ),
        // An element count of 5·10¹⁵ vertices in a 2 kB file: the parser allocated for it.
        (
            "huge_element_count.ply",
            MeshFormat::Ply,
            "elements, at least",
        ),
    ] {
        let bytes = std::fs::read(dir.join(file)).unwrap();
        let err = read_mesh_bytes(&bytes, format, file)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(file) && err.contains(expected) && !err.contains("parser failed"),
            "{file}: {err}"
        );
    }
}
