//! glTF 2.0 writing: one mesh, one primitive (POSITION with min/max, NORMAL when present,
//! u32 indices), metadata in `asset.extras` and `mesh.extras`. GLB carries the buffer in
//! its BIN chunk; `.gltf` embeds it as a base64 data URI.

use std::borrow::Cow;
use std::collections::BTreeMap;

use gltf_json as json;
use json::validation::Checked::Valid;
use json::validation::USize64;

use super::{FormatError, MeshFormat, MeshMetadata};
use crate::geometry::TriMesh;

/// Binary glTF.
pub(super) fn write_glb(mesh: &TriMesh, meta: &MeshMetadata) -> Result<Vec<u8>, FormatError> {
    let bin = buffer_bytes(mesh);
    let root = document(mesh, meta, bin.len(), None, MeshFormat::Glb)?;
    let json = json::serialize::to_vec(&root).map_err(|e| write_error(MeshFormat::Glb, e))?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: 0, // to_writer computes the real length
        },
        json: Cow::Owned(json),
        bin: Some(Cow::Owned(bin)),
    };
    let mut out = Vec::new();
    glb.to_writer(&mut out)
        .map_err(|e| write_error(MeshFormat::Glb, e))?;
    Ok(out)
}

/// glTF JSON with the buffer embedded as a base64 data URI.
pub(super) fn write_gltf(mesh: &TriMesh, meta: &MeshMetadata) -> Result<Vec<u8>, FormatError> {
    let bin = buffer_bytes(mesh);
    let uri = format!("data:application/octet-stream;base64,{}", base64(&bin));
    let root = document(mesh, meta, bin.len(), Some(uri), MeshFormat::Gltf)?;
    json::serialize::to_vec_pretty(&root).map_err(|e| write_error(MeshFormat::Gltf, e))
}

fn write_error(format: MeshFormat, e: impl std::fmt::Display) -> FormatError {
    FormatError::Write {
        format,
        message: e.to_string(),
    }
}

/// Positions, then normals (if any), then indices: all 4-byte quantities, so every view
/// starts 4-byte aligned.
fn buffer_bytes(mesh: &TriMesh) -> Vec<u8> {
    let floats = mesh
        .positions
        .iter()
        .chain(mesh.normals.iter().flatten())
        .flatten();
    let indices = mesh.triangles.iter().flatten();
    floats
        .flat_map(|f| f.to_le_bytes())
        .chain(indices.flat_map(|i| i.to_le_bytes()))
        .collect()
}

fn document(
    mesh: &TriMesh,
    meta: &MeshMetadata,
    length: usize,
    uri: Option<String>,
    format: MeshFormat,
) -> Result<json::Root, FormatError> {
    let extras = |value: &serde_json::Value| {
        json::extras::RawValue::from_string(value.to_string()).map_err(|e| write_error(format, e))
    };
    let mut root = json::Root {
        asset: json::Asset {
            generator: Some(meta.generator.clone()),
            extras: Some(extras(&meta.to_json())?),
            ..Default::default()
        },
        ..Default::default()
    };
    let buffer = root.push(json::Buffer {
        byte_length: USize64::from(length),
        extensions: None,
        extras: None,
        name: None,
        uri,
    });
    let vertex_bytes = 12 * mesh.vertex_count();
    let mut offset = 0;
    let mut view = |root: &mut json::Root, len: usize, target: json::buffer::Target| {
        let v = root.push(json::buffer::View {
            buffer,
            byte_length: USize64::from(len),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            extensions: None,
            extras: None,
            name: None,
            target: Some(Valid(target)),
        });
        offset += len;
        v
    };
    let positions_view = view(&mut root, vertex_bytes, json::buffer::Target::ArrayBuffer);
    let normals_view = mesh
        .normals
        .as_ref()
        .map(|_| view(&mut root, vertex_bytes, json::buffer::Target::ArrayBuffer));
    let indices_view = view(
        &mut root,
        12 * mesh.triangle_count(),
        json::buffer::Target::ElementArrayBuffer,
    );

    let (min, max) = bounds(&mesh.positions);
    let positions = root.push(accessor(
        positions_view,
        mesh.vertex_count(),
        json::accessor::Type::Vec3,
        json::accessor::ComponentType::F32,
        Some((min, max)),
    ));
    let normals = normals_view.map(|v| {
        root.push(accessor(
            v,
            mesh.vertex_count(),
            json::accessor::Type::Vec3,
            json::accessor::ComponentType::F32,
            None,
        ))
    });
    let indices = root.push(accessor(
        indices_view,
        3 * mesh.triangle_count(),
        json::accessor::Type::Scalar,
        json::accessor::ComponentType::U32,
        None,
    ));

    let mut attributes = BTreeMap::new();
    attributes.insert(Valid(json::mesh::Semantic::Positions), positions);
    if let Some(n) = normals {
        attributes.insert(Valid(json::mesh::Semantic::Normals), n);
    }
    let mesh_extras = serde_json::json!({
        "units": meta.units,
        "sign_convention": super::SIGN_CONVENTION_NOTE,
    });
    let gltf_mesh = root.push(json::Mesh {
        extensions: None,
        extras: Some(extras(&mesh_extras)?),
        name: Some("aorta".to_owned()),
        primitives: vec![json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: None,
            indices: Some(indices),
            material: None,
            mode: Valid(json::mesh::Mode::Triangles),
            targets: None,
        }],
        weights: None,
    });
    let node = root.push(json::Node {
        mesh: Some(gltf_mesh),
        ..Default::default()
    });
    let scene = root.push(json::Scene {
        extensions: None,
        extras: None,
        name: None,
        nodes: vec![node],
    });
    root.scene = Some(scene);
    Ok(root)
}

pub(super) fn accessor(
    view: json::Index<json::buffer::View>,
    count: usize,
    type_: json::accessor::Type,
    component: json::accessor::ComponentType,
    bounds: Option<([f32; 3], [f32; 3])>,
) -> json::Accessor {
    let as_json = |v: [f32; 3]| json::Value::from(Vec::from(v));
    json::Accessor {
        buffer_view: Some(view),
        byte_offset: None,
        count: USize64::from(count),
        component_type: Valid(json::accessor::GenericComponentType(component)),
        extensions: None,
        extras: None,
        type_: Valid(type_),
        min: bounds.map(|b| as_json(b.0)),
        max: bounds.map(|b| as_json(b.1)),
        name: None,
        normalized: false,
        sparse: None,
    }
}

/// Component-wise min and max of the positions (exact f32 values, as the spec requires).
pub(super) fn bounds(points: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut min = [f32::INFINITY; 3];
    let mut max = [f32::NEG_INFINITY; 3];
    for p in points {
        for i in 0..3 {
            min[i] = min[i].min(p[i]);
            max[i] = max[i].max(p[i]);
        }
    }
    (min, max)
}

/// Standard base64 with padding (RFC 4648 §4).
pub(super) fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::base64;

    #[test]
    fn base64_matches_the_rfc_4648_test_vectors() {
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, encoded) in cases {
            assert_eq!(base64(plain.as_bytes()), encoded, "{plain:?}");
        }
        assert_eq!(base64(&[0xff, 0xfe, 0xfd]), "//79");
    }
}
