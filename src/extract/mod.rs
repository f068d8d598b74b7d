//! Fast surface extraction from an implicit field (the neural SDF, or an analytic one).
//!
//! [`extract_surface`] evaluates the field only near its zero level: a coarse-to-fine pass over
//! blocks of cells (≤ 4 blocks per axis at the top, halving the edge at every level down to
//! [`ExtractOptions::block_cells`], 2 by default) keeps a block when `|f(centre)| ≤ L ·
//! half-diagonal · safety` (L = the field's Lipschitz bound) and splits it into its eight
//! children. A block that contains any surface point passes this test whatever the sign
//! pattern at its corners, so thin parts that a sign-change test would miss are kept. Block
//! centres of even edge are grid samples: their values are cached by grid index with the
//! samples taken afterwards, so no point is evaluated twice. The fine grid is then sampled
//! only at the corners of the kept finest blocks and polygonised with the very cell code of
//! [`crate::geometry::marching_cubes`] — so the mesh equals the dense R³ path
//! ([`extract_dense`]) vertex for vertex when L really bounds the gradient.
//!
//! **Batching and parallelism.** Points go to [`ScalarField::eval_batch`] in batches of
//! [`ExtractOptions::batch_size`] (default 32 768, large enough for big matrix products). With
//! [`Parallelism::InsideField`] (default) batches are sent one after another and the field
//! uses the cores itself (a tensor backend does); with [`Parallelism::AcrossBatches`] rayon
//! sends batches concurrently, for fields that evaluate a batch on one thread.
//!
//! ```
//! use aortagen::extract::{analytic::Shape, extract_surface, ExtractOptions};
//!
//! let sphere = Shape::Sphere { centre: [0.0; 3], radius: 0.5 };
//! let out = extract_surface(&sphere, 64, &ExtractOptions::default()).unwrap();
//! assert!(out.mesh.edge_report().is_closed_and_oriented());
//! assert!(out.evaluations.total() < 64 * 64 * 64 / 2);
//! ```

pub mod analytic;
pub mod components;
mod dense;
mod evaluate;
mod samples;
mod sparse;

pub use components::remove_small_components;
pub use dense::extract_dense;
pub use sparse::extract_surface;

use crate::geometry::marching_cubes::GridError;
use std::time::Duration;

/// A scalar field that can be meshed: negative inside, positive outside.
pub trait ScalarField: Sync {
    /// Writes `f(p)` for every point into `values` and, when `gradients` is given, `∇f(p)`
    /// into it (a field without gradients leaves it untouched; normals then come from the
    /// mesh faces). Both slices have the length of `points`.
    fn eval_batch(
        &self,
        points: &[[f32; 3]],
        values: &mut [f32],
        gradients: Option<&mut [[f32; 3]]>,
    );

    /// An upper bound L on `|∇f|` over the meshed box: 1 for an exact signed distance. The
    /// block culling is exact only when this really bounds the gradient.
    fn lipschitz_bound(&self) -> f32;
}

/// How batches of points are spread over the cores.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum Parallelism {
    /// One batch at a time; the field parallelises inside a batch.
    #[default]
    InsideField,
    /// Several batches at once on rayon's pool (fields that are single-threaded per batch).
    AcrossBatches,
}

/// Settings of an extraction; the defaults suit a unit-ball shape.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExtractOptions {
    /// Lower bound of the sampled cube on every axis.
    pub min: f32,
    /// Upper bound of the sampled cube on every axis.
    pub max: f32,
    /// Level set to extract (0 for a signed distance).
    pub iso: f32,
    /// Edge length of the finest blocks, in cells: their corner samples are all evaluated.
    /// 2 costs the fewest evaluations (the band of kept cells hugs the surface); larger
    /// blocks trade evaluations for fewer, larger polygonisation tasks.
    pub block_cells: usize,
    /// Factor on the Lipschitz bound when culling blocks (margin for fields whose bound is
    /// only approximate, such as a trained network).
    pub safety: f32,
    /// Points per `eval_batch` call.
    pub batch_size: usize,
    /// Who uses the cores during evaluation.
    pub parallelism: Parallelism,
    /// Components with fewer triangles than this fraction of the largest are removed
    /// (floaters); 0 keeps all. The default, a tenth, removes the detached blobs a trained
    /// network leaves in empty space (2–5 % of the surface on SynthAorta-100, nothing
    /// anatomical) and keeps any component of comparable size.
    pub min_component_fraction: f64,
    /// Vertex normals from the field's gradient (one more evaluation per vertex); otherwise
    /// area-weighted face normals.
    pub gradient_normals: bool,
}

