//! Binary glTF of a face-labelled surface: one mesh with one triangle primitive per face,
//! each with its own vertices (so a flat cap is shaded flat beside the curved wall), POSITION
//! with min/max, NORMAL, u32 indices and `extras` naming the face (`face_id`, `name`).
//! Metadata goes in `asset.extras` as in every GLB the project writes.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};

use gltf_json as json;
use json::validation::Checked::Valid;
use json::validation::USize64;

use super::MeshMetadata;
use super::gltf_write::{accessor, bounds};
use super::labelled::{FacePatch, LabelledWriteError, check_labels, triangles_by_patch};
use crate::geometry::TriMesh;

fn failed(e: impl std::fmt::Display) -> LabelledWriteError {
    LabelledWriteError {
        format: "GLB",
        message: e.to_string(),
    }
}

/// One face's own vertices, normals and triangles.
struct Part {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    indices: Vec<u32>,
}

fn part(mesh: &TriMesh, tris: &[usize]) -> Part {
    let mut map: HashMap<u32, u32> = HashMap::new();
    let mut sub = TriMesh::default();
    for &t in tris {
        let tri = mesh.triangles[t].map(|v| {
            *map.entry(v).or_insert_with(|| {
                sub.positions.push(mesh.positions[v as usize]);
                (sub.positions.len() - 1) as u32
            })
        });
        sub.triangles.push(tri);
    }
    Part {
        normals: sub.compute_vertex_normals(),
        indices: sub.triangles.iter().flatten().copied().collect(),
        positions: sub.positions,
    }
}

/// GLB with one primitive per face.
pub fn write_faces_glb(
    mesh: &TriMesh,
    face_ids: &[u32],
    patches: &[FacePatch],
    meta: &MeshMetadata,
) -> Result<Vec<u8>, LabelledWriteError> {
    check_labels(mesh, face_ids, patches, "GLB")?;
    let parts: Vec<(&FacePatch, Part)> = triangles_by_patch(face_ids, patches)
        .filter(|(_, t)| !t.is_empty())
        .map(|(p, t)| (p, part(mesh, &t)))
        .collect();
    let mut bin: Vec<u8> = Vec::new();
    let extras =
        |v: serde_json::Value| json::extras::RawValue::from_string(v.to_string()).map_err(failed);
    let mut root = json::Root {
        asset: json::Asset {
            generator: Some(meta.generator.clone()),
            extras: Some(extras(meta.to_json())?),
            ..Default::default()
        },
        ..Default::default()
    };
    let buffer = root.push(json::Buffer {
        byte_length: USize64(0),
        extensions: None,
        extras: None,
        name: None,
        uri: None,
    });
    let mut primitives = Vec::new();
    for (patch, p) in &parts {
        let mut view = |root: &mut json::Root, bytes: Vec<u8>, target| {
            let offset = bin.len();
            bin.extend(bytes);
            root.push(json::buffer::View {
                buffer,
                byte_length: USize64::from(bin.len() - offset),
                byte_offset: Some(USize64::from(offset)),
                byte_stride: None,
                extensions: None,
                extras: None,
                name: None,
                target: Some(Valid(target)),
            })
        };
        let floats = |v: &[[f32; 3]]| v.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        let array = json::buffer::Target::ArrayBuffer;
        let pv = view(&mut root, floats(&p.positions), array);
        let nv = view(&mut root, floats(&p.normals), array);
        let index_bytes = p.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        let iv = view(
            &mut root,
            index_bytes,
            json::buffer::Target::ElementArrayBuffer,
        );
        let (vec3, f32c) = (
            json::accessor::Type::Vec3,
            json::accessor::ComponentType::F32,
        );
        let count = p.positions.len();
        let positions = root.push(accessor(pv, count, vec3, f32c, Some(bounds(&p.positions))));
        let normals = root.push(accessor(nv, count, vec3, f32c, None));
        let indices = root.push(accessor(
            iv,
            p.indices.len(),
            json::accessor::Type::Scalar,
            json::accessor::ComponentType::U32,
            None,
        ));
        let mut attributes = BTreeMap::new();
        attributes.insert(Valid(json::mesh::Semantic::Positions), positions);
        attributes.insert(Valid(json::mesh::Semantic::Normals), normals);
        primitives.push(json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Some(extras(
                serde_json::json!({"face_id": patch.id, "name": patch.name}),
            )?),
            indices: Some(indices),
            material: None,
            mode: Valid(json::mesh::Mode::Triangles),
            targets: None,
        });
    }
    root.buffers[0].byte_length = USize64::from(bin.len());
    let gltf_mesh = root.push(json::Mesh {
        extensions: None,
        extras: Some(extras(serde_json::json!({"units": meta.units}))?),
        name: Some("aorta".to_owned()),
        primitives,
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
    let json = json::serialize::to_vec(&root).map_err(failed)?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: 0,
        },
        json: Cow::Owned(json),
        bin: Some(Cow::Owned(bin)),
    };
    let mut out = Vec::new();
    glb.to_writer(&mut out).map_err(failed)?;
    Ok(out)
}
