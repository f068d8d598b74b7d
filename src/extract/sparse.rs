//! Coarse-to-fine sparse extraction: cull blocks by the Lipschitz bound, sample the fine grid
//! only inside the kept blocks, polygonise them with the shared cell code, merge vertices by
//! their global grid-edge id.

use super::evaluate::{Evaluator, finish};
use super::samples::{Layout, Probe, SampleCache};
use super::{Evaluations, ExtractError, ExtractOptions, Extraction, ScalarField, Timings};
use crate::geometry::TriMesh;
use crate::geometry::marching_cubes::cell::{
    case_of, centre_position, decisions, edge_position, slot_corners, slot_edge, triangles,
};
use crate::geometry::marching_cubes::tables::CENTRE_SLOT;
use rayon::prelude::*;
use std::time::Instant;

/// Extracts the `options.iso` level of `field` on an R³ grid over `[min, max]³`, evaluating
/// only near the surface. The mesh equals [`super::extract_dense`]'s (same triangles, same
/// vertex positions) whenever `lipschitz_bound` bounds the field's gradient; memory grows
/// with the surface area, not with R³.
pub fn extract_surface(
    field: &dyn ScalarField,
    resolution: usize,
    options: &ExtractOptions,
) -> Result<Extraction, ExtractError> {
    let start = Instant::now();
    let grid = options.grid(resolution)?;
    let lipschitz = field.lipschitz_bound();
    if !(lipschitz.is_finite() && lipschitz > 0.0) {
        return Err(ExtractError::Lipschitz(lipschitz));
    }
    let layout = Layout::new(&grid, options.block_cells);
    let mut evaluator = Evaluator::new(field, options);
    let mut cache = SampleCache::new(&layout);
    let (blocks, block_centres) = cull(
        &layout,
        &mut cache,
        &mut evaluator,
        lipschitz * options.safety,
        options.iso,
    )?;
    let sample_count = cache.fill_blocks(&layout, &blocks, &mut evaluator)?;
    let mesh = polygonise(&layout, &blocks, &cache, options.iso);
    drop(cache);
    let (mesh, normals, removed_components) = finish(mesh, &mut evaluator, options);
    let total = start.elapsed();
    Ok(Extraction {
        mesh,
        evaluations: Evaluations {
            block_centres,
            samples: sample_count,
            normals,
        },
        kept_blocks: blocks.len(),
        removed_components,
        timings: Timings {
            evaluation: evaluator.time,
            meshing: total.saturating_sub(evaluator.time),
        },
    })
}

/// Finest blocks that may hold surface, found level by level from a coarse block grid (a
/// block is split into its 8 children when `|f(probe) − iso| ≤ bound · radius`, where the
/// probe ball covers the block). Probes at grid samples go through `cache`. Returns the
/// finest blocks sorted, and the number of field evaluations made.
fn cull(
    layout: &Layout,
    cache: &mut SampleCache,
    evaluator: &mut Evaluator<'_>,
    bound: f32,
    iso: f32,
) -> Result<(Vec<[u32; 3]>, u64), ExtractError> {
    let mut level = 0;
    while layout.blocks.div_ceil(1 << level) > 4 {
        level += 1;
    }
    let top = layout.blocks.div_ceil(1 << level) as u32;
    let mut candidates: Vec<[u32; 3]> = (0..top.pow(3))
        .map(|n| [n % top, n / top % top, n / (top * top)])
        .collect();
    let mut evaluated = 0u64;
    loop {
        let span = layout.block_cells << level;
        let probes: Vec<Probe> = candidates
            .par_iter()
            .map(|b| layout.probe(*b, span))
            .collect();
        // Probes not answered by the cache, each once.
        let fresh: Vec<usize> = probes
            .iter()
            .enumerate()
            .filter(|(_, p)| p.sample.is_none_or(|n| cache.get(n).is_none()))
            .map(|(i, _)| i)
            .collect();
        let points: Vec<[f32; 3]> = fresh.iter().map(|&i| probes[i].point).collect();
        let fresh_values = evaluator.values(&points)?;
        evaluated += points.len() as u64;
        let mut values = vec![0.0f32; probes.len()];
        for (&i, &v) in fresh.iter().zip(&fresh_values) {
            values[i] = v;
            if let Some(n) = probes[i].sample {
                cache.insert(n, v);
            }
        }
        for (v, p) in values.iter_mut().zip(&probes) {
            if let Some(n) = p.sample {
                *v = cache.get(n).expect("probe value was cached");
            }
        }
        let kept = candidates
            .iter()
            .zip(&probes)
            .zip(&values)
            .filter(|((_, p), v)| (**v - iso).abs() <= bound * p.radius)
            .map(|((b, _), _)| *b);
        if level == 0 {
            let mut fine: Vec<[u32; 3]> = kept.collect();
            fine.sort_unstable_by_key(|b| (b[2], b[1], b[0]));
            return Ok((fine, evaluated));
        }
        level -= 1;
        let child_span = layout.block_cells << level;
        candidates = kept
            .flat_map(|b| {
                (0..8u32).map(move |d| {
                    [
                        2 * b[0] + (d & 1),
                        2 * b[1] + (d >> 1 & 1),
                        2 * b[2] + (d >> 2),
                    ]
                })
            })
            .filter(|c| c.iter().all(|&x| (x as usize) * child_span < layout.cells))
            .collect();
    }
}

