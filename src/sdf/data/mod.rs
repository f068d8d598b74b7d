//! Training data: the shapes' meshes, normalised to the unit ball and sampled once.
//!
//! Each training shape is read from a mesh file (or generated parametrically), moved into the
//! unit ball (the transform is kept so generated meshes can be returned in millimetres), and
//! sampled once with `P` surface points and unit normals. Each sample also carries
//! `σ_local`, the distance to its k-th nearest neighbour among the shape's samples (k = 50 as
//! in IGR): the spread of the Gaussian part of the eikonal distribution D (DESIGN §2).
//! The prepared set is cached on disk ([`crate::sdf::data::cache`]) so reruns and resumes do not resample.

pub mod batch;
pub mod cache;
pub mod holdout;

use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::geometry::TriMesh;
use crate::geometry::normalize::{UnitBallTransform, normalize_to_unit_ball};
use crate::geometry::sampling::sample_surface;

/// File extensions read as training meshes (lower case).
pub const MESH_EXTENSIONS: [&str; 5] = ["stl", "obj", "ply", "glb", "gltf"];

/// Where the training shapes come from; recorded in the manifest so evaluation can find the
/// originals again.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DataSource {
    /// Every mesh file in a directory (not recursive), in file-name order.
    Directory {
        /// The directory.
        path: PathBuf,
    },
    /// `count` parametric aortic roots drawn from `seed` (the embedded default dataset).
    Synth {
        /// Number of shapes.
        count: usize,
        /// Seed of the parameter draw.
        seed: u64,
    },
}

/// How each shape is sampled once before training; part of the cache key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SamplingSettings {
    /// Surface points (with normals) per shape, `P`.
    pub points_per_shape: usize,
    /// Neighbour rank that defines `σ_local` (IGR: 50).
    pub knn_k: usize,
    /// Seed of the surface sampling (shape `i` uses `seed + i`).
    pub seed: u64,
}

/// One training shape, normalised and sampled.
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedShape {
    /// Display name (file stem or `root_007`).
    pub name: String,
    /// Mesh units ↔ unit ball.
    pub transform: UnitBallTransform,
    /// Surface points in unit-ball coordinates.
    pub points: Vec<[f32; 3]>,
    /// Unit outward normals, one per point.
    pub normals: Vec<[f32; 3]>,
    /// Distance to the k-th nearest other sample, one per point.
    pub sigma: Vec<f32>,
}

/// All training shapes, sampled with the same settings.
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedDataset {
    /// The shapes, in training-index order.
    pub shapes: Vec<PreparedShape>,
    /// How they were sampled.
    pub settings: SamplingSettings,
}

/// Reads (or generates) the source meshes in their own units, with their names.
pub fn load_source_meshes(source: &DataSource) -> anyhow::Result<Vec<(String, TriMesh)>> {
    match source {
        DataSource::Directory { path } => read_mesh_directory(path),
        DataSource::Synth { count, seed } => {
            if *count == 0 {
                bail!("--synth needs at least one shape");
            }
            Ok(crate::synth::generate_roots(*count, *seed, true)
                .into_iter()
                .enumerate()
                .map(|(i, (_, mesh))| (format!("root_{i:03}"), mesh))
                .collect())
        }
    }
}

/// Every mesh file of `dir` (by extension), sorted by file name so indices are stable.
pub fn read_mesh_directory(dir: &Path) -> anyhow::Result<Vec<(String, TriMesh)>> {
    let entries = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read the data directory {}", dir.display()))?;
    let mut files: Vec<PathBuf> = Vec::new();
    for entry in entries {
        let path = entry
            .with_context(|| format!("cannot list {}", dir.display()))?
            .path();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if path.is_file() && ext.is_some_and(|e| MESH_EXTENSIONS.contains(&e.as_str())) {
            files.push(path);
        }
    }
    files.sort();
    if files.is_empty() {
        bail!(
            "no mesh files ({}) in {}",
            MESH_EXTENSIONS.join(", "),
            dir.display()
        );
    }
    files
        .par_iter()
        .map(|path| {
            let mesh = crate::formats::read_mesh_file(path)
                .with_context(|| format!("cannot read mesh {}", path.display()))?;
            mesh.validate()
                .with_context(|| format!("unusable mesh {}", path.display()))?;
            let name = path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            Ok((name, mesh))
        })
        .collect()
}

/// Normalises and samples every mesh (in parallel, each shape with its own seed).
pub fn prepare_shapes(
    meshes: &[(String, TriMesh)],
    settings: &SamplingSettings,
) -> anyhow::Result<Vec<PreparedShape>> {
    if settings.points_per_shape <= settings.knn_k {
        bail!(
            "points per shape ({}) must exceed the neighbour rank k = {} used for σ_local",
            settings.points_per_shape,
            settings.knn_k
        );
    }
    meshes
        .par_iter()
        .enumerate()
        .map(|(i, (name, mesh))| {
            let (unit, transform) = normalize_to_unit_ball(mesh);
            let seed = settings.seed.wrapping_add(i as u64);
            let samples = sample_surface(&unit, settings.points_per_shape, seed);
            let sigma = local_sigma(&samples.points, settings.knn_k)
                .with_context(|| format!("cannot sample shape {name}"))?;
            Ok(PreparedShape {
                name: name.clone(),
                transform,
                points: samples.points,
                normals: samples.normals,
                sigma,
            })
        })
        .collect()
}

/// Distance from each point to its k-th nearest *other* point of the same set (k-d tree).
///
/// The point itself is its own nearest neighbour at distance 0, so the query asks for k + 1.
pub fn local_sigma(points: &[[f32; 3]], k: usize) -> anyhow::Result<Vec<f32>> {
    if k == 0 || points.len() <= k {
        bail!(
            "σ_local needs more than k = {k} points, got {}",
            points.len()
        );
    }
    let tree = ImmutableKdTree::<f32, 3>::new_from_slice(points)
        .map_err(|e| anyhow::anyhow!("cannot build a k-d tree over the samples: {e:?}"))?;
    let want = NonZeroUsize::new(k + 1).expect("k + 1 > 0");
    Ok(points
        .par_iter()
        .map(|p| {
            let found = tree
                .query(p)
                .nearest_n::<SquaredEuclidean<f32>>(want)
                .execute();
            found.last().map_or(0.0, |r| r.distance.sqrt())
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn local_sigma_is_the_distance_to_the_kth_other_point() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let points: Vec<[f32; 3]> = (0..300)
            .map(|_| std::array::from_fn(|_| rng.random_range(-1.0f32..1.0)))
            .collect();
        let k = 5;
        let sigma = local_sigma(&points, k).unwrap();
        for (i, p) in points.iter().enumerate() {
            let mut d: Vec<f32> = points
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| (0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f32>().sqrt())
                .collect();
            d.sort_by(f32::total_cmp);
            assert!((sigma[i] - d[k - 1]).abs() < 1e-5, "point {i}");
        }
    }

    #[test]
    fn local_sigma_needs_more_points_than_k() {
        let err = local_sigma(&[[0.0; 3]; 5], 5).unwrap_err().to_string();
        assert!(err.contains("k = 5"), "{err}");
    }

    #[test]
    fn a_directory_without_meshes_is_reported_by_name() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("notes.txt"), "x").unwrap();
        let err = read_mesh_directory(dir.path()).unwrap_err().to_string();
        assert!(err.contains("no mesh files"), "{err}");
        let err = read_mesh_directory(&dir.path().join("absent")).unwrap_err();
        assert!(format!("{err:#}").contains("absent"), "{err:#}");
    }
}
