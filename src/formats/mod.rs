//! Mesh file formats: reading STL, OBJ, PLY and glTF/GLB into a [`TriMesh`] and writing
//! GLB, glTF, STL, OBJ and PLY.
//!
//! Every read ends with [`TriMesh::validate`], so a mesh that comes out of this module is
//! safe to measure and sample. Every failure is a [`FormatError`] naming the file, the
//! format and, where the parser knows it, the place in the file. No input makes a reader
//! panic. Units, the coordinate frame and the sign convention travel with every written
//! mesh: in glTF `extras`, and as comments in the formats that allow them.

mod error;
mod gltf;
mod gltf_write;
mod obj;
mod ply;
mod stl;

use std::fmt;
use std::path::Path;
use std::str::FromStr;

pub use error::FormatError;

use crate::geometry::TriMesh;

/// The mesh file formats aortagen reads and writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MeshFormat {
    /// STL, binary or ASCII (written binary). Unindexed: vertices are welded on read.
    Stl,
    /// Wavefront OBJ (polygons are triangulated, materials ignored).
    Obj,
    /// Stanford PLY, ASCII or binary of either endianness (written binary little-endian).
    Ply,
    /// Binary glTF 2.0.
    Glb,
    /// glTF 2.0 JSON; written with the buffer embedded as a base64 data URI.
    Gltf,
}

impl MeshFormat {
    /// Every format, in the order the command line lists them.
    pub const ALL: [MeshFormat; 5] = [Self::Glb, Self::Gltf, Self::Stl, Self::Obj, Self::Ply];

    /// The usual file extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            Self::Stl => "stl",
            Self::Obj => "obj",
            Self::Ply => "ply",
            Self::Glb => "glb",
            Self::Gltf => "gltf",
        }
    }

    /// Format from a file's extension (case-insensitive).
    pub fn from_path(path: &Path) -> Result<Self, FormatError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().into_owned())
            .unwrap_or_default();
        ext.parse().map_err(|_| FormatError::UnknownFormat {
            name: display_name(path),
            given: ext,
        })
    }

    /// Recognises the formats that announce themselves in their first bytes: GLB
    /// (`glTF` magic), glTF JSON (`{`) and PLY (`ply`). STL and OBJ have no reliable
    /// signature and are only chosen by extension.
    pub fn sniff(bytes: &[u8]) -> Option<Self> {
        let start = bytes.trim_ascii_start();
        if bytes.starts_with(b"glTF") {
            Some(Self::Glb)
        } else if start.starts_with(b"{") {
            Some(Self::Gltf)
        } else if bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r") {
            Some(Self::Ply)
        } else {
            None
        }
    }
}

impl FromStr for MeshFormat {
    type Err = FormatError;

    /// Accepts "glb", "gltf", "stl", "obj", "ply" in any case, with or without a leading dot.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.trim().trim_start_matches('.').to_ascii_lowercase();
        Self::ALL
            .into_iter()
            .find(|f| f.extension() == lower)
            .ok_or_else(|| FormatError::UnknownFormat {
                name: "format".to_owned(),
                given: s.to_owned(),
            })
    }
}

impl fmt::Display for MeshFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Stl => "STL",
            Self::Obj => "OBJ",
            Self::Ply => "PLY",
            Self::Glb => "GLB",
            Self::Gltf => "glTF",
        })
    }
}

/// The coordinate frame recorded with every written mesh.
pub const COORDINATE_FRAME_NOTE: &str = "right-handed x, y, z: the source data's own frame \
    (millimetres as scanned), or the model's unit-ball frame when the unit is 'unit'";

/// The sign convention recorded with every written mesh.
pub const SIGN_CONVENTION_NOTE: &str = "signed distance f < 0 inside, f > 0 outside; \
    triangles counter-clockwise seen from outside (outward normals)";

/// What a written mesh says about itself: units, the software that made it and any
/// provenance (model id, weights, seed, ...) as free JSON.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeshMetadata {
    /// Length unit of the coordinates: "mm" for shapes in their own units, "unit" for
    /// unit-ball coordinates.
    pub units: String,
    /// Software and version, e.g. "aortagen 0.1.0".
    pub generator: String,
    /// Provenance or any other JSON; `null` when there is nothing to record.
    pub extras: serde_json::Value,
}

impl MeshMetadata {
    /// Metadata with the given units, this software as generator and no extras.
    pub fn new(units: impl Into<String>) -> Self {
        Self {
            units: units.into(),
            generator: format!("aortagen {}", crate::VERSION),
            extras: serde_json::Value::Null,
        }
    }

