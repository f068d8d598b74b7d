//! The reference path: evaluate the field on the full R³ grid, then dense marching cubes.

use super::evaluate::{Evaluator, finish};
use super::{Evaluations, ExtractError, ExtractOptions, Extraction, ScalarField, Timings};
use crate::geometry::marching_cubes::marching_cubes;
use std::time::Instant;

/// Extracts the surface from a dense R³ evaluation (R³ floats in memory): the reference the
/// sparse [`super::extract_surface`] is checked against, and the baseline of its benchmark.
pub fn extract_dense(
    field: &dyn ScalarField,
    resolution: usize,
    options: &ExtractOptions,
) -> Result<Extraction, ExtractError> {
    let start = Instant::now();
    let grid = options.grid(resolution)?;
    let r = grid.resolution;
    let coords = grid.coordinates();
    let mut evaluator = Evaluator::new(field, options);
    let mut values = Vec::with_capacity(grid.sample_count());
    // A few planes at a time keeps the point buffer small next to the value grid.
    let planes = (options.batch_size * 8).div_ceil(r * r).max(1);
    for k0 in (0..r).step_by(planes) {
        let points: Vec<[f32; 3]> = (k0..(k0 + planes).min(r))
            .flat_map(|k| (0..r * r).map(move |n| (n, k)))
            .map(|(n, k)| [coords[n % r], coords[n / r], coords[k]])
            .collect();
        values.extend(evaluator.values(&points)?);
    }
    let mesh = marching_cubes(&grid, &values, options.iso);
    drop(values);
    let (mesh, normals, removed_components) = finish(mesh, &mut evaluator, options);
    let total = start.elapsed();
    Ok(Extraction {
        mesh,
        evaluations: Evaluations {
            block_centres: 0,
            samples: grid.sample_count() as u64,
            normals,
        },
        kept_blocks: 0,
        removed_components,
        timings: Timings {
            evaluation: evaluator.time,
            meshing: total.saturating_sub(evaluator.time),
        },
    })
}
