//! Area-weighted random sampling of a triangle surface, with unit normals: the training
//! data of the signed-distance model and the point sets of the Chamfer distance.
//!
//! Determinism: the samples are split into fixed chunks of [`SAMPLING_CHUNK`] points; chunk
//! `c` draws from ChaCha8 seeded with `seed` on stream `c`. ChaCha8 is a portable,
//! value-stable generator and the draws are turned into floats by integer arithmetic, so a
//! seed gives the same samples on every platform and for every thread count.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::mesh::{MeshError, TriMesh, cross, normalized, sub};

/// Points sampled on a surface with their unit normals (same length, same order).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SurfaceSamples {
    /// Sample positions.
    pub points: Vec<[f32; 3]>,
    /// Unit normal at each sample.
    pub normals: Vec<[f32; 3]>,
}

/// Where a sample's normal comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NormalSource {
    /// The flat normal of the sampled triangle.
    #[default]
    Face,
    /// The mesh's vertex normals interpolated with the sample's barycentric weights
    /// (smoother for meshes extracted from a field); requires `mesh.normals`.
    Vertex,
}

/// Why a mesh cannot be sampled.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SamplingError {
    /// The mesh itself is unusable.
    #[error("cannot sample the mesh: {0}")]
    Mesh(#[from] MeshError),
    /// Interpolated normals were asked for, but the mesh has none.
    #[error("vertex normals were requested, but the mesh has no per-vertex normals")]
    NoVertexNormals,
}

/// A sample expressed on the mesh: which triangle, and the barycentric weights of its
/// second and third corners (the first is `1 − w1 − w2`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceLocation {
    /// Index of the sampled triangle.
    pub triangle: u32,
    /// Weights of corners 1 and 2.
    pub weights: [f64; 2],
}

/// Samples per independently seeded stream; fixed so results do not depend on threads.
pub const SAMPLING_CHUNK: usize = 8192;

/// `n` area-weighted samples with unit face normals, deterministic for `seed`.
///
/// A mesh that cannot be sampled (empty, invalid indices or coordinates, zero area) gives
/// no samples; [`try_sample_surface`] says why.
pub fn sample_surface(mesh: &TriMesh, n: usize, seed: u64) -> SurfaceSamples {
    try_sample_surface(mesh, n, seed, NormalSource::Face).unwrap_or_default()
}

/// `n` area-weighted samples with unit normals from `normals`, deterministic for `seed`.
pub fn try_sample_surface(
    mesh: &TriMesh,
    n: usize,
    seed: u64,
    normals: NormalSource,
) -> Result<SurfaceSamples, SamplingError> {
    let table = AreaTable::new(mesh)?;
    let vertex_normals = match normals {
        NormalSource::Face => None,
        NormalSource::Vertex => Some(
            mesh.normals
                .as_deref()
                .ok_or(SamplingError::NoVertexNormals)?,
        ),
    };
    let mut out = SurfaceSamples {
        points: vec![[0.0; 3]; n],
        normals: vec![[0.0; 3]; n],
    };
    out.points
        .par_chunks_mut(SAMPLING_CHUNK)
        .zip(out.normals.par_chunks_mut(SAMPLING_CHUNK))
        .enumerate()
        .for_each(|(chunk, (points, normals))| {
            let mut rng = chunk_rng(seed, chunk);
            for (p, nrm) in points.iter_mut().zip(normals) {
                let loc = table.draw(&mut rng);
                let (point, normal) = evaluate(mesh, vertex_normals, loc);
                *p = point;
                *nrm = normal;
            }
        });
    Ok(out)
}

/// `n` area-weighted sample locations (triangle + barycentric weights), drawn from the
/// same streams as [`try_sample_surface`], so they describe exactly its samples.
pub fn sample_locations(
    mesh: &TriMesh,
    n: usize,
    seed: u64,
) -> Result<Vec<SurfaceLocation>, SamplingError> {
    let table = AreaTable::new(mesh)?;
    let mut out = vec![
        SurfaceLocation {
            triangle: 0,
            weights: [0.0; 2]
        };
        n
    ];
    out.par_chunks_mut(SAMPLING_CHUNK)
        .enumerate()
        .for_each(|(chunk, locs)| {
            let mut rng = chunk_rng(seed, chunk);
            for loc in locs {
                *loc = table.draw(&mut rng);
            }
        });
    Ok(out)
}

fn chunk_rng(seed: u64, chunk: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(chunk as u64);
    rng
}

