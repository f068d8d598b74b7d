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
#[path = "sampling_tests.rs"]
mod tests;
