//! Chamfer distance between point sets (DESIGN §3, as DeepSDF evaluates it):
//! `CD(A,B) = mean_a min_b ‖a−b‖² + mean_b min_a ‖a−b‖²` — squared distances, the sum of
//! both directed means, no factor ½. Reported in the coordinates of the points (unit-ball
//! coordinates everywhere in aortagen).
//!
//! Each set is indexed once by a k-d tree ([`ChamferIndex`]); queries run in fixed chunks
//! whose f64 partial sums are added in order, so results do not depend on the thread count.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use super::mesh::TriMesh;
use super::sampling::sample_surface;

/// Points sampled per surface for a Chamfer distance (DeepSDF's evaluation uses 30 000).
pub const DEFAULT_CHAMFER_POINTS: usize = 30_000;

/// Queries per parallel task; fixed so the summation order is fixed.
const QUERY_CHUNK: usize = 2048;

type Tree = ImmutableKdTree<f32, 3>;

/// A point set with its nearest-neighbour tree, built once and queried many times.
pub struct ChamferIndex {
    tree: Option<Tree>,
    /// The points in the tree's leaf order: neighbouring queries visit neighbouring leaves
    /// when this set is used as the query side, which keeps the other tree in cache.
    ordered: Vec<[f32; 3]>,
}

impl ChamferIndex {
    /// Indexes `points` (any order; an empty set is allowed).
    pub fn new(points: &[[f32; 3]]) -> Self {
        // Only an index overflow (more than u32::MAX points) can fail construction.
        let tree = Tree::new_from_slice(points).ok().filter(|t| t.size() > 0);
        let ordered = match &tree {
            Some(t) => t.iter().map(|(_, p)| p).collect(),
            None => Vec::new(),
        };
        Self { tree, ordered }
    }

    /// Number of indexed points.
    pub fn len(&self) -> usize {
        self.ordered.len()
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.ordered.is_empty()
    }

    /// The indexed points (in tree order, not input order).
    pub fn points(&self) -> &[[f32; 3]] {
        &self.ordered
    }

    /// Squared distance from `q` to the nearest indexed point (∞ for an empty set).
    pub fn nearest_squared(&self, q: &[f32; 3]) -> f64 {
        match &self.tree {
            Some(t) => {
                t.query(q)
                    .nearest_one::<SquaredEuclidean<f64>>()
                    .execute()
                    .distance
            }
            None => f64::INFINITY,
        }
    }

    /// `mean_q min_p ‖q−p‖²` over `queries`, computed in parallel.
    pub fn mean_squared_distance_from(&self, queries: &[[f32; 3]]) -> f64 {
        let partial: Vec<f64> = queries
            .par_chunks(QUERY_CHUNK)
            .map(|chunk| self.sum_squared(chunk))
            .collect();
        partial.iter().sum::<f64>() / queries.len() as f64
    }

    /// The same mean on the calling thread only (for callers that parallelise outside).
    fn mean_squared_distance_serial(&self, queries: &[[f32; 3]]) -> f64 {
        let total: f64 = queries
            .chunks(QUERY_CHUNK)
            .map(|chunk| self.sum_squared(chunk))
            .sum();
        total / queries.len() as f64
    }

    fn sum_squared(&self, queries: &[[f32; 3]]) -> f64 {
        queries.iter().map(|q| self.nearest_squared(q)).sum()
    }
}

/// Chamfer distance between two indexed sets, queries in parallel.
/// Either set empty → ∞ (no nearest neighbour exists).
pub fn chamfer_between(a: &ChamferIndex, b: &ChamferIndex) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::INFINITY;
    }
    let (ab, ba) = rayon::join(
        || b.mean_squared_distance_from(a.points()),
        || a.mean_squared_distance_from(b.points()),
    );
    ab + ba
}

/// [`chamfer_between`] on the calling thread (bit-identical result).
fn chamfer_between_serial(a: &ChamferIndex, b: &ChamferIndex) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::INFINITY;
    }
    b.mean_squared_distance_serial(a.points()) + a.mean_squared_distance_serial(b.points())
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
