//! A simulation mesh made once and served many times: the capped labelled surface and a
//! summary of everything else (openings, the face table and quality of both variants, the
//! remesh report), from which every file and sidecar of either variant is written without
//! running the pipeline again. It is also the form stored beside a generated shape: the
//! surface as a mesh blob and a face-id blob, the summary as JSON.

use serde::{Deserialize, Serialize};

use super::export::{SimulationFormat, Variant, encode};
use super::faces::{FaceData, FaceName, LabelledMesh};
use super::opening::{Opening, ShapeKind};
use super::pipeline::SimulationMesh;
use super::quality::{QualityReport, quality_report};
use super::remesh::RemeshReport;
use crate::formats::{LabelledWriteError, MeshMetadata, mesh_blob};

/// Everything known about a simulation mesh but its triangles.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulationSummary {
    /// The rules the openings followed.
    pub kind: ShapeKind,
    /// The opening planes (before any flow extension moved the caps).
    pub openings: Vec<Opening>,
    /// Face table of the capped variant (wall, caps, extension walls).
    pub capped_faces: Vec<FaceData>,
    /// Quality of the capped variant.
    pub capped_quality: QualityReport,
    /// Face table of the open variant (the caps left out).
    pub open_faces: Vec<FaceData>,
    /// Quality of the open variant.
    pub open_quality: QualityReport,
    /// What the remeshing did, when it ran.
    pub remesh: Option<RemeshReport>,
}

impl SimulationSummary {
    /// The face table of a variant.
    pub fn faces(&self, variant: Variant) -> &[FaceData] {
        match variant {
            Variant::Capped => &self.capped_faces,
            Variant::Open => &self.open_faces,
        }
    }

    /// The sidecar JSON of a variant: metadata, face table, openings with their
    /// boundary-condition data and planes, quality, remesh report.
    pub fn sidecar(&self, variant: Variant, meta: &MeshMetadata) -> serde_json::Value {
        let quality = match variant {
            Variant::Capped => &self.capped_quality,
            Variant::Open => &self.open_quality,
        };
        let caps: Vec<&FaceData> = self
            .capped_faces
            .iter()
            .filter(|f| self.openings.iter().any(|o| o.id == f.id))
            .collect();
        serde_json::json!({
            "metadata": meta.to_json(),
            "variant": variant,
            "kind": self.kind,
            "face_id_array": "ModelFaceID",
            "faces": self.faces(variant),
            "openings": caps,
            "opening_planes": self.openings,
            "quality": quality,
            "remesh": self.remesh,
        })
    }
}

/// A capped simulation surface with its summary.
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedSimulation {
    /// The watertight labelled surface, mm.
    pub capped: LabelledMesh,
    /// The rest.
    pub summary: SimulationSummary,
}

/// The stored form: mesh blob, face ids (`u32` little endian per triangle), summary JSON.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredSimulation {
    /// [`mesh_blob`] encoding of the capped surface.
    pub mesh: Vec<u8>,
    /// Face id of each triangle.
    pub face_ids: Vec<u8>,
    /// [`SimulationSummary`] as JSON.
    pub summary: String,
}

