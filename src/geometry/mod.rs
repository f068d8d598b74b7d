//! Pure geometry: the triangle mesh type, normalisation, surface sampling, marching cubes
//! and the Chamfer distance. No I/O, no model, no async.

pub mod marching_cubes;
pub(crate) mod mc_cell;
pub(crate) mod mc_dense;
pub(crate) mod mc_tables;
pub mod mesh;

pub use mesh::{Aabb, EdgeReport, MeshError, TriMesh};
