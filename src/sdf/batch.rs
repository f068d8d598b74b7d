//! Reproducible mini-batches for training.
//!
//! Every random draw of epoch `e`, batch `b` comes from a ChaCha8 stream seeded from
//! `(seed, e, b)` alone, so a resumed run draws exactly the batches an uninterrupted run
//! would have drawn: the training RNG's "position" is just the pair (epoch, batch).
//!
//! Per shape a batch holds `N` surface points with their normals and `M` eikonal points from
//! D (DESIGN §2): `M/2` Gaussian around the drawn surface points with their `σ_local`, the rest
//! uniform in [-1,1]³.

use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::data::{PreparedDataset, PreparedShape};
use super::loss::TrainingBatch;

/// Points drawn per shape in one step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BatchSize {
    /// Shapes per batch, `B`.
    pub shapes: usize,
    /// Surface points per shape, `N`.
    pub surface: usize,
    /// Eikonal points per shape, `M`.
    pub eikonal: usize,
}

/// Stream tags keep the shuffle and the point draws independent.
const SHUFFLE_STREAM: u64 = 0x5348_5546;
const POINTS_STREAM: u64 = 0x504f_494e;

/// A ChaCha8 generator determined by `(seed, epoch, batch, stream)` only.
pub fn stream_rng(seed: u64, epoch: u64, batch: u64, stream: u64) -> ChaCha8Rng {
    let mut key = [0u8; 32];
    for (chunk, v) in key.chunks_exact_mut(8).zip([seed, epoch, batch, stream]) {
        chunk.copy_from_slice(&v.to_le_bytes());
    }
    ChaCha8Rng::from_seed(key)
}

/// The shapes of every batch of `epoch`: a seeded shuffle cut into groups of `batch_shapes`
/// (the last group may be smaller).
pub fn epoch_batches(num_shapes: usize, batch_shapes: usize, seed: u64, epoch: u64) -> Vec<Vec<usize>> {
    let mut order: Vec<usize> = (0..num_shapes).collect();
    order.shuffle(&mut stream_rng(seed, epoch, 0, SHUFFLE_STREAM));
    order
        .chunks(batch_shapes.max(1))
        .map(<[usize]>::to_vec)
        .collect()
}

/// Draws the points of batch `batch` of `epoch` for the given shapes, shape-major as
/// [`TrainingBatch`] expects.
pub fn draw_batch(
    data: &PreparedDataset,
    shapes: &[usize],
    size: &BatchSize,
    seed: u64,
    epoch: u64,
    batch: u64,
) -> TrainingBatch {
    let mut rng = stream_rng(seed, epoch, batch, POINTS_STREAM);
    let mut out = TrainingBatch {
        shape_indices: shapes.to_vec(),
        surface_points: Vec::with_capacity(shapes.len() * size.surface),
        surface_normals: Vec::with_capacity(shapes.len() * size.surface),
        eikonal_points: Vec::with_capacity(shapes.len() * size.eikonal),
    };
    for &k in shapes {
        draw_shape(&data.shapes[k], size, &mut rng, &mut out);
    }
    out
}

fn draw_shape(shape: &PreparedShape, size: &BatchSize, rng: &mut ChaCha8Rng, out: &mut TrainingBatch) {
    let available = shape.points.len();
    let drawn: Vec<usize> = (0..size.surface)
        .map(|_| rng.random_range(0..available))
        .collect();
    for &i in &drawn {
        out.surface_points.push(shape.points[i]);
        out.surface_normals.push(shape.normals[i]);
    }
    // Without surface points there is nothing to centre the Gaussians on: all uniform.
    let gaussian = if drawn.is_empty() { 0 } else { size.eikonal / 2 };
    for _ in 0..gaussian {
        let i = drawn[rng.random_range(0..drawn.len())];
        let (p, s) = (shape.points[i], shape.sigma[i]);
        out.eikonal_points.push(std::array::from_fn(|c| {
            p[c] + s * rng.sample::<f32, _>(StandardNormal)
        }));
    }
    for _ in gaussian..size.eikonal {
        out.eikonal_points
            .push(std::array::from_fn(|_| rng.random_range(-1.0f32..=1.0)));
    }
}