impl Default for ExtractOptions {
    fn default() -> Self {
        Self {
            min: -1.0,
            max: 1.0,
            iso: 0.0,
            block_cells: 2,
            safety: 1.5,
            batch_size: 32_768,
            parallelism: Parallelism::InsideField,
            min_component_fraction: 0.1,
            gradient_normals: true,
        }
    }
}

/// Field evaluations spent by an extraction, by purpose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct Evaluations {
    /// Block centres evaluated on all levels (zero on the dense path); centres that are
    /// grid samples count here only, not again under `samples`.
    pub block_centres: u64,
    /// Grid samples evaluated after culling (R³ on the dense path).
    pub samples: u64,
    /// Points evaluated with gradients for vertex normals.
    pub normals: u64,
}

impl Evaluations {
    /// All evaluations together.
    pub fn total(&self) -> u64 {
        self.block_centres + self.samples + self.normals
    }
}

/// Where the time of an extraction went.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Timings {
    /// Inside `eval_batch`.
    pub evaluation: Duration,
    /// Everything else: culling, polygonisation, merging, cleaning.
    pub meshing: Duration,
}

/// The result of an extraction.
#[derive(Debug, Clone)]
pub struct Extraction {
    /// The surface (closed wherever it stays inside the box).
    pub mesh: crate::geometry::TriMesh,
    /// How many field evaluations were made.
    pub evaluations: Evaluations,
    /// Finest-level blocks that were sampled (zero on the dense path).
    pub kept_blocks: usize,
    /// Connected components removed as floaters.
    pub removed_components: usize,
    /// Time split.
    pub timings: Timings,
}

/// Why an extraction could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExtractError {
    /// The resolution or the bounds do not make a grid.
    #[error("invalid grid: {0}")]
    Grid(#[from] GridError),
    /// An option is out of range.
    #[error("option `{option}` {reason}")]
    Option {
        /// The option's field name.
        option: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The field's Lipschitz bound is not a positive finite number.
    #[error("the field's Lipschitz bound {0} must be positive and finite")]
    Lipschitz(f32),
    /// The field returned NaN or infinity.
    #[error("the field returned {value} at point {point:?}")]
    NonFinite {
        /// Where.
        point: [f32; 3],
        /// What.
        value: f32,
    },
}

impl ExtractOptions {
    /// Checks every option and returns the grid of `resolution` samples over the box.
    pub fn grid(
        &self,
        resolution: usize,
    ) -> Result<crate::geometry::marching_cubes::Grid, ExtractError> {
        let bad = |option, reason: &str| {
            Err(ExtractError::Option {
                option,
                reason: reason.to_owned(),
            })
        };
        if self.block_cells < 2 {
            return bad("block_cells", "must be at least 2");
        }
        if !(self.safety.is_finite() && self.safety >= 1.0) {
            return bad("safety", "must be a finite number ≥ 1");
        }
        if self.batch_size == 0 {
            return bad("batch_size", "must be positive");
        }
        if !(0.0..=1.0).contains(&self.min_component_fraction) {
            return bad("min_component_fraction", "must lie in [0, 1]");
        }
        if !self.iso.is_finite() {
            return Err(GridError::Iso(self.iso).into());
        }
        let grid = crate::geometry::marching_cubes::Grid {
            resolution,
            min: self.min,
            max: self.max,
        };
        grid.validate()?;
        Ok(grid)
    }
}
