//! glTF 2.0 reading (JSON or GLB) through the `gltf` crate: every triangle primitive of
//! every mesh, placed by its node's world transform when a node instances it.

use std::path::Path;

use gltf::mesh::Mode;

use super::{FormatError, LoadedMesh, MeshFormat, guard};
use crate::geometry::{TriMesh, cross, dot};

type Matrix = [[f64; 4]; 4];
const IDENTITY: Matrix = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

/// Reads glTF JSON or GLB (told apart by the magic bytes). External buffer files are only
/// followed when `dir` is given, and only to files inside it.
pub(super) fn read(
    bytes: &[u8],
    name: &str,
    dir: Option<&Path>,
) -> Result<LoadedMesh, FormatError> {
    let format = if bytes.starts_with(b"glTF") {
        MeshFormat::Glb
    } else {
        MeshFormat::Gltf
    };
    let malformed = |msg: String| FormatError::malformed(name, format, msg);
    let gltf = guard(|| gltf::Gltf::from_slice(bytes))
        .map_err(malformed)?
        .map_err(|e| malformed(e.to_string()))?;
    check_buffer_uris(&gltf.document, name, format, dir)?;
    let buffers = guard(|| gltf::import_buffers(&gltf.document, dir, gltf.blob.clone()))
        .map_err(malformed)?
        .map_err(|e| malformed(format!("cannot load buffers: {e}")))?;
    let mesh = guard(|| collect(&gltf.document, &buffers, name, format)).map_err(malformed)??;
    let extras = gltf
        .document
        .as_json()
        .asset
        .extras
        .as_ref()
        .and_then(|raw| serde_json::from_str::<serde_json::Value>(raw.get()).ok());
    let units = extras
        .as_ref()
        .and_then(|e| e.get("units"))
        .and_then(|u| u.as_str())
        .map(str::to_owned);
    Ok(LoadedMesh {
        mesh,
        format,
        units,
        extras,
    })
}

/// Rejects external buffers when there is no directory, and any that leave it.
fn check_buffer_uris(
    document: &gltf::Document,
    name: &str,
    format: MeshFormat,
    dir: Option<&Path>,
) -> Result<(), FormatError> {
    for buffer in document.buffers() {
        let gltf::buffer::Source::Uri(uri) = buffer.source() else {
            continue;
        };
        if uri.starts_with("data:") {
            continue;
        }
        let unsupported = |message: String| FormatError::Unsupported {
            name: name.to_owned(),
            format,
            message,
        };
        if dir.is_none() {
            return Err(unsupported(format!(
                "buffer {} is stored in the external file {uri:?}; read the glTF from a file \
                 path whose directory holds that file, or embed the buffer (GLB or data URI)",
                buffer.index()
            )));
        }
        if uri.contains(':')
            || uri.starts_with(['/', '\\'])
            || uri.split(['/', '\\']).any(|p| p == "..")
        {
            return Err(unsupported(format!(
                "buffer {} refers to {uri:?}, which is not a file inside the glTF's directory",
                buffer.index()
            )));
        }
    }
    Ok(())
}

/// All triangle primitives: instanced by nodes with their world transforms, and meshes
/// that no node uses as they are.
fn collect(
    document: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    name: &str,
    format: MeshFormat,
) -> Result<TriMesh, FormatError> {
    let mut out = TriMesh::default();
    let mut normals_complete = true;
    let mut instanced = vec![false; document.meshes().len()];
    let nodes: Vec<gltf::Node<'_>> = document.nodes().collect();
    let mut parents = vec![None; nodes.len()];
    for node in &nodes {
        for child in node.children() {
            parents[child.index()] = Some(node.index());
        }
    }
    for node in &nodes {
        if let Some(mesh) = node.mesh() {
            instanced[mesh.index()] = true;
            let world = world_matrix(&nodes, &parents, node.index());
            append_mesh(
                &mut out,
                &mut normals_complete,
                &mesh,
                &world,
                buffers,
                name,
                format,
            )?;
        }
    }
    for mesh in document.meshes().filter(|m| !instanced[m.index()]) {
        append_mesh(
            &mut out,
            &mut normals_complete,
            &mesh,
            &IDENTITY,
            buffers,
            name,
            format,
        )?;
    }
    if out.triangles.is_empty() {
        return Err(FormatError::malformed(
            name,
            format,
            "no triangle primitives with positions",
        ));
    }
    if !normals_complete {
        out.normals = None;
    }
    Ok(out)
}

