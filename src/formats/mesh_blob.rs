//! The compact binary form in which a shape's unit-ball mesh is stored: the mesh is kept
//! once, in its normalised frame, and converted to the requested format and units on
//! download.
//!
//! Layout (little endian): magic `AGM1`, flags `u32` (bit 0: normals present), vertex count
//! `u32`, triangle count `u32`, positions `3×f32` per vertex, normals `3×f32` per vertex when
//! flagged, triangles `3×u32`. About 24 bytes per vertex with normals plus 12 per triangle,
//! a third of a GLB with the same content and trivially validated on read.

use crate::geometry::TriMesh;

const MAGIC: &[u8; 4] = b"AGM1";
const HEADER_LEN: usize = 16;
const FLAG_NORMALS: u32 = 1;

/// Why stored mesh bytes cannot be decoded (a corrupted or foreign blob).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MeshBlobError {
    /// The first four bytes are not `AGM1`.
    #[error("mesh blob does not start with the AGM1 magic")]
    BadMagic,
    /// The length does not match the counts in the header.
    #[error("mesh blob is {actual} bytes but its header announces {expected}")]
    BadLength {
        /// Length implied by the header.
        expected: usize,
        /// Actual length.
        actual: usize,
    },
    /// The decoded mesh fails validation.
    #[error("mesh blob holds an invalid mesh: {0}")]
    Invalid(#[from] crate::geometry::MeshError),
}

/// Encodes `mesh` (normals included when present).
pub fn encode(mesh: &TriMesh) -> Vec<u8> {
    let n = mesh.positions.len();
    let normals = mesh.normals.as_ref().filter(|v| v.len() == n);
    let flags = if normals.is_some() { FLAG_NORMALS } else { 0 };
    let mut out = Vec::with_capacity(encoded_len(n, mesh.triangles.len(), normals.is_some()));
    out.extend_from_slice(MAGIC);
    for word in [flags, n as u32, mesh.triangles.len() as u32] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    let floats = mesh.positions.iter().chain(normals.into_iter().flatten());
    for v in floats.flatten() {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for i in mesh.triangles.iter().flatten() {
        out.extend_from_slice(&i.to_le_bytes());
    }
    out
}

/// The hex SHA-256 of an encoded mesh: the identity of a stored shape's geometry.
pub fn sha256_hex(encoded: &[u8]) -> String {
    crate::digest::sha256_hex(encoded)
}

/// Decodes and validates a blob written by [`encode`].
pub fn decode(bytes: &[u8]) -> Result<TriMesh, MeshBlobError> {
    if bytes.len() < HEADER_LEN || &bytes[..4] != MAGIC {
        return Err(MeshBlobError::BadMagic);
    }
    let word = |i: usize| u32::from_le_bytes(bytes[4 + 4 * i..8 + 4 * i].try_into().unwrap());
    let (flags, n, t) = (word(0), word(1) as usize, word(2) as usize);
    let has_normals = flags & FLAG_NORMALS != 0;
    let expected = encoded_len(n, t, has_normals);
    if bytes.len() != expected {
        return Err(MeshBlobError::BadLength {
            expected,
            actual: bytes.len(),
        });
    }
    let mut words = bytes[HEADER_LEN..]
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]]);
    let mut read_vec3 = |count: usize| -> Vec<[f32; 3]> {
        (0..count)
            .map(|_| std::array::from_fn(|_| f32::from_le_bytes(words.next().unwrap())))
            .collect()
    };
    let positions = read_vec3(n);
    let normals = has_normals.then(|| read_vec3(n));
    let triangles = (0..t)
        .map(|_| std::array::from_fn(|_| u32::from_le_bytes(words.next().unwrap())))
        .collect();
    let mesh = TriMesh {
        positions,
        triangles,
        normals,
    };
    mesh.validate()?;
    Ok(mesh)
}

fn encoded_len(vertices: usize, triangles: usize, normals: bool) -> usize {
    HEADER_LEN + vertices * 12 * (1 + usize::from(normals)) + triangles * 12
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetrahedron() -> TriMesh {
        let positions = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let triangles = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        TriMesh::new(positions, triangles)
    }

    #[test]
    fn round_trip_preserves_positions_triangles_and_normals_exactly() {
        let mut mesh = tetrahedron();
        mesh.normals = Some(mesh.compute_vertex_normals());
        let bytes = encode(&mesh);
        assert_eq!(bytes.len(), 16 + 4 * 24 + 4 * 12);
        assert_eq!(decode(&bytes).unwrap(), mesh);

        let plain = tetrahedron();
        assert_eq!(decode(&encode(&plain)).unwrap(), plain);
    }

    #[test]
    fn truncated_or_foreign_bytes_are_rejected_not_misread() {
        let bytes = encode(&tetrahedron());
        assert_eq!(
            decode(&bytes[..bytes.len() - 1]),
            Err(MeshBlobError::BadLength {
                expected: bytes.len(),
                actual: bytes.len() - 1
            })
        );
        assert_eq!(
            decode(b"glTF\0\0\0\0\0\0\0\0\0\0\0\0"),
            Err(MeshBlobError::BadMagic)
        );
        let mut bad_index = bytes.clone();
        let last = bad_index.len() - 4;
        bad_index[last..].copy_from_slice(&99u32.to_le_bytes());
        assert!(matches!(decode(&bad_index), Err(MeshBlobError::Invalid(_))));
    }
}
