//! Dense marching cubes over a full sample grid, parallel over slabs of z-layers.
//!
//! Each slab walks its cell layers with two rolling edge→vertex maps (the sample layers below
//! and above the current cell layer) plus one for the vertical edges, so a crossing becomes
//! exactly one vertex without any welding. The x/y edges on a slab's bottom plane belong to
//! the slab below; they are recorded as borrowed references and resolved in the stitch step
//! once every slab's vertex count (and hence its global offset) is known.

use super::cell::{
    case_of, centre_polygon, crossing_fraction, decisions, edge_position, slot_corners, slot_edge,
    triangles,
};
use super::grid::Grid;
use super::tables::CENTRE_SLOT;
use crate::geometry::mesh::TriMesh;
use rayon::prelude::*;

/// Marks a triangle index that refers to the slab below's top-plane vertex map.
const BORROWED: u32 = 1 << 31;
const NONE: u32 = u32::MAX;

/// One slab's share of the mesh, with vertex indices local to the slab.
struct Slab {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    /// Vertex of every x/y edge on the slab's top sample plane (`NONE` if no crossing).
    top: Vec<u32>,
}

/// Edge → vertex map for one plane of edges that can be cleared in time proportional to use.
struct EdgeMap {
    slots: Vec<u32>,
    touched: Vec<u32>,
}

impl EdgeMap {
    fn new(len: usize) -> Self {
        Self {
            slots: vec![NONE; len],
            touched: Vec::new(),
        }
    }
    fn clear(&mut self) {
        for &i in &self.touched {
            self.slots[i as usize] = NONE;
        }
        self.touched.clear();
    }
}

/// Everything a slab reads.
struct Dense<'a> {
    r: usize,
    values: &'a [f32],
    coords: Vec<f32>,
    iso: f32,
}

/// Runs marching cubes on a validated grid.
pub(crate) fn polygonise(grid: &Grid, values: &[f32], iso: f32) -> TriMesh {
    let r = grid.resolution;
    let ctx = Dense {
        r,
        values,
        coords: grid.coordinates(),
        iso,
    };
    let layers = r - 1;
    let thickness = layers
        .div_ceil(4 * rayon::current_num_threads())
        .max(4)
        .min(layers);
    let starts: Vec<usize> = (0..layers).step_by(thickness).collect();
    let slabs: Vec<Slab> = starts
        .par_iter()
        .map(|&k0| ctx.slab(k0, (k0 + thickness).min(layers)))
        .collect();
    stitch(slabs)
}

/// Concatenates the slabs, turning local and borrowed indices into global ones.
fn stitch(slabs: Vec<Slab>) -> TriMesh {
    let mut offsets = Vec::with_capacity(slabs.len());
    let mut total = 0u32;
    for s in &slabs {
        offsets.push(total);
        total += s.positions.len() as u32;
    }
    let triangles: Vec<Vec<[u32; 3]>> = slabs
        .par_iter()
        .enumerate()
        .map(|(n, s)| {
            let resolve = |v: u32| {
                if v & BORROWED != 0 {
                    slabs[n - 1].top[(v & !BORROWED) as usize] + offsets[n - 1]
                } else {
                    v + offsets[n]
                }
            };
            s.triangles.iter().map(|t| t.map(resolve)).collect()
        })
        .collect();
    let mut mesh = TriMesh::new(
        slabs
            .iter()
            .flat_map(|s| s.positions.iter().copied())
            .collect(),
        triangles.concat(),
    );
    let mut normals: Vec<[f32; 3]> = slabs.into_iter().flat_map(|s| s.normals).collect();
    // A vanishing gradient (flat spot of the field) gets the surface's own normal instead.
    if normals.contains(&[0.0; 3]) {
        let from_faces = mesh.compute_vertex_normals();
        for (n, f) in normals.iter_mut().zip(from_faces) {
            if *n == [0.0; 3] {
                *n = f;
            }
        }
    }
    mesh.normals = Some(normals);
    mesh
}