fn append_mesh(
    out: &mut TriMesh,
    normals_complete: &mut bool,
    mesh: &gltf::Mesh<'_>,
    m: &Matrix,
    buffers: &[gltf::buffer::Data],
    name: &str,
    format: MeshFormat,
) -> Result<(), FormatError> {
    let det = determinant3(m);
    for primitive in mesh.primitives().filter(|p| p.mode() == Mode::Triangles) {
        let at = format!("mesh {} primitive {}", mesh.index(), primitive.index());
        let err = |msg: String| FormatError::malformed_at(name, format, at.clone(), msg);
        let reader = primitive.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let positions: Vec<[f32; 3]> = reader
            .read_positions()
            .ok_or_else(|| err("POSITION is missing or lies outside its buffer".into()))?
            .collect();
        let count = positions.len();
        let indices: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..count as u32).collect(),
        };
        if indices.len() % 3 != 0 {
            return Err(err(format!(
                "{} indices is not a multiple of 3",
                indices.len()
            )));
        }
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= count) {
            return Err(err(format!(
                "an index refers to vertex {bad} but only {count} exist"
            )));
        }
        let normals: Option<Vec<[f32; 3]>> = reader.read_normals().map(Iterator::collect);
        let base = out.positions.len() as u32;
        out.positions
            .extend(positions.iter().map(|p| transform_point(m, *p)));
        match normals {
            Some(n) if n.len() == count => {
                let normals = out.normals.get_or_insert_with(Vec::new);
                normals.resize(base as usize, [0.0; 3]);
                normals.extend(n.iter().map(|v| transform_normal(m, det, *v)));
            }
            _ => *normals_complete = false,
        }
        out.triangles.extend(indices.chunks_exact(3).map(|t| {
            // A mirroring transform turns outward triangles inward: swap to keep them outward.
            if det < 0.0 {
                [t[0], t[2], t[1]]
            } else {
                [t[0], t[1], t[2]]
            }
            .map(|i| base + i)
        }));
    }
    Ok(())
}

/// The node's local matrix premultiplied by its ancestors' (cycle-safe).
fn world_matrix(nodes: &[gltf::Node<'_>], parents: &[Option<usize>], node: usize) -> Matrix {
    let mut world = local_matrix(&nodes[node]);
    let mut current = node;
    for _ in 0..nodes.len() {
        let Some(parent) = parents[current] else {
            break;
        };
        world = multiply(&local_matrix(&nodes[parent]), &world);
        current = parent;
    }
    world
}

/// Column-major local matrix as row-major f64.
fn local_matrix(node: &gltf::Node<'_>) -> Matrix {
    let cols = node.transform().matrix();
    std::array::from_fn(|r| std::array::from_fn(|c| f64::from(cols[c][r])))
}

fn multiply(a: &Matrix, b: &Matrix) -> Matrix {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..4).map(|k| a[r][k] * b[k][c]).sum()))
}

fn transform_point(m: &Matrix, p: [f32; 3]) -> [f32; 3] {
    if *m == IDENTITY {
        return p; // bit-exact for the common case
    }
    let p = p.map(f64::from);
    std::array::from_fn(|r| (m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3]) as f32)
}

/// Normals transform by the inverse transpose of the linear part (the cofactor matrix,
/// scaled by the determinant's sign), then are renormalised.
fn transform_normal(m: &Matrix, det: f64, n: [f32; 3]) -> [f32; 3] {
    if *m == IDENTITY {
        return n;
    }
    let row = |r: usize| [m[r][0], m[r][1], m[r][2]];
    let cofactor = [
        cross(row(1), row(2)),
        cross(row(2), row(0)),
        cross(row(0), row(1)),
    ];
    let n = n.map(f64::from);
    let v: [f64; 3] = std::array::from_fn(|i| dot(cofactor[i], n) * det.signum());
    let len = dot(v, v).sqrt();
    if len > 0.0 {
        v.map(|c| (c / len) as f32)
    } else {
        [0.0; 3]
    }
}

fn determinant3(m: &Matrix) -> f64 {
    dot(
        [m[0][0], m[0][1], m[0][2]],
        cross([m[1][0], m[1][1], m[1][2]], [m[2][0], m[2][1], m[2][2]]),
    )
}
