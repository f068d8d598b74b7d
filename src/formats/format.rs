//! Which mesh format a file or name means: by extension, by name, or by its first bytes.

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use super::{FormatError, display_name};

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

#[cfg(test)]
mod tests {
    use super::*;

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