/// A uniform f64 in [0, 1) from the top 53 bits of one draw (exact, platform-independent).
fn unit_f64(rng: &mut ChaCha8Rng) -> f64 {
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Cumulative triangle areas, searched to pick a triangle with probability ∝ its area.
struct AreaTable {
    cumulative: Vec<f64>,
    total: f64,
}

impl AreaTable {
    fn new(mesh: &TriMesh) -> Result<Self, MeshError> {
        mesh.validate()?;
        let areas: Vec<f64> = (0..mesh.triangles.len())
            .into_par_iter()
            .map(|t| mesh.triangle_area(t))
            .collect();
        let mut cumulative = areas;
        let mut total = 0.0;
        for a in &mut cumulative {
            total += *a;
            *a = total;
        }
        Ok(Self { cumulative, total })
    }

    fn draw(&self, rng: &mut ChaCha8Rng) -> SurfaceLocation {
        let target = unit_f64(rng) * self.total;
        // The first triangle whose running total exceeds the target; zero-area triangles
        // share their predecessor's total and are therefore never chosen.
        let t = self
            .cumulative
            .partition_point(|&c| c <= target)
            .min(self.cumulative.len() - 1);
        // Uniform in the triangle: √r1 spreads the mass linearly towards the far edge.
        let s = unit_f64(rng).sqrt();
        let r2 = unit_f64(rng);
        SurfaceLocation {
            triangle: t as u32,
            weights: [s * (1.0 - r2), s * r2],
        }
    }
}

fn evaluate(
    mesh: &TriMesh,
    vertex_normals: Option<&[[f32; 3]]>,
    loc: SurfaceLocation,
) -> ([f32; 3], [f32; 3]) {
    let t = loc.triangle as usize;
    let [a, b, c] = mesh.corners(t);
    let [w1, w2] = loc.weights;
    let w0 = 1.0 - w1 - w2;
    let point = std::array::from_fn(|k| (w0 * a[k] + w1 * b[k] + w2 * c[k]) as f32);
    let face = || normalized(cross(sub(b, a), sub(c, a)));
    let normal = match vertex_normals {
        None => face(),
        Some(vn) => {
            let [n0, n1, n2] = mesh.triangles[t].map(|i| vn[i as usize].map(f64::from));
            let n = normalized(std::array::from_fn(|k| {
                w0 * n0[k] + w1 * n1[k] + w2 * n2[k]
            }));
            if n == [0.0; 3] { face() } else { n }
        }
    };
    (point, normal.map(|x| x as f32))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::mesh::{dot, norm};
    use crate::geometry::test_shapes::uv_sphere;

    /// Four disjoint triangles whose areas are 1, 10, 100 and 1000 (× 0.5).
    fn unequal_triangles() -> TriMesh {
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        for (k, side) in [1.0f32, 10f32.sqrt(), 10.0, 1000f32.sqrt()]
            .into_iter()
            .enumerate()
        {
            let z = k as f32;
            let base = positions.len() as u32;
            positions.extend([[0.0, 0.0, z], [side, 0.0, z], [0.0, side, z]]);
            triangles.push([base, base + 1, base + 2]);
        }
        TriMesh::new(positions, triangles)
    }

    #[test]
    fn the_same_seed_gives_identical_samples_and_another_seed_does_not() {
        let m = uv_sphere(1.0, [0.0; 3], 10, 16);
        let a = sample_surface(&m, 20_000, 7);
        let b = sample_surface(&m, 20_000, 7);
        let c = sample_surface(&m, 20_000, 8);
        assert_eq!(a, b);
        assert_eq!(a.points.len(), 20_000);
        let same = a
            .points
            .iter()
            .zip(&c.points)
            .filter(|(p, q)| p == q)
            .count();
        assert_eq!(same, 0);
    }

    #[test]
    fn samples_do_not_depend_on_the_thread_count() {
        let m = uv_sphere(1.0, [0.0; 3], 10, 16);
        let parallel = sample_surface(&m, 3 * SAMPLING_CHUNK + 17, 3);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let serial = pool.install(|| sample_surface(&m, 3 * SAMPLING_CHUNK + 17, 3));
        assert_eq!(parallel, serial);
        // A prefix of a longer run is the shorter run: chunks are independent streams.
        let shorter = sample_surface(&m, SAMPLING_CHUNK + 5, 3);
        assert_eq!(shorter.points[..], parallel.points[..SAMPLING_CHUNK + 5]);
    }

    #[test]
    fn sphere_samples_lie_on_their_triangles_with_unit_outward_normals() {
        let centre = [0.5f32, -1.0, 2.0];
        let m = uv_sphere(3.0, centre, 12, 24);
        let n = 20_000;
        let s = sample_surface(&m, n, 11);
        let locs = sample_locations(&m, n, 11).unwrap();
        for ((p, nrm), loc) in s.points.iter().zip(&s.normals).zip(&locs) {
            let t = loc.triangle as usize;
            let [a, b, c] = m.corners(t);
            let p = p.map(f64::from);
            // Barycentric coordinates of p recovered by projection onto the triangle's plane.
            let (e1, e2, d) = (sub(b, a), sub(c, a), sub(p, a));
            let face = m.face_normal(t);
            assert!(
                dot(d, face).abs() < 1e-5,
                "off the plane by {}",
                dot(d, face)
            );
            let (d11, d12, d22) = (dot(e1, e1), dot(e1, e2), dot(e2, e2));
            let det = d11 * d22 - d12 * d12;
            let w1 = (d22 * dot(d, e1) - d12 * dot(d, e2)) / det;
            let w2 = (d11 * dot(d, e2) - d12 * dot(d, e1)) / det;
            let eps = 1e-4;
            assert!(
                w1 > -eps && w2 > -eps && w1 + w2 < 1.0 + eps,
                "outside: {w1} {w2}"
            );
            let nrm = nrm.map(f64::from);
            assert!((norm(nrm) - 1.0).abs() < 1e-6);
            let radial = sub(p, centre.map(f64::from));
            assert!(dot(nrm, radial) > 0.95 * norm(radial), "normal not outward");
        }
    }

    #[test]
    fn each_triangle_gets_its_share_of_the_area() {
        let m = unequal_triangles();
        let n = 400_000;
        let locs = sample_locations(&m, n, 5).unwrap();
        let mut counts = [0usize; 4];
        for l in &locs {
            counts[l.triangle as usize] += 1;
        }
        let total = m.area();
        let chi2: f64 = (0..4)
            .map(|t| {
                let expected = n as f64 * m.triangle_area(t) / total;
                (counts[t] as f64 - expected).powi(2) / expected
            })
            .sum();
        // 3 degrees of freedom: P(χ² > 25) ≈ 1.6e-5.
        assert!(chi2 < 25.0, "chi-square {chi2}, counts {counts:?}");
        assert!(counts[0] > 0, "the smallest triangle is never drawn");
    }

    #[test]
    fn samples_are_uniform_inside_a_triangle() {
        let m = TriMesh::new(
            vec![[0.0; 3], [4.0, 0.0, 0.0], [1.0, 3.0, 0.0]],
            vec![[0, 1, 2]],
        );
        let n = 200_000;
        let locs = sample_locations(&m, n, 9).unwrap();
        let (mut mean, mut second) = ([0.0; 3], [0.0; 3]);
        for l in &locs {
            let [w1, w2] = l.weights;
            for (k, w) in [1.0 - w1 - w2, w1, w2].into_iter().enumerate() {
                assert!((-1e-12..=1.0 + 1e-12).contains(&w));
                mean[k] += w / n as f64;
                second[k] += w * w / n as f64;
            }
        }
        // Uniform on a triangle ⇔ barycentrics ~ Dirichlet(1,1,1): E[w] = 1/3, E[w²] = 1/6.
        for k in 0..3 {
            assert!((mean[k] - 1.0 / 3.0).abs() < 0.004, "mean {mean:?}");
            assert!(
                (second[k] - 1.0 / 6.0).abs() < 0.004,
                "second moment {second:?}"
            );
        }
    }

    #[test]
    fn interpolated_vertex_normals_follow_the_sphere_more_closely_than_face_normals() {
        let m = uv_sphere(1.0, [0.0; 3], 8, 12);
        let err = |source| {
            let s = try_sample_surface(&m, 5000, 2, source).unwrap();
            s.points
                .iter()
                .zip(&s.normals)
                .map(|(p, n)| {
                    let exact = normalized(p.map(f64::from));
                    1.0 - dot(exact, n.map(f64::from))
                })
                .sum::<f64>()
        };
        let (face, vertex) = (err(NormalSource::Face), err(NormalSource::Vertex));
        assert!(vertex < 0.5 * face, "vertex {vertex} vs face {face}");
    }

    #[test]
    fn unusable_meshes_are_reported() {
        let mut m = uv_sphere(1.0, [0.0; 3], 6, 8);
        m.normals = None;
        assert_eq!(
            try_sample_surface(&m, 10, 0, NormalSource::Vertex),
            Err(SamplingError::NoVertexNormals)
        );
        m.triangles[3][1] = 1000;
        assert!(matches!(
            try_sample_surface(&m, 10, 0, NormalSource::Face),
            Err(SamplingError::Mesh(MeshError::IndexOutOfRange {
                triangle: 3,
                ..
            }))
        ));
        assert!(sample_surface(&m, 10, 0).points.is_empty());
        let flat = TriMesh::new(vec![[0.0; 3]; 3], vec![[0, 1, 2]]);
        assert!(matches!(
            sample_locations(&flat, 10, 0),
            Err(SamplingError::Mesh(MeshError::AllDegenerate(1)))
        ));
    }
}
