//! The block layout of the fine grid and the cache of field values at grid samples.
//!
//! Block `b` at a level of span `s` cells covers cells `[b·s, b·s + s)` per axis (clipped to
//! the grid). Every value taken at a grid sample — a block centre on the culling levels, or a
//! cell corner of a kept finest block — goes into one cache keyed by the sample's grid index,
//! so each sample is evaluated at most once whoever needs it, and no R³ array exists (only
//! the 8³ bricks of samples that were needed).

use super::ExtractError;
use super::evaluate::Evaluator;
use crate::geometry::marching_cubes::Grid;
use rayon::prelude::*;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// Sizes of the block decomposition of an R³ grid.
pub(crate) struct Layout {
    /// Samples per axis.
    pub(crate) resolution: usize,
    /// Cells per axis (R − 1).
    pub(crate) cells: usize,
    /// Cells per finest block edge (B).
    pub(crate) block_cells: usize,
    /// Finest blocks per axis, ⌈(R − 1) / B⌉.
    pub(crate) blocks: usize,
    /// Sample coordinates along one axis.
    pub(crate) coords: Vec<f32>,
}

/// Where a block's culling test evaluates the field and how far its cells reach from there.
pub(crate) struct Probe {
    /// The point evaluated.
    pub(crate) point: [f32; 3],
    /// Largest distance from `point` to any point of the block's (clipped) cells.
    pub(crate) radius: f32,
    /// The point's grid index when it is a grid sample (then its value is cached).
    pub(crate) sample: Option<u64>,
}

impl Layout {
    pub(crate) fn new(grid: &Grid, block_cells: usize) -> Self {
        let cells = grid.resolution - 1;
        Self {
            resolution: grid.resolution,
            cells,
            block_cells,
            blocks: cells.div_ceil(block_cells),
            coords: grid.coordinates(),
        }
    }

    /// Linear grid index of sample `g` (x fastest).
    pub(crate) fn sample_index(&self, g: [usize; 3]) -> u64 {
        let r = self.resolution as u64;
        g[0] as u64 + r * (g[1] as u64 + r * g[2] as u64)
    }

    /// Position of the sample with linear index `n`.
    fn sample_point(&self, n: u64) -> [f32; 3] {
        let r = self.resolution as u64;
        [n % r, n / r % r, n / (r * r)].map(|i| self.coords[i as usize])
    }

    /// The culling probe of a block spanning `span` cells per axis. With an even span the
    /// probe is the grid sample at the block's centre (its value is then shared with the
    /// finer levels and the final sampling); otherwise the centre of the clipped box.
    pub(crate) fn probe(&self, block: [u32; 3], span: usize) -> Probe {
        let lo = block.map(|b| b as usize * span);
        let hi = lo.map(|l| (l + span).min(self.cells));
        let centre = lo.map(|l| l + span / 2);
        if span.is_multiple_of(2) && centre.iter().all(|&c| c <= self.cells) {
            let point = centre.map(|c| self.coords[c]);
            let radius = (0..3)
                .map(|k| {
                    let below = point[k] - self.coords[lo[k]];
                    let above = self.coords[hi[k]] - point[k];
                    below.max(above).powi(2)
                })
                .sum::<f32>()
                .sqrt();
            return Probe {
                point,
                radius,
                sample: Some(self.sample_index(centre)),
            };
        }
        let (lo, hi) = (lo.map(|i| self.coords[i]), hi.map(|i| self.coords[i]));
        Probe {
            point: std::array::from_fn(|k| 0.5 * (lo[k] + hi[k])),
            radius: 0.5 * (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f32>().sqrt(),
            sample: None,
        }
    }

    /// Grid indices of the (B+1)³ corner samples of a finest block (clipped to the grid).
    fn block_samples(&self, block: [u32; 3], out: &mut Vec<u64>) {
        let b = self.block_cells;
        let origin = block.map(|x| x as usize * b);
        let extent = origin.map(|o| b.min(self.cells - o));
        for lz in 0..=extent[2] {
            for ly in 0..=extent[1] {
                for lx in 0..=extent[0] {
                    out.push(self.sample_index([origin[0] + lx, origin[1] + ly, origin[2] + lz]));
                }
            }
        }
    }
}

/// A multiplicative hash for grid indices (the default SipHash costs more than the lookup).
#[derive(Default, Clone, Copy)]
pub(crate) struct IndexHasher(u64);

impl Hasher for IndexHasher {
    fn finish(&self) -> u64 {
        let x = self.0.wrapping_mul(0x9e37_79b9_7f4a_7c15);
        x ^ (x >> 31)
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = self.0.rotate_left(8) ^ u64::from(b);
        }
    }

    fn write_u64(&mut self, n: u64) {
        self.0 ^= n;
    }
}

