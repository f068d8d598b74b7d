//! Minimal binary little-endian PLY for triangle meshes: `float x y z` vertices and
//! `list uchar int` faces, the layout of the SynthAorta files. It keeps the `synth` and
//! `render` commands self-contained; the general readers and writers live in
//! [`crate::formats`].

use crate::geometry::TriMesh;

/// Why a PLY byte stream could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlyError {
    /// The header is missing, malformed or describes an unsupported layout.
    #[error("PLY header: {0}")]
    Header(String),
    /// The body ends before all declared elements were read.
    #[error("PLY body is truncated: expected {expected} bytes of {element} data, found {found}")]
    Truncated {
        /// Which element was being read.
        element: &'static str,
        /// Bytes required.
        expected: usize,
        /// Bytes present.
        found: usize,
    },
    /// A face is not a triangle.
    #[error("PLY face {face} has {count} vertices; only triangles are supported")]
    NotTriangle {
        /// Face index.
        face: usize,
        /// Vertex count found.
        count: u8,
    },
}

/// Serialises `mesh` as binary little-endian PLY with a units comment.
pub fn write_ply(mesh: &TriMesh, comment: &str) -> Vec<u8> {
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment {}\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nelement face {}\n\
         property list uchar int vertex_indices\nend_header\n",
        comment.replace('\n', " "),
        mesh.positions.len(),
        mesh.triangles.len()
    );
    let mut out =
        Vec::with_capacity(header.len() + 12 * mesh.positions.len() + 13 * mesh.triangles.len());
    out.extend_from_slice(header.as_bytes());
    for p in &mesh.positions {
        for c in p {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    for t in &mesh.triangles {
        out.push(3);
        for &i in t {
            out.extend_from_slice(&(i as i32).to_le_bytes());
        }
    }
    out
}

/// Parses the layout written by [`write_ply`] (any comments allowed).
pub fn read_ply(bytes: &[u8]) -> Result<TriMesh, PlyError> {
    let end = b"end_header\n";
    let body_start = bytes
        .windows(end.len())
        .position(|w| w == end)
        .ok_or_else(|| PlyError::Header("no `end_header` line".into()))?
        + end.len();
    let header = std::str::from_utf8(&bytes[..body_start])
        .map_err(|_| PlyError::Header("header is not UTF-8".into()))?;
    let lines: Vec<&str> = header
        .lines()
        .map(str::trim)
        .filter(|l| !l.starts_with("comment") && !l.starts_with("obj_info"))
        .collect();
    let expected_props = ["property float x", "property float y", "property float z"];
    let count = |line: Option<&&str>, element: &str| -> Result<usize, PlyError> {
        line.and_then(|l| l.strip_prefix(&format!("element {element} ")))
            .and_then(|n| n.trim().parse().ok())
            .ok_or_else(|| PlyError::Header(format!("expected `element {element} <count>`")))
    };
    if lines.first() != Some(&"ply") || lines.get(1) != Some(&"format binary_little_endian 1.0") {
        return Err(PlyError::Header(
            "only binary_little_endian 1.0 PLY is supported".into(),
        ));
    }
    let vertices = count(lines.get(2), "vertex")?;
    if lines.get(3..6) != Some(&expected_props[..]) {
        return Err(PlyError::Header(
            "vertices must have exactly `float x y z`".into(),
        ));
    }
    let faces = count(lines.get(6), "face")?;
    let list = lines.get(7).copied().unwrap_or_default();
    let index_is_int = matches!(
        list,
        "property list uchar int vertex_indices"
            | "property list uchar int vertex_index"
            | "property list uchar uint vertex_indices"
            | "property list uchar uint vertex_index"
    );
    if !index_is_int || lines.get(8) != Some(&"end_header") {
        return Err(PlyError::Header(format!(
            "unsupported face layout `{list}`"
        )));
    }
    let body = &bytes[body_start..];
    let vbytes = 12 * vertices;
    if body.len() < vbytes {
        return Err(PlyError::Truncated {
            element: "vertex",
            expected: vbytes,
            found: body.len(),
        });
    }
    let f32_at = |o: usize| f32::from_le_bytes(body[o..o + 4].try_into().expect("4 bytes"));
    let positions = (0..vertices)
        .map(|v| std::array::from_fn(|k| f32_at(12 * v + 4 * k)))
        .collect();
    let fbody = &body[vbytes..];
    if fbody.len() < 13 * faces {
        return Err(PlyError::Truncated {
            element: "face",
            expected: 13 * faces,
            found: fbody.len(),
        });
    }
    let mut triangles = Vec::with_capacity(faces);
    for f in 0..faces {
        let rec = &fbody[13 * f..13 * f + 13];
        if rec[0] != 3 {
            return Err(PlyError::NotTriangle {
                face: f,
                count: rec[0],
            });
        }
        triangles.push(std::array::from_fn(|k| {
            u32::from_le_bytes(rec[1 + 4 * k..5 + 4 * k].try_into().expect("4 bytes"))
        }));
    }
    Ok(TriMesh::new(positions, triangles))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra() -> TriMesh {
        TriMesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.5],
            ],
            vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
        )
    }

    #[test]
    fn round_trip_preserves_the_mesh_exactly() {
        let m = tetra();
        let back = read_ply(&write_ply(&m, "units mm")).unwrap();
        assert_eq!(back, m);
    }

    #[test]
    fn truncated_and_foreign_files_are_rejected_with_a_reason() {
        let bytes = write_ply(&tetra(), "x");
        let cut = &bytes[..bytes.len() - 5];
        assert!(matches!(
            read_ply(cut),
            Err(PlyError::Truncated {
                element: "face",
                ..
            })
        ));
        let ascii = b"ply\nformat ascii 1.0\nelement vertex 0\nend_header\n";
        assert!(matches!(read_ply(ascii), Err(PlyError::Header(_))));
        assert!(matches!(read_ply(b"solid cube"), Err(PlyError::Header(_))));
        let mut quad = bytes.clone();
        let face0 = quad.len() - 4 * 13;
        quad[face0] = 4;
        assert_eq!(
            read_ply(&quad),
            Err(PlyError::NotTriangle { face: 0, count: 4 })
        );
    }
}
