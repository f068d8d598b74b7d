//! glTF 2.0 reading (JSON or GLB) through the `gltf` crate: every triangle primitive of
//! every mesh, placed by its node's world transform when a node instances it.

use std::collections::HashMap;
use std::path::Path;

use gltf::mesh::Mode;

use super::transform::{
    IDENTITY, Matrix, determinant3, transform_normal, transform_point, world_matrix,
};
use super::{FormatError, LoadedMesh, MeshFormat, guard};
use crate::geometry::TriMesh;

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
    if format == MeshFormat::Glb {
        check_glb_header(bytes)
            .map_err(|msg| FormatError::malformed_at(name, format, "GLB header", msg))?;
    }
    check_accessor_references(bytes, format).map_err(&malformed)?;
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

/// Every primitive attribute and index reference must name an existing accessor. The `gltf`
/// crate's own validation indexes the accessor list without checking, so a dangling reference
/// would panic inside it instead of being reported.
fn check_accessor_references(bytes: &[u8], format: MeshFormat) -> Result<(), String> {
    let json: &[u8] = if format == MeshFormat::Glb {
        match gltf::binary::Glb::from_slice(bytes) {
            Ok(glb) => return check_accessor_json(&glb.json),
            Err(e) => return Err(e.to_string()),
        }
    } else {
        bytes
    };
    check_accessor_json(json)
}

fn check_accessor_json(json: &[u8]) -> Result<(), String> {
    // The glTF parser skips unknown fields without checking their UTF-8, so a document it
    // accepts may hold invalid bytes: read those as U+FFFD here rather than skip the check.
    let parsed = serde_json::from_slice::<serde_json::Value>(json)
        .or_else(|_| serde_json::from_str(&String::from_utf8_lossy(json)));
    let Ok(root) = parsed else {
        return Ok(()); // the glTF parser reports malformed JSON with its position
    };
    let accessors = root["accessors"].as_array().map_or(0, Vec::len) as u64;
    let meshes = root["meshes"]
        .as_array()
        .map(Vec::as_slice)
        .unwrap_or_default();
    for (m, mesh) in meshes.iter().enumerate() {
        let primitives = mesh["primitives"]
            .as_array()
            .map(Vec::as_slice)
            .unwrap_or_default();
        for (p, primitive) in primitives.iter().enumerate() {
            let attributes = primitive["attributes"].as_object().into_iter().flatten();
            let indices = primitive.get("indices").map(|v| ("indices", v));
            for (what, value) in attributes.map(|(k, v)| (k.as_str(), v)).chain(indices) {
                if let Some(i) = value.as_u64().filter(|&i| i >= accessors) {
                    return Err(format!(
                        "mesh {m} primitive {p}: {what} refers to accessor {i}, but there are only {accessors}"
                    ));
                }
            }
        }
    }
    Ok(())
}

/// Size and version checks the `gltf` crate leaves to arithmetic that can overflow.
fn check_glb_header(bytes: &[u8]) -> Result<(), String> {
    let word = |at: usize| {
        bytes
            .get(at..at + 4)
            .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
    };
    let (Some(version), Some(declared)) = (word(4), word(8)) else {
        return Err(format!(
            "truncated GLB: {} bytes, the header alone needs 12",
            bytes.len()
        ));
    };
    if version != 2 {
        return Err(format!(
            "GLB version {version}; only version 2 is supported"
        ));
    }
    let declared = declared as usize;
    if declared > bytes.len() {
        return Err(format!(
            "truncated GLB: header declares {declared} bytes, file holds {}",
            bytes.len()
        ));
    }
    if declared < 20 {
        return Err(format!(
            "header declares {declared} bytes, less than a header and one chunk header (20)"
        ));
    }
    Ok(())
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
    let mut c = Collector {
        out: TriMesh::default(),
        normals_complete: true,
        shared: HashMap::new(),
        buffers,
        name,
        format,
    };
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
            c.append_mesh(&mesh, &world, Some(node.index()))?;
        }
    }
    for mesh in document.meshes().filter(|m| !instanced[m.index()]) {
        c.append_mesh(&mesh, &IDENTITY, None)?;
    }
    if c.out.triangles.is_empty() {
        return Err(FormatError::malformed(
            name,
            format,
            "no triangle primitives with positions",
        ));
    }
    if !c.normals_complete {
        c.out.normals = None;
    }
    Ok(c.out)
}

/// Accumulates primitives into one mesh.
struct Collector<'a> {
    out: TriMesh,
    normals_complete: bool,
    /// First vertex of the copy of each (POSITION, NORMAL, node) combination already
    /// added, so primitives that share vertex accessors also share vertices (and edges).
    shared: HashMap<(usize, Option<usize>, Option<usize>), u32>,
    buffers: &'a [gltf::buffer::Data],
    name: &'a str,
    format: MeshFormat,
}

/// A vertex attribute the reader takes as `[f32; 3]`: VEC3 of FLOAT, not normalised.
fn check_vec3_float(accessor: &gltf::Accessor<'_>) -> Result<(), String> {
    use gltf::accessor::{DataType, Dimensions};
    let (kind, dims) = (accessor.data_type(), accessor.dimensions());
    if kind == DataType::F32 && dims == Dimensions::Vec3 && !accessor.normalized() {
        return Ok(());
    }
    Err(format!(
        "the accessor must be VEC3 of FLOAT, it is {dims:?} of {kind:?}{}",
        if accessor.normalized() {
            " (normalized)"
        } else {
            ""
        }
    ))
}

