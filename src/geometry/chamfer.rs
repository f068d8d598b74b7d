//! Chamfer distance between point sets (DESIGN §3, as DeepSDF evaluates it):
//! `CD(A,B) = mean_a min_b ‖a−b‖² + mean_b min_a ‖a−b‖²` — squared distances, the sum of
//! both directed means, no factor ½. Reported in the coordinates of the points (unit-ball
//! coordinates everywhere in aortagen).
//!
//! Each set is indexed once by a k-d tree ([`ChamferIndex`]); the points of one set query
//! the other's tree a leaf at a time, in fixed tasks whose f64 partial sums are added in
//! order, so results do not depend on the thread count.

use rayon::prelude::*;

use super::mesh::TriMesh;
use super::point_tree::{LEAF, PointTree};
use super::sampling::sample_surface;

/// Points sampled per surface for a Chamfer distance (DeepSDF's evaluation uses 30 000).
pub const DEFAULT_CHAMFER_POINTS: usize = 30_000;

/// Query leaves per parallel task; fixed so the summation order is fixed.
const LEAVES_PER_TASK: usize = 16;

/// A point set with its nearest-neighbour tree, built once and queried many times.
pub struct ChamferIndex {
    tree: PointTree,
}

impl ChamferIndex {
    /// Indexes `points` (any order; an empty set is allowed).
    pub fn new(points: &[[f32; 3]]) -> Self {
        Self {
            tree: PointTree::new(points),
        }
    }

    /// Number of indexed points.
    pub fn len(&self) -> usize {
        self.tree.points().len()
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.tree.points().is_empty()
    }

    /// The indexed points (in tree order, not input order).
    pub fn points(&self) -> &[[f32; 3]] {
        self.tree.points()
    }

    /// Squared distance from `q` to the nearest indexed point (∞ for an empty set).
    pub fn nearest_squared(&self, q: &[f32; 3]) -> f64 {
        self.tree.nearest_squared(q)
    }

    /// `mean_q min_p ‖q−p‖²` over `queries`, computed in parallel (∞ for an empty index,
    /// NaN for no queries).
    pub fn mean_squared_distance_from(&self, queries: &[[f32; 3]]) -> f64 {
        self.mean_from_index(&ChamferIndex::new(queries), true)
    }

    /// Mean over the points of `queries`, a leaf (a compact block of points) at a time.
    fn mean_from_index(&self, queries: &ChamferIndex, parallel: bool) -> f64 {
        let leaves = queries.tree.leaf_count();
        let task = |t: usize| {
            let mut out = [0.0; LEAF];
            let mut sum = 0.0;
            for l in t * LEAVES_PER_TASK..((t + 1) * LEAVES_PER_TASK).min(leaves) {
                let block = queries.tree.leaf_points(l);
                self.tree.nearest_block(block, &mut out);
                sum += out[..block.len()].iter().sum::<f64>();
            }
            sum
        };
        let tasks = leaves.div_ceil(LEAVES_PER_TASK);
        let partial: Vec<f64> = if parallel {
            (0..tasks).into_par_iter().map(task).collect()
        } else {
            (0..tasks).map(task).collect()
        };
        partial.iter().sum::<f64>() / queries.len() as f64
    }
}

/// Chamfer distance between two indexed sets, queries in parallel.
/// Either set empty → ∞ (no nearest neighbour exists).
pub fn chamfer_between(a: &ChamferIndex, b: &ChamferIndex) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::INFINITY;
    }
    let (ab, ba) = rayon::join(|| b.mean_from_index(a, true), || a.mean_from_index(b, true));
    ab + ba
}

/// [`chamfer_between`] on the calling thread (bit-identical result).
fn chamfer_between_serial(a: &ChamferIndex, b: &ChamferIndex) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::INFINITY;
    }
    b.mean_from_index(a, false) + a.mean_from_index(b, false)
}

/// Chamfer distance between two point sets (DESIGN §3). Either set empty → ∞.
pub fn chamfer_distance(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let (ia, ib) = rayon::join(|| ChamferIndex::new(a), || ChamferIndex::new(b));
    chamfer_between(&ia, &ib)
}

/// Indexes every set once, in parallel.
pub fn index_sets(sets: &[Vec<[f32; 3]>]) -> Vec<ChamferIndex> {
    sets.par_iter().map(|s| ChamferIndex::new(s)).collect()
}

/// Symmetric matrix of Chamfer distances between all sets (zero diagonal): each tree is
/// built once and the n(n−1)/2 pairs run in parallel.
pub fn pairwise_chamfer(sets: &[Vec<[f32; 3]>]) -> Vec<Vec<f64>> {
    pairwise_chamfer_indexed(&index_sets(sets))
}

/// [`pairwise_chamfer`] over sets that are already indexed.
pub fn pairwise_chamfer_indexed(indices: &[ChamferIndex]) -> Vec<Vec<f64>> {
    let n = indices.len();
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .collect();
    let values: Vec<f64> = pairs
        .par_iter()
        .map(|&(i, j)| chamfer_between_serial(&indices[i], &indices[j]))
        .collect();
    let mut matrix = vec![vec![0.0; n]; n];
    for (&(i, j), &v) in pairs.iter().zip(&values) {
        matrix[i][j] = v;
        matrix[j][i] = v;
    }
    matrix
}

/// Chamfer distance from one point set to each of many indexed sets, in parallel.
pub fn chamfer_to_each(query: &[[f32; 3]], candidates: &[ChamferIndex]) -> Vec<f64> {
    let q = ChamferIndex::new(query);
    candidates
        .par_iter()
        .map(|c| chamfer_between_serial(&q, c))
        .collect()
}

/// The candidate set closest to `query` by Chamfer distance, as (index, distance); `None`
/// when there are no candidates. Ties go to the lower index.
pub fn nearest_by_chamfer(query: &[[f32; 3]], candidates: &[ChamferIndex]) -> Option<(usize, f64)> {
    chamfer_to_each(query, candidates)
        .into_iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// Chamfer distance between two independent `n`-point samplings of the same surface
/// (seeds `seed` and `seed + 1`): the value a perfect reconstruction would score, so
/// reconstruction figures can be read against it. ∞ if the mesh cannot be sampled.
pub fn sampling_floor(mesh: &TriMesh, n: usize, seed: u64) -> f64 {
    let (a, b) = rayon::join(
        || sample_surface(mesh, n, seed),
        || sample_surface(mesh, n, seed.wrapping_add(1)),
    );
    chamfer_distance(&a.points, &b.points)
}

#[cfg(test)]
#[path = "chamfer_tests.rs"]
mod tests;
