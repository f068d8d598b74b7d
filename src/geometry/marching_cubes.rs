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

use super::mc_dense;
use super::mesh::TriMesh;

/// Largest accepted resolution (keeps every vertex and edge index inside 32 bits).
pub const MAX_RESOLUTION: usize = 1024;

/// A cubic sample grid: `resolution` samples per axis spread evenly over `[min, max]`,
/// sample `(i, j, k)` stored at `i + R·(j + R·k)` (x fastest).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Grid {
    /// Samples per axis (R ≥ 2).
    pub resolution: usize,
    /// Coordinate of the first sample on every axis.
    pub min: f32,
    /// Coordinate of the last sample on every axis.
    pub max: f32,
}

/// Why a grid or its values cannot be meshed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridError {
    /// Fewer than two samples per axis, or more than [`MAX_RESOLUTION`].
    #[error("grid resolution {0} is outside 2..={MAX_RESOLUTION}")]
    Resolution(usize),
    /// The bounds are not finite or not increasing.
    #[error("grid bounds [{min}, {max}] must be finite with min < max")]
    Bounds {
        /// Given lower bound.
        min: f32,
        /// Given upper bound.
        max: f32,
    },
    /// The value slice does not hold R³ samples.
    #[error("grid of resolution {resolution} needs {expected} values, got {found}")]
    Length {
        /// The grid's resolution.
        resolution: usize,
        /// R³.
        expected: usize,
        /// Length of the given slice.
        found: usize,
    },
    /// A sample is NaN or infinite.
    #[error("sample ({i}, {j}, {k}) has the non-finite value {value}")]
    NonFinite {
        /// x index.
        i: usize,
        /// y index.
        j: usize,
        /// z index.
        k: usize,
        /// The value found.
        value: f32,
    },
    /// The iso level is NaN or infinite.
    #[error("iso level {0} is not finite")]
    Iso(f32),
}

impl Grid {
    /// R samples per axis over the unit-ball box `[-1, 1]³` used for normalised shapes.
    pub fn new(resolution: usize) -> Self {
        Self {
            resolution,
            min: -1.0,
            max: 1.0,
        }
    }

    /// Checks the resolution and the bounds.
    pub fn validate(&self) -> Result<(), GridError> {
        if !(2..=MAX_RESOLUTION).contains(&self.resolution) {
            return Err(GridError::Resolution(self.resolution));
        }
        if !(self.min.is_finite() && self.max.is_finite() && self.min < self.max) {
            return Err(GridError::Bounds {
                min: self.min,
                max: self.max,
            });
        }
        Ok(())
    }

    /// Number of samples, R³.
    pub fn sample_count(&self) -> usize {
        self.resolution.pow(3)
    }

    /// Distance between neighbouring samples.
    pub fn spacing(&self) -> f32 {
        (self.max - self.min) / (self.resolution - 1) as f32
    }

    /// Coordinate of sample index `i` on any axis (computed in f64, so the last sample is
    /// exactly `max`). Every path that samples the grid uses this, which keeps the dense and
    /// sparse extractions bit-identical.
    pub fn coordinate(&self, i: usize) -> f32 {
        let t = i as f64 / (self.resolution - 1) as f64;
        (f64::from(self.min) + t * (f64::from(self.max) - f64::from(self.min))) as f32
    }

    /// All R coordinates of one axis.
    pub fn coordinates(&self) -> Vec<f32> {
        (0..self.resolution).map(|i| self.coordinate(i)).collect()
    }

    /// Position of sample `(i, j, k)`.
    pub fn point(&self, i: usize, j: usize, k: usize) -> [f32; 3] {
        [self.coordinate(i), self.coordinate(j), self.coordinate(k)]
    }

    /// All sample positions in storage order (x fastest).
    pub fn points(&self) -> impl Iterator<Item = [f32; 3]> + '_ {
        let c = self.coordinates();
        let r = self.resolution;
        (0..self.sample_count()).map(move |n| [c[n % r], c[n / r % r], c[n / (r * r)]])
    }
}

impl Default for Grid {
    /// The paper's 256³ over `[-1, 1]³`.
    fn default() -> Self {
        Self::new(256)
    }
}

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
    mc_dense::polygonise(grid, values, iso)
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
    Ok(mc_dense::polygonise(grid, values, iso))
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
