//! Pure geometry: the triangle mesh type, normalisation, surface sampling, marching cubes
//! and the Chamfer distance. No I/O, no model, no async.

pub mod chamfer;
pub mod marching_cubes;
pub mod mesh;
pub mod normalize;
pub mod point_tree;
pub mod sampling;
#[cfg(test)]
pub(crate) mod test_shapes;

pub use mesh::{Aabb, EdgeReport, MeshError, TriMesh, cross, dot, norm, normalized, sub};
