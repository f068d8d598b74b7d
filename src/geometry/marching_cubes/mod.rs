//! Marching cubes: the zero level (or any iso level) of a sampled scalar field as a
//! watertight, consistently oriented, indexed triangle mesh with gradient normals.
//!
//! **Why not the classic Lorensen table.** Its 15 cases resolve a face with alternating corner
//! signs differently depending on the rest of the cell, so two cells sharing such a face can
//! disagree and leave a hole. Here every ambiguous face is resolved by the *asymptotic
//! decider* (Nielson & Hamann 1991): the sign of the bilinear interpolant's saddle, a test on
//! that face's four values alone, so both cells always agree. The 2¹⁴ table entries (8 corner
//! bits × 6 face decisions) are generated from the cube's topology by tracing the face
//! segments into closed loops (see the table module), which makes the surface closed by
//! construction: every edge of the output lies in exactly two triangles, traversed once in
//! each direction, inside the grid. Interior ambiguities (MC33's tunnels) are not
//! reconstructed — each loop becomes its own disk — which keeps the surface manifold.
//!
//! Conventions: values below `iso` are inside (the signed-distance convention, negative
//! inside), a value *equal* to `iso` counts as outside, triangles are counter-clockwise seen
//! from outside, vertex normals are the field gradient (central differences of the grid,
//! interpolated along the edge) and point outward. One vertex is made per grid-edge crossing,
//! so the mesh is indexed without welding. The grid's border is not capped: a surface that
//! leaves the grid is open there.
//!
//! ```
//! use aortagen::geometry::marching_cubes::{marching_cubes, Grid};
//!
//! let grid = Grid::new(48);
//! let values: Vec<f32> = grid.points().map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 0.5).collect();
//! let mesh = marching_cubes(&grid, &values, 0.0);
//! assert!(mesh.edge_report().is_closed_and_oriented());
//! assert_eq!(mesh.euler_characteristic(), 2);
//! let sphere_volume = 4.0 / 3.0 * std::f64::consts::PI * 0.125;
//! assert!((mesh.signed_volume() / sphere_volume - 1.0).abs() < 0.01);
//! ```

pub(crate) mod cell;
pub(crate) mod dense;
mod grid;
pub(crate) mod tables;

pub use grid::{Grid, GridError, MAX_RESOLUTION};

use super::mesh::TriMesh;

/// The iso surface of `values` sampled on `grid` (see the module docs for the guarantees).
///
/// # Panics
/// When the grid is invalid or `values.len() != R³` — a caller's programming error; use
/// [`try_marching_cubes`] for input that is not known to be well formed. Non-finite values are
/// not checked here (NaN counts as outside).
pub fn marching_cubes(grid: &Grid, values: &[f32], iso: f32) -> TriMesh {
    if let Err(e) = check_shape(grid, values, iso) {
        panic!("marching_cubes: {e}");
    }
    dense::polygonise(grid, values, iso)
}

/// [`marching_cubes`] for untrusted input: reports a bad grid, a wrong number of values, a
/// non-finite iso level or the first non-finite sample instead of panicking.
pub fn try_marching_cubes(grid: &Grid, values: &[f32], iso: f32) -> Result<TriMesh, GridError> {
    check_shape(grid, values, iso)?;
    if let Some(n) = values.iter().position(|v| !v.is_finite()) {
        let r = grid.resolution;
        return Err(GridError::NonFinite {
            i: n % r,
            j: n / r % r,
            k: n / (r * r),
            value: values[n],
        });
    }
    Ok(dense::polygonise(grid, values, iso))
}

fn check_shape(grid: &Grid, values: &[f32], iso: f32) -> Result<(), GridError> {
    grid.validate()?;
    if values.len() != grid.sample_count() {
        return Err(GridError::Length {
            resolution: grid.resolution,
            expected: grid.sample_count(),
            found: values.len(),
        });
    }
    if !iso.is_finite() {
        return Err(GridError::Iso(iso));
    }
    Ok(())
}
