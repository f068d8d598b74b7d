//! Conditioned generation from a loaded model (the command line's side of
//! [`crate::anatomy::targets`]): the training shapes' measurements and the candidate
//! mixtures of a targeted shape.

use super::generate::{CohortSpecError, MixSpec, Mixture, Selection, attempt_seed};
use super::reconstruct::{ExtractionMethod, ReconstructError, reconstruct};
use super::store::LoadedModel;
use crate::anatomy::shape::{ShapeAnatomy, measure_shape};
use crate::anatomy::targets::{guided_indices, is_guided};

/// Each training latent meshed at `resolution` in its own mm frame and measured (`None`
/// where the measurement failed).
pub fn measure_training_shapes(
    model: &LoadedModel,
    latents: &[Vec<f32>],
    resolution: usize,
    extraction: ExtractionMethod,
) -> Result<Vec<Option<ShapeAnatomy>>, ReconstructError> {
    let transforms = model.manifest.transforms();
    latents
        .iter()
        .zip(&transforms)
        .map(|(z, transform)| {
            let field = model.field(z).map_err(ReconstructError::from)?;
            let mesh = reconstruct(&field, resolution, extraction)?.mesh;
            Ok(measure_shape(&transform.mesh_to_mesh_units(&mesh)).ok())
        })
        .collect()
}

/// The mixture of candidate `attempt` of cohort shape `shape`: the plain draw of that
/// attempt, with its training shapes drawn from `pool` on guided attempts.
pub fn candidate_mixture(
    spec: &MixSpec,
    latents: &[Vec<f32>],
    selection: Selection,
    (seed, shape, attempt): (u64, u64, u32),
    pool: &[usize],
) -> Result<Mixture, CohortSpecError> {
    let mut mixture = spec.mixture_with(latents, selection, seed, shape, attempt)?;
    if is_guided(attempt) && pool.len() >= spec.arity {
        let guided_seed = attempt_seed(seed ^ shape.rotate_left(32), attempt);
        mixture.indices = guided_indices(guided_seed, pool, spec.arity);
    }
    Ok(mixture)
}