/// Samples per brick edge (a power of two): the cache stores values in 8³ bricks so that
/// neighbouring samples share memory pages, not one hash entry each.
const BRICK_SHIFT: u32 = 3;
const BRICK: usize = 1 << BRICK_SHIFT;
const BRICK_VALUES: usize = BRICK * BRICK * BRICK;

/// Field values at grid samples, each evaluated once. Values live in dense 8³ bricks found
/// through a hash map by brick index (NaN marks a sample not evaluated yet; evaluated
/// values are finite).
pub(crate) struct SampleCache {
    resolution: u64,
    bricks: HashMap<u64, usize, BuildHasherDefault<IndexHasher>>,
    values: Vec<f32>,
}

/// Brick key and the offset inside the brick of grid index `n`.
fn brick_of(n: u64, r: u64) -> (u64, usize) {
    let g = [n % r, n / r % r, n / (r * r)];
    let b = g.map(|c| c >> BRICK_SHIFT);
    let mask = (BRICK - 1) as u64;
    let l = g.map(|c| (c & mask) as usize);
    (
        b[0] | b[1] << 21 | b[2] << 42,
        l[0] + BRICK * (l[1] + BRICK * l[2]),
    )
}

impl SampleCache {
    pub(crate) fn new(layout: &Layout) -> Self {
        Self {
            resolution: layout.resolution as u64,
            bricks: HashMap::default(),
            values: Vec::new(),
        }
    }

    /// The cached value at grid index `n`.
    pub(crate) fn get(&self, n: u64) -> Option<f32> {
        let (brick, at) = brick_of(n, self.resolution);
        let slot = *self.bricks.get(&brick)?;
        let v = self.values[slot * BRICK_VALUES + at];
        (!v.is_nan()).then_some(v)
    }

    /// Stores the value at grid index `n`.
    pub(crate) fn insert(&mut self, n: u64, value: f32) {
        let (brick, at) = brick_of(n, self.resolution);
        let next = self.bricks.len();
        let slot = *self.bricks.entry(brick).or_insert(next);
        if slot == next {
            self.values.resize((next + 1) * BRICK_VALUES, f32::NAN);
        }
        self.values[slot * BRICK_VALUES + at] = value;
    }

    /// Evaluates every corner sample of `blocks` that is not cached yet, each once. Returns
    /// the number of field evaluations made.
    pub(crate) fn fill_blocks(
        &mut self,
        layout: &Layout,
        blocks: &[[u32; 3]],
        evaluator: &mut Evaluator<'_>,
    ) -> Result<u64, ExtractError> {
        let mut wanted: Vec<u64> = blocks
            .par_chunks(1024)
            .flat_map_iter(|chunk| {
                let mut out = Vec::new();
                for &block in chunk {
                    layout.block_samples(block, &mut out);
                }
                out
            })
            .collect();
        wanted.par_sort_unstable();
        wanted.dedup();
        wanted.retain(|&n| self.get(n).is_none());
        let chunk = evaluator_chunk(evaluator);
        for part in wanted.chunks(chunk) {
            let points: Vec<[f32; 3]> = part.iter().map(|&n| layout.sample_point(n)).collect();
            let values = evaluator.values(&points)?;
            for (&n, v) in part.iter().zip(values) {
                self.insert(n, v);
            }
        }
        Ok(wanted.len() as u64)
    }

    /// The (B+1)³ corner samples of a kept finest block, x fastest (entries past a clipped
    /// block's last cell are NaN and never read).
    pub(crate) fn gather(&self, layout: &Layout, block: [u32; 3]) -> Vec<f32> {
        let b = layout.block_cells;
        let side = b + 1;
        let origin = block.map(|x| x as usize * b);
        let extent = origin.map(|o| b.min(layout.cells - o));
        let mut out = vec![f32::NAN; side * side * side];
        let mut last: Option<(u64, usize)> = None;
        for lz in 0..=extent[2] {
            for ly in 0..=extent[1] {
                for lx in 0..=extent[0] {
                    let n = layout.sample_index([origin[0] + lx, origin[1] + ly, origin[2] + lz]);
                    let (brick, at) = brick_of(n, self.resolution);
                    let slot = match last {
                        Some((key, slot)) if key == brick => slot,
                        _ => {
                            let slot = *self
                                .bricks
                                .get(&brick)
                                .expect("corner samples of kept blocks were evaluated");
                            last = Some((brick, slot));
                            slot
                        }
                    };
                    let v = self.values[slot * BRICK_VALUES + at];
                    debug_assert!(!v.is_nan(), "corner samples of kept blocks were evaluated");
                    out[lx + side * (ly + side * lz)] = v;
                }
            }
        }
        out
    }
}

/// Points per evaluation call: enough for several full batches.
fn evaluator_chunk(evaluator: &Evaluator<'_>) -> usize {
    evaluator.batch_size() * rayon::current_num_threads().max(2) * 2
}
