//! Stanford PLY through `ply-rs-bw`: ASCII and binary of both endiannesses, faces as
//! `vertex_indices` or `vertex_index` lists of any integer type (polygons split as fans),
//! optional `nx ny nz` normals. Written as binary little-endian.

use std::fmt::Write as _;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    DefaultElement, ElementDef, Encoding, Header, Property, PropertyType, ScalarType,
};

use super::{FormatError, LoadedMesh, MeshFormat, MeshMetadata, guard, units_in};
use crate::geometry::TriMesh;

const FORMAT: MeshFormat = MeshFormat::Ply;

/// Reads a PLY file; errors name the header line, the payload line (ASCII) or the element.
pub(super) fn read(bytes: &[u8], name: &str) -> Result<LoadedMesh, FormatError> {
    let (header, vertices, faces) =
        guard(|| parse(bytes, name)).map_err(|msg| FormatError::malformed(name, FORMAT, msg))??;
    let units = header
        .comments
        .iter()
        .chain(&header.obj_infos)
        .find_map(|c| units_in(c));
    let mut mesh = TriMesh {
        positions: coordinates(&vertices, ["x", "y", "z"], name, "position")?.ok_or_else(|| {
            FormatError::malformed(name, FORMAT, "element 'vertex' lacks x, y or z")
        })?,
        triangles: Vec::new(),
        normals: coordinates(&vertices, ["nx", "ny", "nz"], name, "normal")?,
    };
    mesh.triangles = triangulate(&faces, mesh.positions.len(), name)?;
    Ok(LoadedMesh {
        mesh,
        format: FORMAT,
        units,
        extras: None,
    })
}

type Parsed = (Header, Vec<DefaultElement>, Vec<DefaultElement>);

/// Header, then every element in order (unknown elements are read and dropped).
fn parse(bytes: &[u8], name: &str) -> Result<Parsed, FormatError> {
    if !(bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r")) {
        return Err(FormatError::malformed_at(
            name,
            FORMAT,
            "header line 1",
            "not a PLY file: it does not start with the magic number 'ply'",
        ));
    }
    let parser = Parser::<DefaultElement>::new();
    let mut reader = Reader::new(bytes);
    let header = match parser.read_header(&mut reader) {
        Ok(header) => header,
        Err(e) => {
            let line = e.line().unwrap_or(reader.line());
            let message = flatten(&e.to_string());
            return Err(FormatError::malformed_at(
                name,
                FORMAT,
                format!("header line {line}"),
                message,
            ));
        }
    };
    // The parser keeps every element in memory: refuse counts the file cannot hold before
    // it allocates for them.
    let payload = reader.get_ref().len();
    for (key, def) in &header.elements {
        let least = def
            .count
            .saturating_mul(min_element_bytes(def, header.encoding));
        if least > payload {
            return Err(FormatError::malformed_at(
                name,
                FORMAT,
                format!("element '{key}'"),
                format!(
                    "the header declares {} '{key}' elements, at least {least} bytes, but only \
                     {payload} bytes follow the header",
                    def.count
                ),
            ));
        }
    }
    let (mut vertices, mut faces) = (None, None);
    for (key, def) in &header.elements {
        let elements = parser
            .read_payload_for_element(&mut reader, def, &header)
            .map_err(|e| {
                let at = match (header.encoding, e.line()) {
                    (Encoding::Ascii, Some(l)) => format!("line {l} (element '{key}')"),
                    _ => format!("element '{key}'"),
                };
                let hint = if header.encoding == Encoding::Ascii {
                    ""
                } else {
                    "; file truncated?"
                };
                let message = format!(
                    "{} (header declares {} '{key}' elements, {:?} encoding{hint})",
                    flatten(&e.to_string()),
                    def.count,
                    header.encoding
                );
                FormatError::malformed_at(name, FORMAT, at, message)
            })?;
        match key.as_str() {
            "vertex" => vertices = Some(elements),
            "face" => faces = Some(elements),
            _ => {}
        }
    }
    let missing =
        |what| FormatError::malformed_at(name, FORMAT, "header", format!("no '{what}' element"));
    Ok((
        header,
        vertices.ok_or_else(|| missing("vertex"))?,
        faces.ok_or_else(|| missing("face"))?,
    ))
}

