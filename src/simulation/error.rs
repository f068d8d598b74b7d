//! The one error type of the simulation-mesh pipeline: every failure names the opening or
//! option at fault and says why, so a caller can answer a request with a sentence.

use crate::anatomy::MeasureError;
use crate::geometry::MeshError;

/// Why a simulation-ready mesh could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimulationError {
    /// The input mesh is unusable (empty, non-finite, bad indices).
    #[error("invalid mesh: {0}")]
    InvalidMesh(#[from] MeshError),
    /// An option is out of range; `field` names it.
    #[error("invalid option `{field}`: {message}")]
    BadOption {
        /// The option's field name.
        field: &'static str,
        /// What is wrong with its value.
        message: String,
    },
    /// The centreline or the landmarks the openings are placed from could not be measured.
    #[error("openings cannot be placed: {0}")]
    Measure(#[from] MeasureError),
    /// The shape has no recognisable ends (or not the ones its kind needs).
    #[error("openings not found: {0}")]
    OpeningsNotFound(String),
    /// An opening's plane lies outside the vessel (too far from the landmark or end).
    #[error("opening `{opening}` lies outside the vessel: {message}")]
    OutsideVessel {
        /// Name of the opening.
        opening: String,
        /// Why.
        message: String,
    },
    /// An opening's plane does not cut the surface in a closed loop around its centre.
    #[error("the plane of opening `{opening}` misses the surface: {message}")]
    CutMissesSurface {
        /// Name of the opening.
        opening: String,
        /// Why.
        message: String,
    },
    /// The part beyond an opening is not a simple end: the plane also cuts the surface
    /// elsewhere beyond the opening (another limb of the arch, a branch).
    #[error("the cut at opening `{opening}` is not local: {message}")]
    CutNotLocal {
        /// Name of the opening.
        opening: String,
        /// Why.
        message: String,
    },
    /// A remesh would make more triangles than the caller allows (`remesh_mm` too fine for
    /// the surface).
    #[error(
        "a remesh of {area_mm2:.0} mm² to this edge length makes about {triangles} triangles, \
         over the limit of {max_triangles}; use remesh_mm of at least {finest_mm} mm"
    )]
    OverBudget {
        /// Triangles the remesh would make.
        triangles: u64,
        /// The limit.
        max_triangles: u64,
        /// Area of the surface to remesh, mm².
        area_mm2: f64,
        /// The finest target edge length within the limit, mm.
        finest_mm: f64,
    },
    /// The cut or capped surface does not have the expected topology.
    #[error("unexpected topology: {0}")]
    Topology(String),
}

impl SimulationError {
    /// An out-of-range option.
    pub(crate) fn option(field: &'static str, message: impl Into<String>) -> Self {
        Self::BadOption {
            field,
            message: message.into(),
        }
    }
}
