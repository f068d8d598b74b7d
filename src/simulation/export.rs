//! Files of a simulation mesh: the capped or open surface in every format solvers read
//! (VTP, legacy VTK, multi-solid STL, grouped OBJ, per-face GLB), each with a sidecar JSON
//! (`<file>.json`) holding the metadata, the face table with the boundary-condition data of
//! every opening, the openings and the quality report.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::faces::LabelledMesh;
use super::pipeline::SimulationMesh;
use super::prepared::PreparedSimulation;
use crate::formats::{
    FacePatch, LabelledWriteError, MeshMetadata, write_faces_glb, write_grouped_obj,
    write_legacy_vtk, write_multi_solid_stl, write_vtp,
};

/// The formats a simulation mesh is written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SimulationFormat {
    /// VTK XML PolyData with `ModelFaceID` (SimVascular, VMTK, ParaView).
    Vtp,
    /// Legacy ASCII VTK with `ModelFaceID`.
    Vtk,
    /// ASCII STL with one solid per face (snappyHexMesh patches).
    Stl,
    /// OBJ with one group per face.
    Obj,
    /// Binary glTF with one primitive per face.
    Glb,
}

impl SimulationFormat {
    /// Every format.
    pub const ALL: [SimulationFormat; 5] = [Self::Vtp, Self::Vtk, Self::Stl, Self::Obj, Self::Glb];

    /// File extension without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            Self::Vtp => "vtp",
            Self::Vtk => "vtk",
            Self::Stl => "stl",
            Self::Obj => "obj",
            Self::Glb => "glb",
        }
    }
}

/// Capped (watertight, wall + caps) or open (wall only, a boundary loop per opening).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Variant {
    /// Flat caps closing every opening.
    Capped,
    /// The wall alone.
    Open,
}

impl Variant {
    /// Both variants, the default first.
    pub const ALL: [Variant; 2] = [Self::Capped, Self::Open];

    /// `capped` or `open`, as in parameters and file names.
    pub fn name(self) -> &'static str {
        match self {
            Self::Capped => "capped",
            Self::Open => "open",
        }
    }
}

/// Encodes a labelled mesh.
pub fn encode(
    mesh: &LabelledMesh,
    format: SimulationFormat,
    meta: &MeshMetadata,
) -> Result<Vec<u8>, LabelledWriteError> {
    let patches: Vec<FacePatch> = mesh
        .faces
        .iter()
        .map(|f| FacePatch {
            id: f.id,
            name: f.name.clone(),
        })
        .collect();
    let (m, ids) = (&mesh.mesh, &mesh.face_ids[..]);
    match format {
        SimulationFormat::Vtp => write_vtp(m, ids, &patches, meta),
        SimulationFormat::Vtk => write_legacy_vtk(m, ids, &patches, meta),
        SimulationFormat::Stl => write_multi_solid_stl(m, ids, &patches),
        SimulationFormat::Obj => write_grouped_obj(m, ids, &patches, meta),
        SimulationFormat::Glb => write_faces_glb(m, ids, &patches, meta),
    }
}

/// The sidecar JSON of one variant (see [`SimulationSummary::sidecar`]).
pub fn sidecar(sim: &SimulationMesh, variant: Variant, meta: &MeshMetadata) -> serde_json::Value {
    PreparedSimulation::new(sim.clone())
        .summary
        .sidecar(variant, meta)
}

/// Writes `<stem>_<variant>.<ext>` and its sidecar `<…>.json` into `dir` for every format
/// and both variants; returns the paths written.
pub fn write_all(
    dir: &Path,
    stem: &str,
    sim: &SimulationMesh,
    meta: &MeshMetadata,
) -> anyhow::Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    let prepared = PreparedSimulation::new(sim.clone());
    for variant in [Variant::Capped, Variant::Open] {
        let mesh = prepared.mesh(variant);
        let side = serde_json::to_vec_pretty(&prepared.summary.sidecar(variant, meta))?;
        for format in SimulationFormat::ALL {
            let name = variant.name();
            let path = dir.join(format!("{stem}_{name}.{}", format.extension()));
            std::fs::write(&path, encode(&mesh, format, meta)?)?;
            let mut side_path = path.clone().into_os_string();
            side_path.push(".json");
            std::fs::write(&side_path, &side)?;
            written.push(path);
        }
    }
    Ok(written)
}