/// The fewest bytes one element of `def` takes: its scalars' sizes (a list at least its
/// length field) in binary, two characters per property in ASCII; at least one byte.
fn min_element_bytes(def: &ElementDef, encoding: Encoding) -> usize {
    let size = |t: &ScalarType| match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    };
    let bytes: usize = match encoding {
        Encoding::Ascii => 2 * def.properties.len(),
        _ => def
            .properties
            .values()
            .map(|p| match &p.data_type {
                PropertyType::Scalar(t) | PropertyType::List(t, _) => size(t),
            })
            .sum(),
    };
    bytes.max(1)
}

/// The parser's multi-line messages on one line, without its own "Line N:" prefix.
fn flatten(message: &str) -> String {
    let one_line = message
        .replace("\n'", "'")
        .replace("\n\t", "; ")
        .replace('\n', "; ");
    match one_line.split_once(": ") {
        Some((prefix, rest)) if prefix.starts_with("Line ") => rest.to_owned(),
        _ => one_line,
    }
}

/// Three scalar properties of every vertex as f32, or `None` when the header lacks them.
fn coordinates(
    vertices: &[DefaultElement],
    keys: [&str; 3],
    name: &str,
    what: &str,
) -> Result<Option<Vec<[f32; 3]>>, FormatError> {
    let Some(first) = vertices.first() else {
        return Ok(None);
    };
    if !keys.iter().all(|k| first.contains_key(*k)) {
        return Ok(None);
    }
    vertices
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let get = |k: &str| v.get(k).and_then(Property::to_f32_lossy);
            match keys.map(get) {
                [Some(x), Some(y), Some(z)] => Ok([x, y, z]),
                _ => Err(FormatError::malformed_at(
                    name,
                    FORMAT,
                    format!("vertex {i}"),
                    format!("{what} properties {keys:?} are not numeric scalars"),
                )),
            }
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Some)
}

/// Face lists to triangles: fans for polygons, with each index checked against the
/// vertex count.
fn triangulate(
    faces: &[DefaultElement],
    vertices: usize,
    name: &str,
) -> Result<Vec<[u32; 3]>, FormatError> {
    let mut triangles = Vec::with_capacity(faces.len());
    for (f, face) in faces.iter().enumerate() {
        let at = || format!("face {f}");
        let list = face
            .get("vertex_indices")
            .or_else(|| face.get("vertex_index"))
            .ok_or_else(|| {
                FormatError::malformed_at(
                    name,
                    FORMAT,
                    at(),
                    "no 'vertex_indices' or 'vertex_index' list",
                )
            })?;
        let indices = list.to_u32_list().ok_or_else(|| {
            FormatError::malformed_at(
                name,
                FORMAT,
                at(),
                "vertex index list holds negative or non-integer values",
            )
        })?;
        if indices.len() < 3 {
            return Err(FormatError::malformed_at(
                name,
                FORMAT,
                at(),
                format!(
                    "a face needs at least 3 vertices, this one has {}",
                    indices.len()
                ),
            ));
        }
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= vertices) {
            return Err(FormatError::malformed_at(
                name,
                FORMAT,
                at(),
                format!("face refers to vertex {bad} but only {vertices} exist"),
            ));
        }
        triangles.extend((1..indices.len() - 1).map(|k| [indices[0], indices[k], indices[k + 1]]));
    }
    Ok(triangles)
}

/// Binary little-endian PLY with float positions (and normals), uchar/uint face lists.
pub(super) fn write(mesh: &TriMesh, meta: &MeshMetadata) -> Vec<u8> {
    let mut header = String::from("ply\nformat binary_little_endian 1.0\n");
    for line in meta.comment_lines() {
        let _ = writeln!(header, "comment {line}");
    }
    let _ = writeln!(header, "element vertex {}", mesh.vertex_count());
    header.push_str("property float x\nproperty float y\nproperty float z\n");
    if mesh.normals.is_some() {
        header.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    let _ = writeln!(header, "element face {}", mesh.triangle_count());
    header.push_str("property list uchar uint vertex_indices\nend_header\n");

    let stride = if mesh.normals.is_some() { 24 } else { 12 };
    let mut out = header.into_bytes();
    out.reserve(stride * mesh.vertex_count() + 13 * mesh.triangle_count());
    for (i, p) in mesh.positions.iter().enumerate() {
        let normal = mesh.normals.as_ref().map(|n| n[i]);
        for c in p.iter().chain(normal.iter().flatten()) {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    for t in &mesh.triangles {
        out.push(3);
        for i in t {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    out
}
