//! Wavefront OBJ through `tobj`: polygons are triangulated as fans, materials ignored,
//! vertex normals kept when every corner of a vertex names the same one.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::{BufRead, Read};

use super::{FormatError, LoadedMesh, MeshFormat, MeshMetadata, guard, units_in};
use crate::geometry::TriMesh;

/// Reads an OBJ file; errors name the line when the parser can tell.
pub(super) fn read(bytes: &[u8], name: &str) -> Result<LoadedMesh, FormatError> {
    let options = tobj::LoadOptions {
        single_index: false,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    // Indices are checked here first: tobj multiplies texture and normal indices without
    // overflow checks, so a huge index would panic inside it instead of being reported.
    if let Some((line, msg)) = find_bad_index(bytes) {
        let at = format!("line {line}");
        return Err(FormatError::malformed_at(name, MeshFormat::Obj, at, msg));
    }
    let mut source = LineCounter {
        data: bytes,
        pos: 0,
    };
    let loaded = guard(|| {
        let result = tobj::load_obj_buf(&mut source, &options, |_| {
            Err(tobj::LoadError::MaterialParseError) // materials are ignored
        });
        (result, source.line())
    })
    .map_err(|msg| FormatError::malformed(name, MeshFormat::Obj, msg))?;
    let models = match loaded {
        (Ok((models, _materials)), _) => models,
        (Err(e), line) => return Err(describe(bytes, name, e, line)),
    };
    let units = comments(bytes).find_map(|c| units_in(&c));
    Ok(LoadedMesh {
        mesh: merge(&models, name)?,
        format: MeshFormat::Obj,
        units,
        extras: None,
    })
}

/// Concatenates tobj's per-object meshes. tobj re-indexes vertices per object, so when a
/// file has several objects, exactly equal positions are welded to restore shared edges.
fn merge(models: &[tobj::Model], name: &str) -> Result<TriMesh, FormatError> {
    let mut mesh = TriMesh::default();
    let mut normals: Vec<Option<[f32; 3]>> = Vec::new();
    let mut weld: HashMap<[u32; 3], u32> = HashMap::new();
    let welding = models.len() > 1;
    for model in models {
        let m = &model.mesh;
        if !m.positions.len().is_multiple_of(3) || !m.indices.len().is_multiple_of(3) {
            return Err(FormatError::malformed(
                name,
                MeshFormat::Obj,
                "incomplete vertex or face data",
            ));
        }
        let remap: Vec<u32> = m
            .positions
            .chunks_exact(3)
            .map(|p| {
                let p = [p[0], p[1], p[2]];
                let mut add = || {
                    mesh.positions.push(p);
                    normals.push(None);
                    (mesh.positions.len() - 1) as u32
                };
                if welding {
                    *weld
                        .entry(p.map(|c| (c + 0.0).to_bits()))
                        .or_insert_with(add)
                } else {
                    add()
                }
            })
            .collect();
        for (k, &i) in m.indices.iter().enumerate() {
            let normal = m.normal_indices.get(k).and_then(|&n| {
                let n = n as usize * 3;
                m.normals.get(n..n + 3).map(|v| [v[0], v[1], v[2]])
            });
            if let (Some(n), Some(&v)) = (normal, remap.get(i as usize)) {
                normals[v as usize].get_or_insert(n);
            }
        }
        mesh.triangles.extend(m.indices.chunks_exact(3).map(|t| {
            [t[0], t[1], t[2]].map(|i| remap.get(i as usize).copied().unwrap_or(u32::MAX))
        }));
    }
    if normals.iter().all(Option::is_some) && !normals.is_empty() {
        mesh.normals = Some(normals.into_iter().flatten().collect());
    }
    Ok(mesh)
}

/// Turns a tobj error into a message with a line number. Index errors are detected late
/// by tobj (at the end of an object), so their line is found by re-scanning the faces.
fn describe(bytes: &[u8], name: &str, e: tobj::LoadError, line: usize) -> FormatError {
    use tobj::LoadError as L;
    match e {
        L::FaceVertexOutOfBounds | L::FaceNormalOutOfBounds | L::FaceTexCoordOutOfBounds => {
            match find_bad_index(bytes) {
                Some((line, msg)) => {
                    FormatError::malformed_at(name, MeshFormat::Obj, format!("line {line}"), msg)
                }
                None => FormatError::malformed(name, MeshFormat::Obj, e.to_string()),
            }
        }
        _ => {
            FormatError::malformed_at(name, MeshFormat::Obj, format!("line {line}"), e.to_string())
        }
    }
}

/// The first face corner that refers to a missing vertex, texture coordinate or normal.
/// Like tobj, texture and normal indices are not checked when the file has none of them.
fn find_bad_index(bytes: &[u8]) -> Option<(usize, String)> {
    let text = String::from_utf8_lossy(bytes);
    let totals = ["v", "vt", "vn"].map(|kw| {
        text.lines()
            .filter(|l| l.split_whitespace().next() == Some(kw))
            .count()
    });
    let mut seen = [0usize; 3];
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => seen[0] += 1,
            Some("vt") => seen[1] += 1,
            Some("vn") => seen[2] += 1,
            Some("f") => {
                for corner in words {
                    for (slot, field) in corner.split('/').enumerate().take(3) {
                        let Ok(raw) = field.parse::<i64>() else {
                            continue;
                        };
                        if slot > 0 && totals[slot] == 0 {
                            continue;
                        }
                        let what = ["vertex", "texture coordinate", "normal"][slot];
                        let resolved = if raw < 0 {
                            seen[slot] as i64 + raw + 1
                        } else {
                            raw
                        };
                        if raw == 0 || resolved < 1 || resolved > totals[slot] as i64 {
                            return Some((
                                n + 1,
                                format!(
                                    "face refers to {what} {raw} but only {} exist (OBJ counts from 1)",
                                    totals[slot]
                                ),
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    None
}

fn comments(bytes: &[u8]) -> impl Iterator<Item = String> + '_ {
    bytes
        .split(|&b| b == b'\n')
        .filter(|l| l.trim_ascii_start().starts_with(b"#"))
        .map(|l| String::from_utf8_lossy(l).into_owned())
}

/// A `BufRead` over a byte slice that knows which line it has reached.
struct LineCounter<'a> {
    data: &'a [u8],
    pos: usize,
}

impl LineCounter<'_> {
    /// 1-based number of the line most recently (or currently being) read.
    fn line(&self) -> usize {
        let consumed = &self.data[..self.pos];
        let newlines = consumed.iter().filter(|&&b| b == b'\n').count();
        if consumed.last() == Some(&b'\n') {
            newlines
        } else {
            newlines + 1
        }
    }
}

impl Read for LineCounter<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = buf.len().min(self.data.len() - self.pos);
        buf[..n].copy_from_slice(&self.data[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
}

impl BufRead for LineCounter<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        Ok(&self.data[self.pos..])
    }
    fn consume(&mut self, amt: usize) {
        self.pos = (self.pos + amt).min(self.data.len());
    }
}

/// OBJ text: units and notes as `#` comments, `vn` lines and `f a//a` corners when the
/// mesh has normals.
pub(super) fn write(mesh: &TriMesh, meta: &MeshMetadata) -> Vec<u8> {
    let mut s = String::with_capacity(40 * (mesh.vertex_count() + mesh.triangle_count()));
    for line in meta.comment_lines() {
        let _ = writeln!(s, "# {line}");
    }
    s.push_str("o mesh\n");
    for p in &mesh.positions {
        let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
    }
    if let Some(normals) = &mesh.normals {
        for n in normals {
            let _ = writeln!(s, "vn {} {} {}", n[0], n[1], n[2]);
        }
    }
    let with_normals = mesh.normals.is_some();
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| i + 1);
        let _ = if with_normals {
            writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}")
        } else {
            writeln!(s, "f {a} {b} {c}")
        };
    }
    s.into_bytes()
}