/// One block's triangles with block-local vertex indices, and its vertices keyed by their
/// global id (grid edge, or cell for a centroid vertex).
struct BlockMesh {
    vertices: Vec<(u64, [f32; 3])>,
    triangles: Vec<[u32; 3]>,
}

fn polygonise(layout: &Layout, blocks: &[[u32; 3]], samples: &SampleCache, iso: f32) -> TriMesh {
    let parts: Vec<BlockMesh> = blocks
        .par_iter()
        .map(|&b| polygonise_block(layout, b, &samples.gather(layout, b), iso))
        .collect();
    let mut keyed: Vec<(u64, [f32; 3])> = parts
        .iter()
        .flat_map(|p| p.vertices.iter().copied())
        .collect();
    keyed.par_sort_unstable_by_key(|v| v.0);
    keyed.dedup_by_key(|v| v.0);
    let index_of = |key: u64| {
        keyed
            .binary_search_by_key(&key, |v| v.0)
            .expect("vertex was emitted") as u32
    };
    let triangles: Vec<Vec<[u32; 3]>> = parts
        .par_iter()
        .map(|p| {
            let global: Vec<u32> = p.vertices.iter().map(|v| index_of(v.0)).collect();
            p.triangles
                .iter()
                .map(|t| t.map(|v| global[v as usize]))
                .collect()
        })
        .collect();
    TriMesh::new(keyed.into_iter().map(|v| v.1).collect(), triangles.concat())
}

/// Marching cubes on the cells of one block; `lattice` holds its (B+1)³ corner samples.
fn polygonise_block(layout: &Layout, block: [u32; 3], lattice: &[f32], iso: f32) -> BlockMesh {
    let side = layout.block_cells + 1;
    let origin = block.map(|x| x as usize * layout.block_cells);
    let extent = origin.map(|o| layout.block_cells.min(layout.cells - o));
    let mut local = vec![u32::MAX; 3 * side * side * side];
    let mut out = BlockMesh {
        vertices: Vec::new(),
        triangles: Vec::new(),
    };
    let r = layout.resolution as u64;
    for lz in 0..extent[2] {
        for ly in 0..extent[1] {
            for lx in 0..extent[0] {
                let at = |c: usize| {
                    lattice[lx + (c & 1) + side * (ly + (c >> 1 & 1) + side * (lz + (c >> 2)))]
                };
                let values: [f32; 8] = std::array::from_fn(at);
                let case = case_of(&values, iso);
                if case == 0 || case == 0xff {
                    continue;
                }
                let dec = decisions(&values, case, iso);
                let cell = [origin[0] + lx, origin[1] + ly, origin[2] + lz];
                let mut centre = u32::MAX;
                for tri in triangles(case, dec) {
                    let t = tri.map(|slot| {
                        if slot == CENTRE_SLOT {
                            if centre == u32::MAX {
                                let polygon = crate::geometry::marching_cubes::cell::centre_polygon(
                                    case, dec,
                                );
                                let p =
                                    centre_position(&layout.coords, cell, &values, iso, polygon);
                                let key = 3 * r * r * r
                                    + (cell[0] as u64 + r * (cell[1] as u64 + r * cell[2] as u64));
                                out.vertices.push((key, p));
                                centre = (out.vertices.len() - 1) as u32;
                            }
                            return centre;
                        }
                        let (offset, axis) = slot_edge(slot);
                        let l = [lx + offset[0], ly + offset[1], lz + offset[2]];
                        let slot_at = axis + 3 * (l[0] + side * (l[1] + side * l[2]));
                        if local[slot_at] == u32::MAX {
                            let lower = std::array::from_fn(|k| origin[k] + l[k]);
                            let (a, b) = slot_corners(slot);
                            let p = edge_position(
                                &layout.coords,
                                lower,
                                axis,
                                values[a],
                                values[b],
                                iso,
                            );
                            let id = lower[0] as u64 + r * (lower[1] as u64 + r * lower[2] as u64);
                            out.vertices.push((3 * id + axis as u64, p));
                            local[slot_at] = (out.vertices.len() - 1) as u32;
                        }
                        local[slot_at]
                    });
                    out.triangles.push(t);
                }
            }
        }
    }
    out
}