/// Why stored bytes are not a simulation mesh (a corrupted or foreign row).
#[derive(Debug, thiserror::Error)]
pub enum StoredSimulationError {
    /// The mesh blob does not decode.
    #[error(transparent)]
    Mesh(#[from] mesh_blob::MeshBlobError),
    /// The face ids are not one `u32` per triangle, or name faces the summary lacks.
    #[error("stored face ids do not match the mesh: {0}")]
    FaceIds(String),
    /// The summary is not valid JSON of the expected shape.
    #[error("stored summary does not parse: {0}")]
    Summary(#[from] serde_json::Error),
}

impl PreparedSimulation {
    /// Summarises a pipeline result (the open variant's table and quality are measured
    /// here, once).
    pub fn new(sim: SimulationMesh) -> Self {
        let open = sim.open();
        let summary = SimulationSummary {
            kind: sim.kind,
            openings: sim.openings,
            capped_faces: sim.faces,
            capped_quality: sim.quality,
            open_faces: open.face_table(),
            open_quality: quality_report(&open.mesh),
            remesh: sim.remesh,
        };
        Self {
            capped: sim.capped,
            summary,
        }
    }

    /// The labelled surface of a variant.
    pub fn mesh(&self, variant: Variant) -> LabelledMesh {
        match variant {
            Variant::Capped => self.capped.clone(),
            Variant::Open => self.capped.wall_only(),
        }
    }

    /// The file of a variant in `format`.
    pub fn file(
        &self,
        format: SimulationFormat,
        variant: Variant,
        meta: &MeshMetadata,
    ) -> Result<Vec<u8>, LabelledWriteError> {
        match variant {
            Variant::Capped => encode(&self.capped, format, meta),
            Variant::Open => encode(&self.capped.wall_only(), format, meta),
        }
    }

    /// The stored form.
    pub fn to_stored(&self) -> StoredSimulation {
        StoredSimulation {
            mesh: mesh_blob::encode(&self.capped.mesh),
            face_ids: self
                .capped
                .face_ids
                .iter()
                .flat_map(|id| id.to_le_bytes())
                .collect(),
            summary: serde_json::to_string(&self.summary).expect("summaries serialise"),
        }
    }

    /// Reads the stored form back; the face names come from the summary's face table.
    pub fn from_stored(stored: &StoredSimulation) -> Result<Self, StoredSimulationError> {
        let mesh = mesh_blob::decode(&stored.mesh)?;
        let summary: SimulationSummary = serde_json::from_str(&stored.summary)?;
        if stored.face_ids.len() != 4 * mesh.triangle_count() {
            return Err(StoredSimulationError::FaceIds(format!(
                "{} bytes for {} triangles",
                stored.face_ids.len(),
                mesh.triangle_count()
            )));
        }
        let face_ids: Vec<u32> = stored
            .face_ids
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let faces: Vec<FaceName> = summary
            .capped_faces
            .iter()
            .map(|f| FaceName {
                id: f.id,
                name: f.name.clone(),
            })
            .collect();
        if let Some(id) = face_ids
            .iter()
            .find(|id| !faces.iter().any(|f| f.id == **id))
        {
            return Err(StoredSimulationError::FaceIds(format!(
                "face id {id} is not in the face table"
            )));
        }
        Ok(Self {
            capped: LabelledMesh {
                mesh,
                face_ids,
                faces,
            },
            summary,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulation::test_shapes::straight_tube;
    use crate::simulation::{ShapeKind, SimulationOptions, simulation_mesh};

    fn prepared() -> (SimulationMesh, PreparedSimulation) {
        let opts = SimulationOptions {
            kind: Some(ShapeKind::Tube),
            ..Default::default()
        };
        let tube = straight_tube(10.0, 100.0, [1.0, 2.0, 3.0], [0.0, 0.0, 1.0], 40, 36);
        let sim = simulation_mesh(&tube, &opts).unwrap();
        (sim.clone(), PreparedSimulation::new(sim))
    }

    #[test]
    fn the_stored_form_reads_back_to_the_same_surface_labels_and_summary() {
        let (_, prepared) = prepared();
        let back = PreparedSimulation::from_stored(&prepared.to_stored()).unwrap();
        assert_eq!(back, prepared);
    }

    #[test]
    fn files_and_sidecars_equal_those_written_from_the_pipeline_result() {
        let (sim, prepared) = prepared();
        let back = PreparedSimulation::from_stored(&prepared.to_stored()).unwrap();
        let meta = MeshMetadata::new("mm");
        for variant in [Variant::Capped, Variant::Open] {
            let direct = match variant {
                Variant::Capped => sim.capped.clone(),
                Variant::Open => sim.open(),
            };
            for format in SimulationFormat::ALL {
                assert_eq!(
                    back.file(format, variant, &meta).unwrap(),
                    encode(&direct, format, &meta).unwrap(),
                    "{format:?} {variant:?}"
                );
            }
            let side = back.summary.sidecar(variant, &meta);
            assert_eq!(side, prepared.summary.sidecar(variant, &meta));
            assert_eq!(side["faces"], serde_json::json!(direct.face_table()));
            assert_eq!(
                side["quality"],
                serde_json::json!(quality_report(&direct.mesh))
            );
        }
    }

    #[test]
    fn corrupted_face_ids_are_refused() {
        let (_, prepared) = prepared();
        let mut stored = prepared.to_stored();
        stored.face_ids.pop();
        assert!(matches!(
            PreparedSimulation::from_stored(&stored),
            Err(StoredSimulationError::FaceIds(_))
        ));
        let mut stored = prepared.to_stored();
        stored.face_ids[..4].copy_from_slice(&77u32.to_le_bytes());
        assert!(PreparedSimulation::from_stored(&stored).is_err());
    }
}
