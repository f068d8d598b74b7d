//! Mesh file formats: reading STL, OBJ, PLY and glTF/GLB into a [`TriMesh`] and writing
//! GLB, glTF, STL, OBJ and PLY; face-labelled surfaces (a face id per triangle) are written
//! as VTP, legacy VTK, multi-solid STL, grouped OBJ and per-face GLB.
//!
//! Every read ends with [`TriMesh::validate`], so a mesh that comes out of this module is
//! safe to measure and sample. Every failure is a [`FormatError`] naming the file, the
//! format and, where the parser knows it, the place in the file. No input makes a reader
//! panic. Units, the coordinate frame and the sign convention travel with every written
//! mesh: in glTF `extras`, and as comments in the formats that allow them.

mod error;
mod format;
mod gltf;
mod gltf_faces;
mod gltf_write;
mod labelled;
#[cfg(test)]
mod labelled_tests;
pub mod mesh_blob;
mod metadata;
mod obj;
mod ply;
mod stl;
mod transform;
mod vtk;

use std::path::Path;

pub use error::FormatError;
pub use format::MeshFormat;
pub use gltf_faces::write_faces_glb;
pub use labelled::{FacePatch, LabelledWriteError, write_grouped_obj, write_multi_solid_stl};
pub(crate) use metadata::units_in;
pub use metadata::{COORDINATE_FRAME_NOTE, MeshMetadata, SIGN_CONVENTION_NOTE};
pub use vtk::{write_legacy_vtk, write_vtp};

use crate::geometry::TriMesh;

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
pub(crate) fn display_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
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
