//! Simulation-ready meshes: a closed vessel surface cut open at planar, labelled openings,
//! capped flat (or left open), optionally extended by straight flow extensions and
//! isotropically remeshed, with per-face boundary-condition data and a triangle-quality
//! report. This is what CFD of the root and aorta and FEA of a transcatheter valve start
//! from: one surface with a face id per triangle (SimVascular's `ModelFaceID`), caps planar
//! and perpendicular to the centreline.
//!
//! Steps ([`simulation_mesh`] runs them all):
//! 1. openings from the centreline and landmarks ([`find_openings`]): for an aortic root the
//!    inlet at (or below) the annulus and the outlet above the sinotubular junction; for a
//!    branched aorta the ascending inlet, the descending outlet and one outlet per branch;
//! 2. cutting ([`cut`]): each plane removes only the end beyond its opening;
//! 3. flow extensions ([`extension`], optional);
//! 4. caps ([`cap`]): each boundary loop closed by a flat constrained-Delaunay cap;
//! 5. isotropic remeshing ([`remesh`], optional), keeping the cap planes and rims;
//! 6. face table ([`faces`]) and quality ([`quality`]).
//!
//! [`request`] checks the parameters callers give (the service, the command line);
//! [`prepared`] keeps a result so every file and sidecar of either variant is written
//! from it without running the pipeline again.
//!
//! Face ids are described in [`opening`]; the writers are in [`crate::formats`].

pub mod cap;
pub mod cut;
mod error;
pub mod export;
pub mod extension;
pub mod faces;
pub mod intersect;
pub mod opening;
pub mod pipeline;
pub mod prepared;
pub mod quality;
pub mod remesh;
pub mod request;
pub mod root_openings;
#[cfg(test)]
pub(crate) mod test_shapes;
#[cfg(test)]
mod tests;
pub mod tree_openings;

pub use error::SimulationError;
pub use export::{SimulationFormat, Variant, encode, sidecar, write_all};
pub use faces::{FaceData, FaceName, LabelledMesh};
pub use opening::{FIRST_OUTLET_ID, INLET_ID, Opening, OpeningOptions, ShapeKind, WALL_ID};
pub use pipeline::{
    SimulationMesh, SimulationOptions, Step, cap_openings, find_openings, simulation_mesh,
    simulation_mesh_observed,
};
pub use prepared::{PreparedSimulation, SimulationSummary, StoredSimulation};
pub use quality::{QualityReport, quality_report};
pub use remesh::{RemeshOptions, RemeshReport, remesh};
pub use request::{MeshRequest, ParamError, SimulationParams, SimulationRequest};
