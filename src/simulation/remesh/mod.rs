//! Isotropic remeshing (placeholder).
use serde::{Deserialize, Serialize};

use super::{LabelledMesh, SimulationError};

/// Remeshing settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RemeshOptions {
    /// Target edge length, mm.
    pub target_mm: f64,
}

impl RemeshOptions {
    /// Settings for a target edge length.
    pub fn new(target_mm: f64) -> Result<Self, SimulationError> {
        Ok(Self { target_mm })
    }
}

/// What the remeshing did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RemeshReport {
    /// Largest distance to the input surface, mm.
    pub max_distance_mm: f64,
}

/// Remeshes.
pub fn remesh(
    mesh: &LabelledMesh,
    _opts: &RemeshOptions,
) -> Result<(LabelledMesh, RemeshReport), SimulationError> {
    Ok((
        mesh.clone(),
        RemeshReport {
            max_distance_mm: 0.0,
        },
    ))
}
