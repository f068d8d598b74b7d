//! The one error type of the mesh readers and writers: it names the file, the format and,
//! where the parser knows it, the line, element or byte offset of the problem.

use super::MeshFormat;
use crate::geometry::MeshError;

/// Why a mesh file could not be read or written.
///
/// Callers branch on the variant: [`FormatError::Io`] is an environment problem, every
/// other variant means the input itself is unusable (an HTTP caller answers 422).
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The file could not be opened, read or written.
    #[error("{name}: {action}: {source}")]
    Io {
        /// File name as given.
        name: String,
        /// What was being attempted ("cannot read file", "cannot write file").
        action: &'static str,
        /// The operating-system error.
        #[source]
        source: std::io::Error,
    },
    /// The format could not be told from the extension or the name given.
    #[error("{name}: unknown mesh format {given:?} (expected one of glb, gltf, stl, obj, ply)")]
    UnknownFormat {
        /// File name or API argument.
        name: String,
        /// The extension or format name that was not recognised.
        given: String,
    },
    /// The bytes do not follow the format.
    #[error("{name}: {format} parse error{}: {message}", at.as_ref().map(|a| format!(" in {a}")).unwrap_or_default())]
    Malformed {
        /// File name.
        name: String,
        /// Format being parsed.
        format: MeshFormat,
        /// Where in the file, when known ("header line 3", "facet 12 (byte offset 684)").
        at: Option<String>,
        /// What is wrong.
        message: String,
    },
    /// The file parsed but describes an unusable mesh (no triangles, NaN coordinates,
    /// indices out of range, ...).
    #[error("{name}: invalid {format} mesh: {source}")]
    InvalidMesh {
        /// File name.
        name: String,
        /// Format the mesh came from.
        format: MeshFormat,
        /// The mesh check that failed.
        #[source]
        source: MeshError,
    },
    /// The file is valid but uses a feature this reader deliberately does not follow
    /// (for example a glTF buffer in an external file when only bytes were given).
    #[error("{name}: unsupported {format} content: {message}")]
    Unsupported {
        /// File name.
        name: String,
        /// Format being read.
        format: MeshFormat,
        /// What is not supported and what to do instead.
        message: String,
    },
    /// The mesh could not be encoded (it failed validation or is too large for the format).
    #[error("cannot write {format}: {message}")]
    Write {
        /// Output format.
        format: MeshFormat,
        /// Why.
        message: String,
    },
}

impl FormatError {
    /// A parse error at a known place.
    pub(crate) fn malformed_at(
        name: &str,
        format: MeshFormat,
        at: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Self::Malformed {
            name: name.to_owned(),
            format,
            at: Some(at.into()),
            message: message.into(),
        }
    }

    /// A parse error without a location.
    pub(crate) fn malformed(name: &str, format: MeshFormat, message: impl Into<String>) -> Self {
        Self::Malformed {
            name: name.to_owned(),
            format,
            at: None,
            message: message.into(),
        }
    }

    /// True when the input is at fault rather than the environment.
    pub fn is_bad_input(&self) -> bool {
        !matches!(self, Self::Io { .. })
    }
}