impl Dense<'_> {
    fn at(&self, i: usize, j: usize, k: usize) -> f32 {
        self.values[i + self.r * (j + self.r * k)]
    }

    /// 4-bit inside codes of the squares of sample plane `k` (bit dx | dy << 1); `bits` is
    /// scratch space for one plane. Written as straight slice loops so they vectorise.
    fn plane_codes(&self, k: usize, bits: &mut [u8], out: &mut [u8]) {
        let r = self.r;
        let plane = &self.values[r * r * k..r * r * (k + 1)];
        for (b, v) in bits.iter_mut().zip(plane) {
            *b = u8::from(*v < self.iso);
        }
        for (j, out) in out.chunks_exact_mut(r - 1).enumerate() {
            let (row0, row1) = (&bits[j * r..(j + 1) * r], &bits[(j + 1) * r..(j + 2) * r]);
            let (a0, a1, b0, b1) = (&row0[..r - 1], &row0[1..], &row1[..r - 1], &row1[1..]);
            for i in 0..r - 1 {
                out[i] = a0[i] | a1[i] << 1 | b0[i] << 2 | b1[i] << 3;
            }
        }
    }

    /// Calls `f(i, case)` for every cell of a row whose case is not empty or full, skipping
    /// eight uniform cells at a time.
    fn scan_row(lo: &[u8], hi: &[u8], mut f: impl FnMut(usize, u8)) {
        const FULL: u64 = 0x0f0f_0f0f_0f0f_0f0f;
        let mut i = 0;
        for (l8, h8) in lo.chunks_exact(8).zip(hi.chunks_exact(8)) {
            let l = u64::from_le_bytes(l8.try_into().expect("8 bytes"));
            let h = u64::from_le_bytes(h8.try_into().expect("8 bytes"));
            if !((l | h) == 0 || (l == FULL && h == FULL)) {
                for n in 0..8 {
                    let case = l8[n] | h8[n] << 4;
                    if case != 0 && case != 0xff {
                        f(i + n, case);
                    }
                }
            }
            i += 8;
        }
        for n in i..lo.len() {
            let case = lo[n] | hi[n] << 4;
            if case != 0 && case != 0xff {
                f(n, case);
            }
        }
    }

    fn slab(&self, k0: usize, k1: usize) -> Slab {
        let r = self.r;
        let mut out = Slab {
            positions: Vec::new(),
            normals: Vec::new(),
            triangles: Vec::new(),
            top: Vec::new(),
        };
        let mut maps = [
            EdgeMap::new(2 * r * r),
            EdgeMap::new(2 * r * r),
            EdgeMap::new(r * r),
        ];
        let mut bits = vec![0u8; r * r];
        let mut lo = vec![0u8; (r - 1) * (r - 1)];
        let mut hi = lo.clone();
        self.plane_codes(k0, &mut bits, &mut lo);
        for k in k0..k1 {
            self.plane_codes(k + 1, &mut bits, &mut hi);
            for (j, (lo, hi)) in lo
                .chunks_exact(r - 1)
                .zip(hi.chunks_exact(r - 1))
                .enumerate()
            {
                Self::scan_row(lo, hi, |i, case| {
                    self.cell([i, j, k], case, k == k0 && k0 > 0, &mut maps, &mut out)
                });
            }
            std::mem::swap(&mut lo, &mut hi);
            let [below, above, vertical] = &mut maps;
            std::mem::swap(below, above);
            above.clear();
            vertical.clear();
        }
        let [below, _, _] = maps;
        out.top = below.slots;
        out
    }

    fn cell(
        &self,
        cell: [usize; 3],
        case: u8,
        borrow: bool,
        maps: &mut [EdgeMap; 3],
        out: &mut Slab,
    ) {
        let [i, j, k] = cell;
        let values: [f32; 8] =
            std::array::from_fn(|c| self.at(i + (c & 1), j + (c >> 1 & 1), k + (c >> 2)));
        debug_assert_eq!(case, case_of(&values, self.iso));
        let dec = decisions(&values, case, self.iso);
        let mut centre = NONE;
        for tri in triangles(case, dec) {
            let t = tri.map(|slot| {
                if slot == CENTRE_SLOT {
                    if centre == NONE {
                        centre = self.centre(cell, &values, centre_polygon(case, dec), out);
                    }
                    return centre;
                }
                let (offset, axis) = slot_edge(slot);
                let lower = [i + offset[0], j + offset[1], k + offset[2]];
                let (map, at) = match axis {
                    2 => (2, lower[0] + self.r * lower[1]),
                    _ => (
                        offset[2],
                        lower[0] + self.r * lower[1] + axis * self.r * self.r,
                    ),
                };
                if map == 0 && borrow {
                    return BORROWED | at as u32;
                }
                let found = maps[map].slots[at];
                if found != NONE {
                    return found;
                }
                let (a, b) = slot_corners(slot);
                let v = self.push_edge_vertex(lower, axis, values[a], values[b], out);
                maps[map].slots[at] = v;
                maps[map].touched.push(at as u32);
                v
            });
            out.triangles.push(t);
        }
    }

    /// Central-difference gradient of the grid at a sample (one-sided on the border).
    fn gradient(&self, p: [usize; 3]) -> [f32; 3] {
        std::array::from_fn(|axis| {
            let step = |d: isize| {
                let mut q = p;
                q[axis] = (q[axis] as isize + d) as usize;
                self.at(q[0], q[1], q[2])
            };
            match p[axis] {
                0 => step(1) - step(0),
                x if x == self.r - 1 => step(0) - step(-1),
                _ => 0.5 * (step(1) - step(-1)),
            }
        })
    }

    fn edge_normal(&self, lower: [usize; 3], axis: usize, v0: f32, v1: f32) -> [f32; 3] {
        let t = crossing_fraction(v0, v1, self.iso);
        let mut upper = lower;
        upper[axis] += 1;
        let (g0, g1) = (self.gradient(lower), self.gradient(upper));
        unit(std::array::from_fn(|c| g0[c] + t * (g1[c] - g0[c])))
    }

    fn push_edge_vertex(
        &self,
        lower: [usize; 3],
        axis: usize,
        v0: f32,
        v1: f32,
        out: &mut Slab,
    ) -> u32 {
        out.positions
            .push(edge_position(&self.coords, lower, axis, v0, v1, self.iso));
        out.normals.push(self.edge_normal(lower, axis, v0, v1));
        (out.positions.len() - 1) as u32
    }

    fn centre(&self, cell: [usize; 3], values: &[f32; 8], polygon: &[u8], out: &mut Slab) -> u32 {
        let mut n = [0.0f32; 3];
        for &slot in polygon {
            let (offset, axis) = slot_edge(slot);
            let (a, b) = slot_corners(slot);
            let lower = std::array::from_fn(|c| cell[c] + offset[c]);
            let e = self.edge_normal(lower, axis, values[a], values[b]);
            n = std::array::from_fn(|c| n[c] + e[c]);
        }
        let p = super::cell::centre_position(&self.coords, cell, values, self.iso, polygon);
        out.positions.push(p);
        out.normals.push(unit(n));
        (out.positions.len() - 1) as u32
    }
}

/// `v / |v|`, or zero for a zero vector.
pub(crate) fn unit(v: [f32; 3]) -> [f32; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if n > 0.0 && n.is_finite() {
        v.map(|c| c / n)
    } else {
        [0.0; 3]
    }
}
