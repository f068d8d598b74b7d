//! Batched field evaluation with timing, and the steps both extraction paths end with.

use super::{ExtractError, ExtractOptions, Parallelism, ScalarField, remove_small_components};
use crate::geometry::TriMesh;
use rayon::prelude::*;
use std::time::{Duration, Instant};

/// A batch of points with the slice their values go to.
type PointsAndValues<'a> = (&'a [[f32; 3]], &'a mut [f32]);

/// Sends points to a field in batches and keeps the time spent inside it.
pub(crate) struct Evaluator<'a> {
    field: &'a dyn ScalarField,
    options: &'a ExtractOptions,
    /// Total time inside `eval_batch`.
    pub(crate) time: Duration,
}

impl<'a> Evaluator<'a> {
    pub(crate) fn new(field: &'a dyn ScalarField, options: &'a ExtractOptions) -> Self {
        Self {
            field,
            options,
            time: Duration::ZERO,
        }
    }

    /// Points per `eval_batch` call.
    pub(crate) fn batch_size(&self) -> usize {
        self.options.batch_size
    }

    /// Field values at `points`, checked to be finite.
    pub(crate) fn values(&mut self, points: &[[f32; 3]]) -> Result<Vec<f32>, ExtractError> {
        let mut values = vec![0.0f32; points.len()];
        let start = Instant::now();
        let (field, batch) = (self.field, self.options.batch_size);
        let run = |(p, v): (&[[f32; 3]], &mut [f32])| field.eval_batch(p, v, None);
        match self.options.parallelism {
            Parallelism::InsideField => points
                .chunks(batch)
                .zip(values.chunks_mut(batch))
                .for_each(run),
            Parallelism::AcrossBatches => points
                .par_chunks(batch)
                .zip(values.par_chunks_mut(batch))
                .for_each(run),
        }
        self.time += start.elapsed();
        if let Some(n) = values.iter().position(|v| !v.is_finite()) {
            return Err(ExtractError::NonFinite {
                point: points[n],
                value: values[n],
            });
        }
        Ok(values)
    }

    /// Unit gradients at `points`; zero where the field gave none (or a zero gradient).
    pub(crate) fn normals(&mut self, points: &[[f32; 3]]) -> Vec<[f32; 3]> {
        let mut values = vec![0.0f32; points.len()];
        let mut grads = vec![[0.0f32; 3]; points.len()];
        let start = Instant::now();
        let (field, batch) = (self.field, self.options.batch_size);
        let run =
            |((p, v), g): (PointsAndValues<'_>, &mut [[f32; 3]])| field.eval_batch(p, v, Some(g));
        match self.options.parallelism {
            Parallelism::InsideField => points
                .chunks(batch)
                .zip(values.chunks_mut(batch))
                .zip(grads.chunks_mut(batch))
                .for_each(run),
            Parallelism::AcrossBatches => points
                .par_chunks(batch)
                .zip(values.par_chunks_mut(batch))
                .zip(grads.par_chunks_mut(batch))
                .for_each(run),
        }
        self.time += start.elapsed();
        grads
            .into_iter()
            .map(crate::geometry::marching_cubes::dense::unit)
            .collect()
    }
}

/// Gradient normals (where asked and available, face normals elsewhere) and floater removal.
/// Returns the finished mesh, the normal evaluations made and the removed component count.
pub(crate) fn finish(
    mut mesh: TriMesh,
    evaluator: &mut Evaluator<'_>,
    options: &ExtractOptions,
) -> (TriMesh, u64, usize) {
    let removed;
    (mesh, removed) = remove_small_components(mesh, options.min_component_fraction);
    let mut evaluations = 0;
    if options.gradient_normals && !mesh.positions.is_empty() {
        let mut normals = evaluator.normals(&mesh.positions);
        evaluations = mesh.positions.len() as u64;
        if normals.contains(&[0.0; 3]) {
            let faces = mesh.compute_vertex_normals();
            for (n, f) in normals.iter_mut().zip(faces) {
                if *n == [0.0; 3] {
                    *n = f;
                }
            }
        }
        mesh.normals = Some(normals);
    } else if mesh.normals.is_none() {
        mesh.normals = Some(mesh.compute_vertex_normals());
    }
    (mesh, evaluations, removed)
}
