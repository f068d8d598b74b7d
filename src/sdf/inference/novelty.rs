//! Novelty of generated shapes: the Chamfer distance (unit-ball coordinates) to the nearest
//! training shape. A synthetic shape very close to one training shape would disclose that
//! patient's anatomy, so cohorts report it per shape and can require a minimum.
//!
//! The training side is the model's reconstruction of each training latent, extracted at
//! the cohort's resolution: generated and training surfaces then pass through the same
//! decoder and the same marching cubes, so the distance measures how far the shape moved in
//! latent space rather than the decoder's reconstruction error (the training meshes are not
//! kept in a model directory either).

use std::sync::atomic::{AtomicBool, Ordering};

use serde::{Deserialize, Serialize};

use crate::geometry::TriMesh;
use crate::geometry::chamfer::{ChamferIndex, nearest_by_chamfer};
use crate::geometry::sampling::sample_surface;
use crate::sdf::inference::reconstruct::{ExtractionMethod, ReconstructError, reconstruct};
use crate::sdf::store::LoadedModel;

/// Seed of the training surfaces' samples (fixed, so every cohort compares against the
/// same point sets).
pub const REFERENCE_SEED: u64 = 0x7261_696e;

/// A shape's distance to the training set.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Novelty {
    /// Chamfer distance to the nearest training shape (unit-ball coordinates).
    pub chamfer: f64,
    /// That training shape's index.
    pub nearest: usize,
}

/// Why novelty cannot be measured.
#[derive(Debug, thiserror::Error)]
pub enum NoveltyError {
    /// A training latent gave no surface.
    #[error("training shape {index}: {source}")]
    Reconstruct {
        /// Its index.
        index: usize,
        /// Why.
        source: ReconstructError,
    },
    /// A surface has no area to sample.
    #[error("{0} has no surface to sample")]
    Empty(String),
    /// The model has no training shapes.
    #[error("the model has no training shapes")]
    NoTrainingShapes,
    /// Stopped on request.
    #[error("cancelled")]
    Cancelled,
}

/// The training surfaces, sampled and indexed once, to measure shapes against.
pub struct NoveltyReference {
    indices: Vec<ChamferIndex>,
    points: usize,
}

impl std::fmt::Debug for NoveltyReference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NoveltyReference")
            .field("shapes", &self.indices.len())
            .field("points", &self.points)
            .finish()
    }
}

impl NoveltyReference {
    /// Samples `points` points on each training surface (unit-ball coordinates).
    pub fn new(surfaces: &[TriMesh], points: usize) -> Result<Self, NoveltyError> {
        if surfaces.is_empty() {
            return Err(NoveltyError::NoTrainingShapes);
        }
        let points = points.max(1);
        let indices = surfaces
            .iter()
            .enumerate()
            .map(|(i, mesh)| {
                let samples = sample_surface(mesh, points, REFERENCE_SEED.wrapping_add(i as u64));
                if samples.points.is_empty() {
                    return Err(NoveltyError::Empty(format!("training shape {i}")));
                }
                Ok(ChamferIndex::new(&samples.points))
            })
            .collect::<Result<_, _>>()?;
        Ok(Self { indices, points })
    }

    /// Number of training shapes.
    pub fn len(&self) -> usize {
        self.indices.len()
    }

    /// Whether there are no training shapes (never, once built).
    pub fn is_empty(&self) -> bool {
        self.indices.is_empty()
    }

    /// Samples per surface.
    pub fn points(&self) -> usize {
        self.points
    }

    /// The nearest training shape to `mesh` (unit-ball coordinates), sampled with `seed`.
    pub fn novelty(&self, mesh: &TriMesh, seed: u64) -> Result<Novelty, NoveltyError> {
        let samples = sample_surface(mesh, self.points, seed);
        if samples.points.is_empty() {
            return Err(NoveltyError::Empty("the generated shape".into()));
        }
        let (nearest, chamfer) = nearest_by_chamfer(&samples.points, &self.indices)
            .ok_or(NoveltyError::NoTrainingShapes)?;
        Ok(Novelty { chamfer, nearest })
    }
}

/// The model's reconstruction of every training latent at `resolution` (unit-ball
/// coordinates), stopping early once `cancel` is set.
pub fn training_surfaces(
    model: &LoadedModel,
    latents: &[Vec<f32>],
    resolution: usize,
    extraction: ExtractionMethod,
    cancel: &AtomicBool,
) -> Result<Vec<TriMesh>, NoveltyError> {
    latents
        .iter()
        .enumerate()
        .map(|(index, z)| training_surface(model, z, index, resolution, extraction, cancel))
        .collect()
}

/// The model's reconstruction of training latent `index` (`latent`) at `resolution`
/// (unit-ball coordinates): one surface of the novelty reference.
pub fn training_surface(
    model: &LoadedModel,
    latent: &[f32],
    index: usize,
    resolution: usize,
    extraction: ExtractionMethod,
    cancel: &AtomicBool,
) -> Result<TriMesh, NoveltyError> {
    if cancel.load(Ordering::Relaxed) {
        return Err(NoveltyError::Cancelled);
    }
    let field = model.field(latent).map_err(|e| NoveltyError::Reconstruct {
        index,
        source: ReconstructError::from(e),
    })?;
    reconstruct(&field, resolution, extraction)
        .map(|e| e.mesh)
        .map_err(|source| NoveltyError::Reconstruct { index, source })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_shapes;

    fn sphere(r: f32) -> TriMesh {
        test_shapes::uv_sphere(r, [0.0; 3], 24, 48)
    }

    #[test]
    fn the_nearest_training_shape_is_found_with_a_small_distance() {
        let reference = NoveltyReference::new(&[sphere(0.5), sphere(0.9)], 3000).unwrap();
        assert_eq!((reference.len(), reference.points()), (2, 3000));
        let near_large = reference.novelty(&sphere(0.89), 1).unwrap();
        assert_eq!(near_large.nearest, 1);
        assert!(near_large.chamfer >= 0.0 && near_large.chamfer < 1e-2);
        assert_eq!(reference.novelty(&sphere(0.6), 2).unwrap().nearest, 0);
        let far = reference.novelty(&sphere(0.1), 3).unwrap();
        assert_eq!(far.nearest, 0);
        assert!(
            far.chamfer > 10.0 * near_large.chamfer,
            "{far:?} vs {near_large:?}"
        );
    }

    #[test]
    fn an_empty_reference_is_refused() {
        assert!(matches!(
            NoveltyReference::new(&[], 10),
            Err(NoveltyError::NoTrainingShapes)
        ));
    }
}
