//! Analytic vessel surfaces with known centrelines and radii for the simulation tests: a
//! straight tube with flat ends, and marching-cubes surfaces of signed-distance fields (a
//! tube with rounded ends, a branched arch) that look like the model's reconstructions.

use crate::geometry::TriMesh;
use crate::geometry::marching_cubes::{Grid, marching_cubes};
use crate::geometry::mesh::{dot, norm, sub};

/// A closed cylinder of radius `r` from `start` along the unit `axis` for `length`, flat
/// ends (centre fans), triangles outward.
pub(crate) fn straight_tube(
    r: f64,
    length: f64,
    start: [f64; 3],
    axis: [f64; 3],
    rings: usize,
    segments: usize,
) -> TriMesh {
    let frame = crate::anatomy::sections::PlaneFrame::new(start, axis);
    let mut positions = Vec::new();
    for i in 0..=rings {
        let z = length * i as f64 / rings as f64;
        for j in 0..segments {
            let a = std::f64::consts::TAU * j as f64 / segments as f64;
            let p: [f64; 3] = std::array::from_fn(|k| {
                start[k] + z * frame.normal[k] + r * (a.cos() * frame.u[k] + a.sin() * frame.v[k])
            });
            positions.push(p.map(|c| c as f32));
        }
    }
    let idx = |i: usize, j: usize| (i * segments + j % segments) as u32;
    let mut triangles = Vec::new();
    for i in 0..rings {
        for j in 0..segments {
            triangles.push([idx(i, j), idx(i, j + 1), idx(i + 1, j + 1)]);
            triangles.push([idx(i, j), idx(i + 1, j + 1), idx(i + 1, j)]);
        }
    }
    for (ring, outward) in [(0, false), (rings, true)] {
        let c = positions.len() as u32;
        let z = length * ring as f64 / rings as f64;
        positions.push(std::array::from_fn(|k| (start[k] + z * axis[k]) as f32));
        for j in 0..segments {
            let (a, b) = (idx(ring, j), idx(ring, j + 1));
            triangles.push(if outward { [c, a, b] } else { [c, b, a] });
        }
    }
    TriMesh::new(positions, triangles)
}

/// Distance from `p` to the segment `a`–`b`.
pub(crate) fn segment_distance(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let ab = sub(b, a);
    let t = (dot(sub(p, a), ab) / dot(ab, ab)).clamp(0.0, 1.0);
    norm(sub(p, std::array::from_fn(|i| a[i] + t * ab[i])))
}

/// Marching cubes of `sdf` over the cube [−half, half]³ with `resolution` samples per axis,
/// shifted by a fraction of a cell so no sample lands exactly on the surface (which would
/// give coincident vertices).
pub(crate) fn mesh_of(
    sdf: impl Fn([f64; 3]) -> f64 + Sync,
    half: f32,
    resolution: usize,
) -> TriMesh {
    use rayon::prelude::*;
    let shift = 0.37 * 2.0 * half / (resolution - 1) as f32;
    let grid = Grid {
        resolution,
        min: -half - shift,
        max: half - shift,
    };
    let points: Vec<[f32; 3]> = grid.points().collect();
    let values: Vec<f32> = points
        .par_iter()
        .map(|p| sdf(p.map(f64::from)) as f32)
        .collect();
    let mut mesh = marching_cubes(&grid, &values, 0.0);
    mesh.normals = Some(mesh.compute_vertex_normals());
    mesh
}

/// A branched arch in mm: an ascending leg (x = −30, z from −20 up to 0, radius 9), a
/// half-torus arch of centreline radius 30 over +z, a descending leg (x = +30, z from 0 down
/// to −50) and three straight branches of radius 4 leaving the arch upward at 115°, 90° and
/// 65° (proximal to distal), reaching 25 mm above the arch centreline. Rounded (capsule)
/// ends, smooth unions.
pub(crate) struct BranchedArch;

impl BranchedArch {
    /// Main-vessel radius.
    pub(crate) const RADIUS: f64 = 9.0;
    /// Branch radius.
    pub(crate) const BRANCH_RADIUS: f64 = 4.0;
    /// Arch centreline radius.
    pub(crate) const ARCH: f64 = 30.0;
    /// Descending leg of [`BranchedArch::mesh`], mm.
    pub(crate) const DESCENDING: f64 = 50.0;

    /// Where branch `k` leaves the arch centreline and its unit direction (upward, radial
    /// from the arch centre).
    pub(crate) fn branch(k: usize) -> ([f64; 3], [f64; 3]) {
        let angle = [115.0f64, 90.0, 65.0][k].to_radians();
        let dir = [angle.cos(), 0.0, angle.sin()];
        (dir.map(|c| c * Self::ARCH), dir)
    }

    /// Distance from `p` to the main vessel's centreline, with a descending leg of
    /// `descending` mm.
    pub(crate) fn main_axis_distance(p: [f64; 3], descending: f64) -> f64 {
        let (x, z) = (p[0], p[2]);
        let arch = if z >= 0.0 {
            let rho = x.hypot(z);
            (rho - Self::ARCH).hypot(p[1])
        } else {
            f64::INFINITY
        };
        let up = segment_distance(p, [-Self::ARCH, 0.0, -20.0], [-Self::ARCH, 0.0, 0.0]);
        let down = segment_distance(p, [Self::ARCH, 0.0, 0.0], [Self::ARCH, 0.0, -descending]);
        arch.min(up).min(down)
    }

    /// The signed distance (approximately Euclidean; negative inside).
    pub(crate) fn sdf(p: [f64; 3]) -> f64 {
        Self::sdf_with(p, Self::DESCENDING, 25.0)
    }

    /// The signed distance of the arch with a descending leg of `descending` mm and
    /// branches reaching `branch` mm above the arch centreline.
    pub(crate) fn sdf_with(p: [f64; 3], descending: f64, branch: f64) -> f64 {
        let mut d = Self::main_axis_distance(p, descending) - Self::RADIUS;
        for k in 0..3 {
            let (base, dir) = Self::branch(k);
            let tip = std::array::from_fn(|i| base[i] + branch * dir[i]);
            let b = segment_distance(p, base, tip) - Self::BRANCH_RADIUS;
            d = smooth_min(d, b, 3.0);
        }
        d
    }

    /// The surface at 1 mm spacing.
    pub(crate) fn mesh() -> TriMesh {
        mesh_of(Self::sdf, 64.0, 129)
    }

    /// The arch with 90 mm branches, at 1 mm spacing: the geodesically farthest points
    /// are a branch tip and a main end, as on thoracic aortas cut short below the arch.
    pub(crate) fn long_branches_mesh() -> TriMesh {
        mesh_of(
            |p| Self::sdf_with(p, Self::LONG_BRANCHES_DESCENDING, 90.0),
            115.0,
            231,
        )
    }

    /// Descending leg of [`BranchedArch::long_branches_mesh`], mm.
    pub(crate) const LONG_BRANCHES_DESCENDING: f64 = 50.0;
}

/// Polynomial smooth minimum with blending width `k`.
fn smooth_min(a: f64, b: f64, k: f64) -> f64 {
    let h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0);
    b + (a - b) * h - k * h * (1.0 - h)
}
