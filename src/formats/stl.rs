//! STL: binary and ASCII reading through `stl_io`, binary writing. STL stores each
//! triangle's corners separately, so exactly equal positions are welded into shared
//! vertices on read (needed for closedness checks).

use std::collections::HashMap;
use std::io::Cursor;

use super::{FormatError, LoadedMesh, MeshFormat, MeshMetadata, guard, units_in};
use crate::geometry::TriMesh;

const HEADER: usize = 80;
const FACET: usize = 50;

/// Reads binary or ASCII STL, telling them apart by content.
pub(super) fn read(bytes: &[u8], name: &str) -> Result<LoadedMesh, FormatError> {
    let (mesh, units) = if is_ascii(bytes) {
        (read_ascii(bytes, name)?, units_in(&first_line(bytes)))
    } else {
        let header = String::from_utf8_lossy(&bytes[..bytes.len().min(HEADER)]);
        (
            read_binary(bytes, name)?,
            units_in(header.trim_end_matches('\0')),
        )
    };
    Ok(LoadedMesh {
        mesh,
        format: MeshFormat::Stl,
        units,
        extras: None,
    })
}

/// ASCII when the text starts with `solid`, looks like text, and its size is not exactly
/// that of a binary STL (some binary exporters also start their header with "solid").
fn is_ascii(bytes: &[u8]) -> bool {
    let starts_solid = bytes.trim_ascii_start().starts_with(b"solid");
    let head = &bytes[..bytes.len().min(1024)];
    let textual = head
        .iter()
        .all(|b| b.is_ascii_graphic() || b.is_ascii_whitespace());
    starts_solid
        && textual
        && binary_count(bytes).is_none_or(|n| HEADER + 4 + FACET * n != bytes.len())
}

fn binary_count(bytes: &[u8]) -> Option<usize> {
    let raw: [u8; 4] = bytes.get(HEADER..HEADER + 4)?.try_into().ok()?;
    Some(u32::from_le_bytes(raw) as usize)
}

fn first_line(bytes: &[u8]) -> String {
    let line = bytes.split(|&b| b == b'\n').next().unwrap_or_default();
    String::from_utf8_lossy(line).into_owned()
}

fn read_binary(bytes: &[u8], name: &str) -> Result<TriMesh, FormatError> {
    let Some(count) = binary_count(bytes) else {
        return Err(FormatError::malformed(
            name,
            MeshFormat::Stl,
            format!(
                "truncated binary STL: {} bytes, but the 80-byte header and 4-byte triangle \
                 count alone need 84",
                bytes.len()
            ),
        ));
    };
    let holds = (bytes.len() - HEADER - 4) / FACET;
    if holds < count {
        return Err(FormatError::malformed(
            name,
            MeshFormat::Stl,
            format!(
                "truncated binary STL: header says {count} triangles, file holds bytes for {holds}"
            ),
        ));
    }
    // stl_io decides ASCII vs binary by a "solid " prefix; hide it so that binary is parsed.
    let patched;
    let data = if bytes.starts_with(b"solid") {
        let mut copy = bytes[..HEADER + 4 + FACET * count].to_vec();
        copy[..5].copy_from_slice(b"SOLID");
        patched = copy;
        &patched[..]
    } else {
        &bytes[..HEADER + 4 + FACET * count]
    };
    collect(data, name, |i| {
        format!("facet {i} (byte offset {})", HEADER + 4 + FACET * i)
    })
}

fn read_ascii(bytes: &[u8], name: &str) -> Result<TriMesh, FormatError> {
    // stl_io wants the file to start exactly with "solid "; tolerate indentation and a
    // nameless "solid".
    let body = bytes.trim_ascii_start();
    let line_end = body.iter().position(|&b| b == b'\n').unwrap_or(body.len());
    let mut normalised = b"solid ".to_vec();
    normalised.extend_from_slice(body[5..line_end].trim_ascii());
    normalised.extend_from_slice(&body[line_end..]);
    collect(&normalised, name, |i| format!("facet {i}"))
}

/// Iterates the triangles with stl_io and welds exactly equal positions.
fn collect(data: &[u8], name: &str, at: impl Fn(usize) -> String) -> Result<TriMesh, FormatError> {
    let result = guard(|| -> Result<TriMesh, FormatError> {
        let mut cursor = Cursor::new(data);
        let reader = stl_io::create_stl_reader(&mut cursor)
            .map_err(|e| FormatError::malformed(name, MeshFormat::Stl, e.to_string()))?;
        let mut welder = Welder::default();
        for (i, triangle) in reader.enumerate() {
            let t = triangle.map_err(|e| {
                FormatError::malformed_at(name, MeshFormat::Stl, at(i), e.to_string())
            })?;
            if let Some(v) = t
                .vertices
                .iter()
                .find(|v| v.0.iter().any(|c| !c.is_finite()))
            {
                return Err(FormatError::malformed_at(
                    name,
                    MeshFormat::Stl,
                    at(i),
                    format!("non-finite vertex coordinate {:?}", v.0),
                ));
            }
            welder.push(t.vertices.map(|v| v.0));
        }
        Ok(welder.finish())
    });
    result.map_err(|msg| FormatError::malformed(name, MeshFormat::Stl, msg))?
}

/// Builds an indexed mesh from triangle soup, merging positions that are exactly equal
/// (+0.0 and -0.0 count as equal).
#[derive(Default)]
struct Welder {
    index: HashMap<[u32; 3], u32>,
    mesh: TriMesh,
}

impl Welder {
    fn push(&mut self, corners: [[f32; 3]; 3]) {
        let tri = corners.map(|p| {
            let key = p.map(|c| (c + 0.0).to_bits());
            *self.index.entry(key).or_insert_with(|| {
                self.mesh.positions.push(p);
                (self.mesh.positions.len() - 1) as u32
            })
        });
        self.mesh.triangles.push(tri);
    }

    fn finish(self) -> TriMesh {
        self.mesh
    }
}

/// Binary STL with face normals from the geometry and the units in the header text.
pub(super) fn write(mesh: &TriMesh, meta: &MeshMetadata) -> Vec<u8> {
    let triangles: Vec<stl_io::Triangle> = (0..mesh.triangle_count())
        .map(|t| stl_io::Triangle {
            normal: stl_io::Normal::new(mesh.face_normal(t).map(|c| c as f32)),
            vertices: mesh.triangles[t].map(|i| stl_io::Vertex::new(mesh.positions[i as usize])),
        })
        .collect();
    let mut out = Vec::with_capacity(HEADER + 4 + FACET * triangles.len());
    stl_io::write_stl(&mut out, triangles.iter()).expect("writing to a Vec cannot fail");
    // The header must not start with "solid" (readers would take it for ASCII).
    let text = format!("binary STL, units {}, {}", meta.units, meta.generator);
    let n = text.len().min(HEADER);
    out[..n].copy_from_slice(&text.as_bytes()[..n]);
    out
}