    /// The JSON object stored in glTF `extras` and, compactly, in text comments.
    pub fn to_json(&self) -> serde_json::Value {
        let mut obj = serde_json::json!({
            "units": self.units,
            "generator": self.generator,
            "coordinate_frame": COORDINATE_FRAME_NOTE,
            "sign_convention": SIGN_CONVENTION_NOTE,
        });
        if !self.extras.is_null() {
            obj["provenance"] = self.extras.clone();
        }
        obj
    }

    /// Comment lines for text-capable formats (OBJ `#`, PLY `comment`); the units line
    /// comes first so that readers (ours included) find it.
    pub(crate) fn comment_lines(&self) -> Vec<String> {
        let mut lines = vec![
            format!("units {}", self.units),
            format!("generator {}", self.generator),
            format!("coordinate frame: {COORDINATE_FRAME_NOTE}"),
            format!("sign convention: {SIGN_CONVENTION_NOTE}"),
        ];
        if !self.extras.is_null() {
            lines.push(format!("provenance {}", self.extras));
        }
        // One comment per line, whatever the strings hold.
        lines
            .into_iter()
            .map(|l| l.replace(['\n', '\r'], " "))
            .collect()
    }
}

impl Default for MeshMetadata {
    /// Unit-ball coordinates, this software, no provenance.
    fn default() -> Self {
        Self::new("unit")
    }
}

/// A mesh as read from a file, with what the file said about itself.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedMesh {
    /// The validated mesh.
    pub mesh: TriMesh,
    /// The format it was parsed as (after content sniffing).
    pub format: MeshFormat,
    /// Units stated in the file (a comment such as "units mm", or glTF `extras.units`).
    pub units: Option<String>,
    /// glTF `asset.extras`, when present and valid JSON.
    pub extras: Option<serde_json::Value>,
}

/// Reads and validates a mesh file; the format comes from the extension.
pub fn read_mesh_file(path: &Path) -> Result<TriMesh, FormatError> {
    load_mesh_file(path).map(|l| l.mesh)
}

/// Reads and validates a mesh held in memory. A glTF given this way must embed its
/// buffers (GLB chunk or data URI): there is no directory to find external files in.
pub fn read_mesh_bytes(
    bytes: &[u8],
    format: MeshFormat,
    name: &str,
) -> Result<TriMesh, FormatError> {
    load_mesh_bytes(bytes, format, name).map(|l| l.mesh)
}

/// Like [`read_mesh_file`], also returning the units and extras found in the file.
/// An unknown extension falls back to content sniffing (GLB, glTF JSON, PLY).
pub fn load_mesh_file(path: &Path) -> Result<LoadedMesh, FormatError> {
    let name = display_name(path);
    let bytes = std::fs::read(path).map_err(|source| FormatError::Io {
        name: name.clone(),
        action: "cannot read file",
        source,
    })?;
    let format = match MeshFormat::from_path(path) {
        Ok(f) => f,
        Err(e) => MeshFormat::sniff(&bytes).ok_or(e)?,
    };
    let dir = path.parent().map(|d| {
        if d.as_os_str().is_empty() {
            Path::new(".")
        } else {
            d
        }
    });
    load(&bytes, format, &name, dir)
}

/// Like [`read_mesh_bytes`], also returning the units and extras found in the bytes.
pub fn load_mesh_bytes(
    bytes: &[u8],
    format: MeshFormat,
    name: &str,
) -> Result<LoadedMesh, FormatError> {
    load(bytes, format, name, None)
}

fn load(
    bytes: &[u8],
    format: MeshFormat,
    name: &str,
    dir: Option<&Path>,
) -> Result<LoadedMesh, FormatError> {
    if bytes.is_empty() {
        return Err(FormatError::malformed(name, format, "empty file (0 bytes)"));
    }
    // A GLB named .gltf (or the reverse) is still read correctly: the glTF reader sniffs.
    let loaded = match format {
        MeshFormat::Stl => stl::read(bytes, name)?,
        MeshFormat::Obj => obj::read(bytes, name)?,
        MeshFormat::Ply => ply::read(bytes, name)?,
        MeshFormat::Glb | MeshFormat::Gltf => gltf::read(bytes, name, dir)?,
    };
    loaded
        .mesh
        .validate()
        .map_err(|source| FormatError::InvalidMesh {
            name: name.to_owned(),
            format: loaded.format,
            source,
        })?;
    Ok(loaded)
}

