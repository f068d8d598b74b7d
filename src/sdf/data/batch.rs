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

use crate::sdf::data::{PreparedDataset, PreparedShape};
use crate::sdf::training::loss::TrainingBatch;

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
pub fn epoch_batches(
    num_shapes: usize,
    batch_shapes: usize,
    seed: u64,
    epoch: u64,
) -> Vec<Vec<usize>> {
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

fn draw_shape(
    shape: &PreparedShape,
    size: &BatchSize,
    rng: &mut ChaCha8Rng,
    out: &mut TrainingBatch,
) {
    let available = shape.points.len();
    let drawn: Vec<usize> = (0..size.surface)
        .map(|_| rng.random_range(0..available))
        .collect();
    for &i in &drawn {
        out.surface_points.push(shape.points[i]);
        out.surface_normals.push(shape.normals[i]);
    }
    // Without surface points there is nothing to centre the Gaussians on: all uniform.
    let gaussian = if drawn.is_empty() {
        0
    } else {
        size.eikonal / 2
    };
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::normalize::UnitBallTransform;
    use crate::sdf::data::SamplingSettings;

    /// Two "shapes": points on spheres of radius 0.3 and 0.6 with radial normals.
    fn spheres() -> PreparedDataset {
        let shape = |r: f32, sigma: f32| {
            let points: Vec<[f32; 3]> = (0..200)
                .map(|i| {
                    let (t, p) = (i as f32 * 0.7, i as f32 * 0.31);
                    [r * t.sin() * p.cos(), r * t.sin() * p.sin(), r * t.cos()]
                })
                .collect();
            PreparedShape {
                name: format!("r{r}"),
                transform: UnitBallTransform::IDENTITY,
                normals: points.iter().map(|p| p.map(|c| c / r)).collect(),
                sigma: vec![sigma; points.len()],
                points,
            }
        };
        PreparedDataset {
            shapes: vec![shape(0.3, 0.01), shape(0.6, 0.02)],
            settings: SamplingSettings {
                points_per_shape: 200,
                knn_k: 5,
                seed: 0,
            },
        }
    }

    #[test]
    fn every_epoch_visits_every_shape_once_in_a_seeded_order() {
        let a = epoch_batches(10, 3, 5, 2);
        assert_eq!(a.iter().map(Vec::len).collect::<Vec<_>>(), [3, 3, 3, 1]);
        let mut all: Vec<usize> = a.concat();
        all.sort_unstable();
        assert_eq!(all, (0..10).collect::<Vec<_>>());
        assert_eq!(a, epoch_batches(10, 3, 5, 2));
        assert_ne!(a, epoch_batches(10, 3, 5, 3), "epochs shuffle differently");
    }

    #[test]
    fn batches_depend_only_on_seed_epoch_and_batch() {
        let data = spheres();
        let size = BatchSize {
            shapes: 2,
            surface: 16,
            eikonal: 12,
        };
        let a = draw_batch(&data, &[1, 0], &size, 9, 4, 1);
        assert_eq!(a, draw_batch(&data, &[1, 0], &size, 9, 4, 1));
        assert_ne!(a, draw_batch(&data, &[1, 0], &size, 9, 4, 2));
        assert_ne!(a, draw_batch(&data, &[1, 0], &size, 10, 4, 1));
        assert_eq!(a.shape_indices, [1, 0]);
        assert_eq!((a.surface_points.len(), a.eikonal_points.len()), (32, 24));
    }

    #[test]
    fn points_are_surface_samples_gaussians_near_them_and_uniform_ones() {
        let data = spheres();
        let size = BatchSize {
            shapes: 2,
            surface: 64,
            eikonal: 400,
        };
        let batch = draw_batch(&data, &[0, 1], &size, 1, 0, 0);
        let norm = |p: &[f32; 3]| p.iter().map(|c| c * c).sum::<f32>().sqrt();
        for (s, (r, sigma)) in [(0.3f32, 0.01f32), (0.6, 0.02)].into_iter().enumerate() {
            let surface = &batch.surface_points[s * 64..(s + 1) * 64];
            assert!(surface.iter().all(|p| (norm(p) - r).abs() < 1e-5));
            let normals = &batch.surface_normals[s * 64..(s + 1) * 64];
            for (p, n) in surface.iter().zip(normals) {
                assert!((0..3).all(|c| (n[c] - p[c] / r).abs() < 1e-5));
            }
            let eikonal = &batch.eikonal_points[s * 400..(s + 1) * 400];
            let (gaussian, uniform) = eikonal.split_at(200);
            // Radial offsets of the Gaussian half have spread ≈ σ (well inside 6σ).
            assert!(
                gaussian
                    .iter()
                    .all(|p| (norm(p) - r).abs() < 6.0 * sigma * 3f32.sqrt())
            );
            let spread =
                (gaussian.iter().map(|p| (norm(p) - r).powi(2)).sum::<f32>() / 200.0).sqrt();
            assert!(
                spread > 0.3 * sigma && spread < 3.0 * sigma,
                "spread {spread}"
            );
            assert!(uniform.iter().all(|p| p.iter().all(|c| c.abs() <= 1.0)));
            let far = uniform.iter().filter(|p| (norm(p) - r).abs() > 0.1).count();
            assert!(
                far > 100,
                "uniform points fill the cube ({far} of 200 far from the surface)"
            );
        }
    }
}
