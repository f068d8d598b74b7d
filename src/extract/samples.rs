//! The block layout of the fine grid and the store of grid samples taken in kept blocks.
//!
//! Block `b` covers cells `[b·B, b·B + B)` per axis (clipped to the grid) and *owns* the
//! samples `[b·B, b·B + B)`; the corners on its upper faces are owned by its upper
//! neighbours. Each needed sample is evaluated once, in its owner's B³ array, so neighbouring
//! blocks share their face samples without a per-sample hash map and without any R³ array.

use super::ExtractError;
use super::evaluate::Evaluator;
use crate::geometry::marching_cubes::Grid;
use std::collections::HashMap;

/// Sizes of the block decomposition of an R³ grid.
pub(crate) struct Layout {
    /// Samples per axis.
    pub(crate) resolution: usize,
    /// Cells per axis (R − 1).
    pub(crate) cells: usize,
    /// Cells per block edge (B).
    pub(crate) block_cells: usize,
    /// Blocks per axis, ⌈(R − 1) / B⌉.
    pub(crate) blocks: usize,
    /// Sample coordinates along one axis.
    pub(crate) coords: Vec<f32>,
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

    /// Centre and half-diagonal of a block spanning `span` cells per axis (clipped to the grid).
    pub(crate) fn centre_and_radius(&self, block: [u32; 3], span: usize) -> ([f32; 3], f32) {
        let lo = block.map(|b| self.coords[b as usize * span]);
        let hi = block.map(|b| self.coords[(b as usize * span + span).min(self.cells)]);
        let centre = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
        let radius = 0.5 * (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f32>().sqrt();
        (centre, radius)
    }
}

fn key(block: [u32; 3]) -> u64 {
    u64::from(block[0]) | u64::from(block[1]) << 21 | u64::from(block[2]) << 42
}

/// Field values at the samples of kept blocks, grouped by owner block.
pub(crate) struct SampleStore {
    slot_of: HashMap<u64, usize>,
    values: Vec<f32>,
    /// Samples evaluated.
    pub(crate) evaluated: u64,
}

impl SampleStore {
    /// Evaluates every sample that is a corner of a cell in `blocks`, each exactly once.
    pub(crate) fn evaluate(
        layout: &Layout,
        blocks: &[[u32; 3]],
        evaluator: &mut Evaluator<'_>,
    ) -> Result<Self, ExtractError> {
        let b = layout.block_cells;
        // Owner block → which kept blocks (offset d ∈ {0,1}³ below it) need its samples.
        let mut needers: HashMap<u64, ([u32; 3], u8)> = HashMap::with_capacity(blocks.len() * 2);
        for block in blocks {
            for d in 0..8u32 {
                let owner = [
                    block[0] + (d & 1),
                    block[1] + (d >> 1 & 1),
                    block[2] + (d >> 2),
                ];
                if owner.iter().all(|&o| (o as usize) * b < layout.resolution) {
                    needers.entry(key(owner)).or_insert((owner, 0)).1 |= 1 << d;
                }
            }
        }
        let mut owners: Vec<([u32; 3], u8)> = needers.into_values().collect();
        owners.sort_unstable_by_key(|o| key(o.0));
        let cube = b * b * b;
        let mut store = Self {
            slot_of: owners
                .iter()
                .enumerate()
                .map(|(n, o)| (key(o.0), n))
                .collect(),
            values: vec![f32::NAN; owners.len() * cube],
            evaluated: 0,
        };
        let chunk_points = evaluator_chunk(evaluator);
        let mut points = Vec::with_capacity(chunk_points + cube);
        let mut targets = Vec::with_capacity(chunk_points + cube);
        for (slot, &(owner, mask)) in owners.iter().enumerate() {
            // A sample at local l is needed by the block at offset d (below the owner) when
            // l is 0 on every axis where d steps down.
            let needed: [bool; 8] = std::array::from_fn(|zero_axes| {
                (0..8).any(|d| mask >> d & 1 == 1 && d & !zero_axes == 0)
            });
            let extent = owner.map(|o| b.min(layout.resolution - o as usize * b));
            for lz in 0..extent[2] {
                for ly in 0..extent[1] {
                    for lx in 0..extent[0] {
                        let zero_axes = usize::from(lx == 0)
                            | usize::from(ly == 0) << 1
                            | usize::from(lz == 0) << 2;
                        if !needed[zero_axes] {
                            continue;
                        }
                        let s = [lx, ly, lz];
                        let g: [usize; 3] = std::array::from_fn(|k| owner[k] as usize * b + s[k]);
                        points.push(g.map(|i| layout.coords[i]));
                        targets.push(slot * cube + lx + b * (ly + b * lz));
                    }
                }
            }
            if points.len() >= chunk_points || slot + 1 == owners.len() {
                let values = evaluator.values(&points)?;
                for (&t, v) in targets.iter().zip(values) {
                    store.values[t] = v;
                }
                store.evaluated += points.len() as u64;
                points.clear();
                targets.clear();
            }
        }
        Ok(store)
    }

    /// The (B+1)³ corner samples of a kept block, x fastest (entries past a clipped block's
    /// last cell are NaN and never read).
    pub(crate) fn gather(&self, layout: &Layout, block: [u32; 3]) -> Vec<f32> {
        let b = layout.block_cells;
        let side = b + 1;
        let cube = b * b * b;
        let owner_slot: [Option<usize>; 8] = std::array::from_fn(|d| {
            let d = d as u32;
            let owner = [
                block[0] + (d & 1),
                block[1] + (d >> 1 & 1),
                block[2] + (d >> 2),
            ];
            self.slot_of.get(&key(owner)).copied()
        });
        let extent = block.map(|o| b.min(layout.cells - o as usize * b));
        let mut out = vec![f32::NAN; side * side * side];
        for lz in 0..=extent[2] {
            for ly in 0..=extent[1] {
                for lx in 0..=extent[0] {
                    let up = [lx, ly, lz].map(|l| usize::from(l == b));
                    let d = up[0] | up[1] << 1 | up[2] << 2;
                    let slot = owner_slot[d].expect("owner of a needed sample was evaluated");
                    let (x, y, z) = (lx - up[0] * b, ly - up[1] * b, lz - up[2] * b);
                    out[lx + side * (ly + side * lz)] =
                        self.values[slot * cube + x + b * (y + b * z)];
                }
            }
        }
        out
    }
}

/// Points gathered before each evaluation call: enough for several full batches.
fn evaluator_chunk(evaluator: &Evaluator<'_>) -> usize {
    evaluator.batch_size() * rayon::current_num_threads().max(2) * 2
}