/// gltf's readers compute an accessor's last byte as `offset + stride·(count − 1) + size`
/// without checking it: an empty accessor underflows and a huge count overflows. Check the
/// same arithmetic here, for the accessor and its sparse parts, so such a file is an error.
fn check_layout(accessor: &gltf::Accessor<'_>) -> Result<(), String> {
    let size = accessor.size();
    if accessor.count() == 0 {
        return Err("the accessor has count 0".into());
    }
    if let Some(view) = accessor.view() {
        check_span(&view, accessor.offset(), accessor.count(), size)?;
    }
    if let Some(sparse) = accessor.sparse() {
        let count = sparse.count();
        if count == 0 {
            return Err("the sparse accessor has count 0".into());
        }
        let indices = sparse.indices();
        check_span(
            &indices.view(),
            indices.offset(),
            count,
            indices.index_type().size(),
        )
        .map_err(|e| format!("sparse indices: {e}"))?;
        let values = sparse.values();
        check_span(&values.view(), values.offset(), count, size)
            .map_err(|e| format!("sparse values: {e}"))?;
    }
    Ok(())
}

/// `count` elements of `size` bytes from `offset` fit in `view` at its stride.
fn check_span(
    view: &gltf::buffer::View<'_>,
    offset: usize,
    count: usize,
    size: usize,
) -> Result<(), String> {
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!(
            "the buffer view's stride {stride} is smaller than the element size {size}"
        ));
    }
    let end = count
        .checked_sub(1)
        .and_then(|last| stride.checked_mul(last))
        .and_then(|span| span.checked_add(offset))
        .and_then(|span| span.checked_add(size));
    match end {
        Some(end) if end <= view.length() => Ok(()),
        _ => Err(format!(
            "{count} elements of {size} bytes from offset {offset} do not fit in the buffer \
             view's {} bytes",
            view.length()
        )),
    }
}

impl Collector<'_> {
    fn append_mesh(
        &mut self,
        mesh: &gltf::Mesh<'_>,
        m: &Matrix,
        node: Option<usize>,
    ) -> Result<(), FormatError> {
        let det = determinant3(m);
        for primitive in mesh.primitives().filter(|p| p.mode() == Mode::Triangles) {
            let at = format!("mesh {} primitive {}", mesh.index(), primitive.index());
            let err =
                |msg: &str| FormatError::malformed_at(self.name, self.format, at.clone(), msg);
            let buffers = self.buffers;
            // gltf's attribute readers assert the accessor's element size; check the types
            // first so that a mistyped accessor is an error that names it.
            for semantic in [gltf::Semantic::Positions, gltf::Semantic::Normals] {
                if let Some(accessor) = primitive.get(&semantic) {
                    check_vec3_float(&accessor)
                        .and_then(|()| check_layout(&accessor))
                        .map_err(|e| err(&format!("{semantic:?}: {e}")))?;
                }
            }
            let reader = primitive.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
            let positions: Vec<[f32; 3]> = reader
                .read_positions()
                .ok_or_else(|| err("POSITION is missing or lies outside its buffer"))?
                .collect();
            let count = positions.len();
            // gltf's index reader treats any other component type as unreachable.
            if let Some(accessor) = primitive.indices() {
                use gltf::accessor::DataType;
                let kind = accessor.data_type();
                if !matches!(kind, DataType::U8 | DataType::U16 | DataType::U32) {
                    return Err(err(&format!(
                        "indices must be unsigned integers (UNSIGNED_BYTE, UNSIGNED_SHORT or \
                         UNSIGNED_INT), the accessor has {kind:?}"
                    )));
                }
                check_layout(&accessor).map_err(|e| err(&format!("indices: {e}")))?;
            }
            let indices: Vec<u32> = match (primitive.indices(), reader.read_indices()) {
                (_, Some(i)) => i.into_u32().collect(),
                (None, None) => (0..count as u32).collect(),
                (Some(_), None) => return Err(err("the indices accessor lies outside its buffer")),
            };
            if !indices.len().is_multiple_of(3) {
                return Err(err(&format!(
                    "{} indices is not a multiple of 3",
                    indices.len()
                )));
            }
            if let Some(&bad) = indices.iter().find(|&&i| i as usize >= count) {
                return Err(err(&format!(
                    "an index refers to vertex {bad} but only {count} exist"
                )));
            }
            let normals: Option<Vec<[f32; 3]>> = reader.read_normals().map(Iterator::collect);
            let key = (
                primitive
                    .get(&gltf::Semantic::Positions)
                    .map_or(usize::MAX, |a| a.index()),
                primitive.get(&gltf::Semantic::Normals).map(|a| a.index()),
                node,
            );
            let base = match self.shared.get(&key) {
                Some(&base) => base,
                None => {
                    let base = self.out.positions.len() as u32;
                    self.add_vertices(&positions, normals.as_deref(), m, det);
                    self.shared.insert(key, base);
                    base
                }
            };
            self.out.triangles.extend(indices.chunks_exact(3).map(|t| {
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

    fn add_vertices(
        &mut self,
        positions: &[[f32; 3]],
        normals: Option<&[[f32; 3]]>,
        m: &Matrix,
        det: f64,
    ) {
        let base = self.out.positions.len();
        self.out
            .positions
            .extend(positions.iter().map(|p| transform_point(m, *p)));
        match normals {
            Some(n) if n.len() == positions.len() => {
                let normals = self.out.normals.get_or_insert_with(Vec::new);
                normals.resize(base, [0.0; 3]);
                normals.extend(n.iter().map(|v| transform_normal(m, det, *v)));
            }
            _ => self.normals_complete = false,
        }
    }
}