/// Encodes a mesh in `format`. The mesh is validated first: nothing invalid is written.
pub fn write_mesh(
    mesh: &TriMesh,
    format: MeshFormat,
    meta: &MeshMetadata,
) -> Result<Vec<u8>, FormatError> {
    mesh.validate().map_err(|e| FormatError::Write {
        format,
        message: e.to_string(),
    })?;
    if u32::try_from(mesh.triangles.len()).is_err() || u32::try_from(mesh.positions.len()).is_err()
    {
        return Err(FormatError::Write {
            format,
            message: "more than 2^32 - 1 vertices or triangles".to_owned(),
        });
    }
    Ok(match format {
        MeshFormat::Stl => stl::write(mesh, meta),
        MeshFormat::Obj => obj::write(mesh, meta),
        MeshFormat::Ply => ply::write(mesh, meta),
        MeshFormat::Glb => gltf_write::write_glb(mesh, meta)?,
        MeshFormat::Gltf => gltf_write::write_gltf(mesh, meta)?,
    })
}

/// Writes a mesh to `path` in the format named by its extension.
pub fn write_mesh_file(
    path: &Path,
    mesh: &TriMesh,
    meta: &MeshMetadata,
) -> Result<(), FormatError> {
    let format = MeshFormat::from_path(path)?;
    let bytes = write_mesh(mesh, format, meta)?;
    std::fs::write(path, bytes).map_err(|source| FormatError::Io {
        name: display_name(path),
        action: "cannot write file",
        source,
    })
}

/// The name used in error messages: the file name, or the whole path if it has none.
fn display_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

/// Finds a units statement such as "units mm", "units: mm" or "units=mm" in free text.
pub(crate) fn units_in(text: &str) -> Option<String> {
    let lower = text.to_ascii_lowercase();
    let mut from = 0;
    while let Some(pos) = lower[from..].find("units") {
        let start = from + pos;
        let end = start + "units".len();
        from = end;
        let word_start = start == 0 || !lower.as_bytes()[start - 1].is_ascii_alphanumeric();
        let rest = &text[end..];
        let separated = rest.starts_with([':', '=', ' ', '\t']);
        if !word_start || !separated {
            continue;
        }
        let value: String = rest
            .trim_start_matches([':', '=', ' ', '\t'])
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        if !value.is_empty() {
            return Some(value);
        }
    }
    None
}

/// Runs a third-party parser, turning a panic on hostile input into an error message.
pub(crate) fn guard<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|payload| {
        let what = payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown failure".to_owned());
        format!("the parser failed on this input ({what})")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_are_found_in_the_usual_spellings() {
        assert_eq!(
            units_in("SynthAorta surface, units mm").as_deref(),
            Some("mm")
        );
        assert_eq!(units_in("UNITS: m").as_deref(), Some("m"));
        assert_eq!(units_in("units=unit").as_deref(), Some("unit"));
        assert_eq!(units_in("one unit is 105 mm"), None);
        assert_eq!(units_in("subunits mm"), None);
        assert_eq!(units_in("units"), None);
    }

    #[test]
    fn formats_parse_case_insensitively_and_print_their_names() {
        assert_eq!("GLB".parse::<MeshFormat>().unwrap(), MeshFormat::Glb);
        assert_eq!(".Ply".parse::<MeshFormat>().unwrap(), MeshFormat::Ply);
        assert!(
            "step"
                .parse::<MeshFormat>()
                .unwrap_err()
                .to_string()
                .contains("step")
        );
        let p = Path::new("/tmp/Shape.STL");
        assert_eq!(MeshFormat::from_path(p).unwrap(), MeshFormat::Stl);
        assert_eq!(MeshFormat::Gltf.to_string(), "glTF");
    }

    #[test]
    fn sniffing_recognises_self_announcing_formats() {
        assert_eq!(MeshFormat::sniff(b"glTF\x02\0\0\0"), Some(MeshFormat::Glb));
        assert_eq!(
            MeshFormat::sniff(b"  {\"asset\":{}}"),
            Some(MeshFormat::Gltf)
        );
        assert_eq!(
            MeshFormat::sniff(b"ply\nformat ascii 1.0\n"),
            Some(MeshFormat::Ply)
        );
        assert_eq!(MeshFormat::sniff(b"solid x\n"), None);
    }
}
