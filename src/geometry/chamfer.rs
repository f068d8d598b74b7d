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

/// [`chamfer_between`] on the calling thread (bit-identical result), for callers that
/// run many pairs in parallel.
pub fn chamfer_between_serial(a: &ChamferIndex, b: &ChamferIndex) -> f64 {
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
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::geometry::test_shapes::uv_sphere;

    fn random_points(n: usize, seed: u64, scale: f32) -> Vec<[f32; 3]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                std::array::from_fn(|_| scale * ((rng.next_u32() >> 8) as f32 / 16_777_216.0 - 0.5))
            })
            .collect()
    }

    /// mean over `from` of the squared distance to the nearest point of `to`, in f64.
    fn directed_brute_force(from: &[[f32; 3]], to: &[[f32; 3]]) -> f64 {
        from.iter()
            .map(|p| {
                to.iter()
                    .map(|q| {
                        (0..3)
                            .map(|k| (f64::from(p[k]) - f64::from(q[k])).powi(2))
                            .sum::<f64>()
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .sum::<f64>()
            / from.len() as f64
    }

    fn brute_force(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
        directed_brute_force(a, b) + directed_brute_force(b, a)
    }

    fn assert_close(x: f64, y: f64, rel: f64) {
        assert!((x - y).abs() <= rel * y.abs().max(1e-300), "{x} vs {y}");
    }

    #[test]
    fn chamfer_equals_brute_force_on_random_sets() {
        for (na, nb, seed) in [(1, 1, 1), (7, 300, 2), (500, 350, 3), (3000, 2500, 4)] {
            let a = random_points(na, seed, 2.0);
            let b = random_points(nb, seed + 100, 1.5);
            assert_close(chamfer_distance(&a, &b), brute_force(&a, &b), 1e-9);
        }
    }

    #[test]
    fn chamfer_is_symmetric_and_zero_for_identical_sets() {
        let a = random_points(5000, 10, 1.0);
        let b = random_points(4000, 11, 1.0);
        assert_close(chamfer_distance(&a, &b), chamfer_distance(&b, &a), 1e-12);
        assert_eq!(chamfer_distance(&a, &a), 0.0);
        let mut shuffled = a.clone();
        shuffled.reverse();
        assert_eq!(chamfer_distance(&a, &shuffled), 0.0);
    }

    #[test]
    fn chamfer_of_a_translated_copy_is_twice_the_squared_shift_when_far_apart() {
        let a = random_points(2000, 12, 0.1);
        let b: Vec<[f32; 3]> = a.iter().map(|p| [p[0] + 10.0, p[1], p[2]]).collect();
        // Every nearest neighbour is the translated twin only if the shift dominates; compare
        // with brute force rather than assuming it, then check the scale of the answer.
        let cd = chamfer_distance(&a, &b);
        assert_close(cd, brute_force(&a, &b), 1e-9);
        assert!(
            cd > 2.0 * 9.9f64.powi(2) && cd < 2.0 * 10.01f64.powi(2),
            "{cd}"
        );
    }

    #[test]
    fn pairwise_matrix_matches_individual_calls() {
        let sets: Vec<Vec<[f32; 3]>> = (0..5)
            .map(|s| random_points(800 + 100 * s, s as u64, 1.0))
            .collect();
        let m = pairwise_chamfer(&sets);
        for i in 0..5 {
            assert_eq!(m[i][i], 0.0);
            for j in 0..5 {
                if i != j {
                    assert_close(m[i][j], chamfer_distance(&sets[i], &sets[j]), 1e-12);
                    assert_eq!(m[i][j], m[j][i]);
                }
            }
        }
    }

    #[test]
    fn nearest_by_chamfer_finds_the_closest_set() {
        let query = random_points(1000, 20, 1.0);
        let near: Vec<[f32; 3]> = query.iter().map(|p| [p[0] + 0.01, p[1], p[2]]).collect();
        let sets = [
            random_points(1000, 21, 1.0),
            near,
            random_points(1000, 22, 3.0),
        ];
        let indices: Vec<ChamferIndex> = sets.iter().map(|s| ChamferIndex::new(s)).collect();
        let all = chamfer_to_each(&query, &indices);
        for (s, d) in sets.iter().zip(&all) {
            assert_close(*d, brute_force(&query, s), 1e-9);
        }
        let (best, d) = nearest_by_chamfer(&query, &indices).unwrap();
        assert_eq!(best, 1);
        assert_eq!(d, all[1]);
        assert_eq!(nearest_by_chamfer(&query, &[]), None);
    }

    #[test]
    fn empty_sets_are_infinitely_far() {
        let a = random_points(10, 1, 1.0);
        assert_eq!(chamfer_distance(&a, &[]), f64::INFINITY);
        assert_eq!(chamfer_distance(&[], &a), f64::INFINITY);
        assert_eq!(
            ChamferIndex::new(&[]).nearest_squared(&[0.0; 3]),
            f64::INFINITY
        );
    }

    #[test]
    fn sampling_floor_on_a_sphere_is_small_and_positive() {
        let sphere = uv_sphere(1.0, [0.0; 3], 32, 64);
        let n = 5000;
        let floor = sampling_floor(&sphere, n, 1);
        assert!(floor > 0.0);
        // Two independent uniform samplings of area A with n points: each nearest-neighbour
        // squared distance is ≈ A/(π n) on average (2-D Poisson process), so CD ≈ 2A/(π n).
        let expected = 2.0 * sphere.area() / (std::f64::consts::PI * n as f64);
        assert!(
            floor > 0.5 * expected && floor < 1.5 * expected,
            "{floor} vs {expected}"
        );
        // A shifted sphere is much farther than the sampling floor.
        let mut moved = sphere.clone();
        moved.scale_and_translate(1.0, [0.2, 0.0, 0.0]);
        let a = crate::geometry::sampling::sample_surface(&sphere, n, 1);
        let b = crate::geometry::sampling::sample_surface(&moved, n, 2);
        assert!(chamfer_distance(&a.points, &b.points) > 10.0 * floor);
    }

    #[test]
    fn single_queries_and_duplicate_points_match_brute_force() {
        // Many exact duplicates and a flat cluster stress ties and zero-extent boxes.
        let mut a = random_points(700, 30, 1.0);
        a.extend(std::iter::repeat_n([0.25, 0.25, 0.25], 300));
        a.extend(
            random_points(300, 31, 1.0)
                .into_iter()
                .map(|p| [p[0], p[1], 0.0]),
        );
        let b = random_points(900, 32, 1.2);
        let index = ChamferIndex::new(&a);
        assert_eq!(index.len(), a.len());
        for q in b.iter().take(200) {
            assert_close(
                index.nearest_squared(q),
                directed_brute_force(&[*q], &a),
                1e-12,
            );
        }
        let mean = index.mean_squared_distance_from(&b);
        assert_close(mean, directed_brute_force(&b, &a), 1e-9);
        assert_close(chamfer_distance(&a, &b), brute_force(&a, &b), 1e-9);
    }
}
