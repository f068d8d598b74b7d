//! The whole SDF network on host memory: f and ∇ₓf for a batch of points, and the gradients of
//! any loss on (f, ∇ₓf) with respect to every parameter, each in one pass over the points.
//!
//! Through burn, one training step of the network is about sixty tensor operations, each a full
//! pass over activations far larger than the caches, each allocating its output. Here the
//! points are cut into chunks of a few hundred rows; a chunk runs through all layers while its
//! activations stay in the core's cache, with gemm's matrix kernels writing straight into
//! reused buffers and the element-wise work (bias or latent offset, softplus, its slope) done
//! in the same loop that reads a product's output. Each thread works on its own chunks, so
//! there is no synchronisation inside a pass.
//!
//! **Forward** (per chunk): `y_l = h_{l−1}·W_l + b_l` (layer 0: `x·W_x + offset`, the skip
//! layer: `h·W_h + x·W_x + offset`, the weights already scaled by 1/√2 there), `h_l =
//! softplus_β(y_l)`, `s_l = σ(βy_l)`; `f = h_{L−1}·w + b`. The reverse pass for ∇ₓf:
//! `δ_{L−1} = s_{L−1} ⊙ w`, `t_l = δ_l·W_lᵀ`, `δ_{l−1} = s_{l−1} ⊙ t_l`, and ∇ₓf collects
//! `δ_0·W_xᵀ` of layer 0 and `δ_skip·W_xᵀ` of the skip layer. What the backward needs is saved:
//! every `h_l`, `s_l` and `t_l`, so the backward evaluates no softplus.
//!
//! **Backward**, for output gradients `G_f` (∂L/∂f) and `G_g` (∂L/∂∇ₓf): first upwards through
//! the reverse pass with `ε_l = ∂L/∂δ_l` (`ε_0 = G_g·W_x`, `∂t_l = ε_{l−1} ⊙ s_{l−1}`,
//! `ε_l = ∂t_l·W_l`, `∂W_l += ∂t_lᵀ·δ_l`, and each `s_{l−1}` passes `ε_{l−1} ⊙ t_l` on to
//! `∂y_{l−1}` through σ' = β·s(1 − s)), then downwards through the forward pass as usual
//! (`∂W_l += h_{l−1}ᵀ·∂y_l`, `∂y_{l−1} = (∂y_l·W_lᵀ) ⊙ s_{l−1} + …`). Six matrix products per
//! layer in all, the count of PyTorch's double backward. Parameter gradients are summed over a
//! fixed number of row ranges in a fixed order, so results do not depend on the thread count.
//!
//! The loops are generic over f32 (training and inference) and f64 (exact references in the
//! tests), and run compiled for the CPU's widest vector instructions (`run_vectorized`).

use std::ops::Range;

use rayon::prelude::*;

use crate::sdf::kernels::buffers::{Buffer, Pooled};
use crate::sdf::kernels::product::{GemmFloat, View, product_into};
use crate::sdf::kernels::softplus::{BlockKernel, run_vectorized};

/// A float type the kernel runs on.
pub trait KernelFloat: GemmFloat + Pooled {}

impl<E: GemmFloat + Pooled> KernelFloat for E {}

/// Row ranges the backward pass sums parameter gradients over (a constant, so that the sums
/// do not depend on the number of threads).
const LANES: usize = 8;

/// Bounds of the rows per chunk ([`KernelShape::chunk_rows`]).
const MIN_CHUNK_ROWS: usize = 256;
const MAX_CHUNK_ROWS: usize = 512;

/// The network's sizes as the kernel sees them.
#[derive(Debug, Clone, PartialEq)]
pub struct KernelShape {
    /// Output width of every hidden (softplus) layer, layer 0 first.
    pub widths: Vec<usize>,
    /// Index of the layer that also takes x (and the latent): 1 ≤ skip < widths.len().
    pub skip: usize,
    /// Softplus sharpness β.
    pub beta: f64,
}

/// Where each parameter block lies in the flat parameter vector (the order
/// [`KernelShape::param_blocks`] lists).
#[derive(Debug, Clone)]
struct ParamLayout {
    /// `[3, w_0]`: the x rows of layer 0.
    first_x: Range<usize>,
    /// Per hidden layer l ≥ 1 (index l − 1): `[w_{l−1}, w_l]` weights multiplying h_{l−1}.
    weights: Vec<Range<usize>>,
    /// Per hidden layer l ≥ 1 (index l − 1): the bias `[w_l]`, or for the skip layer its x
    /// rows `[3, w_l]` (its bias is part of the per-shape offset).
    extras: Vec<Range<usize>>,
    /// `[w_{L−1}]`: output weights.
    out_weight: Range<usize>,
    /// The output bias.
    out_bias: usize,
    /// Length of the whole vector.
    len: usize,
}

/// One block of the flat parameter vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamBlock {
    /// The x rows of layer 0, `[3, w_0]`.
    FirstX,
    /// Hidden layer `l ≥ 1`: the rows multiplying h_{l−1}, `[w_{l−1}, w_l]`.
    Weight(usize),
    /// Hidden layer `l ≥ 1` other than the skip layer: its bias, `[w_l]`.
    Bias(usize),
    /// The skip layer `l`: the rows multiplying x, `[3, w_l]`.
    SkipX(usize),
    /// The output weights, `[w_{L−1}]`.
    OutWeight,
    /// The output bias, `[1]`.
    OutBias,
}

impl KernelShape {
    /// Hidden layers L.
    pub fn layers(&self) -> usize {
        self.widths.len()
    }

    /// The blocks of the flat parameter vector in order, with their shapes `[rows, cols]`.
    pub fn param_blocks(&self) -> Vec<(ParamBlock, [usize; 2])> {
        let w = &self.widths;
        let mut blocks = vec![(ParamBlock::FirstX, [3, w[0]])];
        for l in 1..w.len() {
            blocks.push((ParamBlock::Weight(l), [w[l - 1], w[l]]));
            blocks.push(if l == self.skip {
                (ParamBlock::SkipX(l), [3, w[l]])
            } else {
                (ParamBlock::Bias(l), [1, w[l]])
            });
        }
        blocks.push((ParamBlock::OutWeight, [1, w[w.len() - 1]]));
        blocks.push((ParamBlock::OutBias, [1, 1]));
        blocks
    }

    fn param_layout(&self) -> ParamLayout {
        let mut next = 0;
        let mut take = |[r, c]: [usize; 2]| {
            let range = next..next + r * c;
            next = range.end;
            range
        };
        let blocks = self.param_blocks();
        let mut it = blocks.iter().map(|&(_, dims)| dims);
        let first_x = take(it.next().expect("layer 0"));
        let (mut weights, mut extras) = (Vec::new(), Vec::new());
        for _ in 1..self.layers() {
            weights.push(take(it.next().expect("weight")));
            extras.push(take(it.next().expect("bias or x rows")));
        }
        let out_weight = take(it.next().expect("output weights"));
        let out_bias = take(it.next().expect("output bias")).start;
        ParamLayout {
            first_x,
            weights,
            extras,
            out_weight,
            out_bias,
            len: next,
        }
    }

    /// Length of the flat parameter vector.
    pub fn param_len(&self) -> usize {
        self.param_layout().len
    }

    /// Values per point of the forward output: f, then ∇ₓf when `with_gradient`.
    pub fn output_cols(with_gradient: bool) -> usize {
        if with_gradient { 4 } else { 1 }
    }

    /// Floats per point the forward pass saves for the backward: every h_l and s_l, and
    /// every t_l when ∇ₓf is part of the output.
    pub fn saved_per_row(&self, with_gradient: bool) -> usize {
        let activations: usize = self.widths.iter().sum();
        let t: usize = self.widths[..self.layers() - 1].iter().sum();
        if with_gradient {
            2 * activations + t
        } else {
            2 * activations
        }
    }

    /// Rows per chunk, measured on the training step (BENCHMARKS.md): 256 rows at H = 128,
    /// 512 at H = 256 and H = 512. Fewer rows leave gemm's kernels short of rows to amortise
    /// packing the weights; more push a chunk's activations out of the cache.
    fn chunk_rows(&self) -> usize {
        let widest = self.widths.iter().copied().max().unwrap_or(1);
        (2 * widest).clamp(MIN_CHUNK_ROWS, MAX_CHUNK_ROWS)
    }
}

/// Per-row starts of the matrices in a chunk's slab of saved values, computed once per pass.
#[derive(Debug, Clone)]
struct SlabStarts {
    /// Per-row start of each layer within the h and s blocks (and the total width).
    layers: Vec<usize>,
    /// Per-row start of each t_l (index l − 1) within the t block.
    t: Vec<usize>,
}

impl SlabStarts {
    fn new(shape: &KernelShape) -> Self {
        Self {
            layers: prefix_sums(&shape.widths),
            t: prefix_sums(&shape.widths[..shape.layers() - 1]),
        }
    }

    /// The layout of a chunk of `rows` rows.
    fn for_rows(&self, rows: usize) -> SlabLayout<'_> {
        SlabLayout { rows, starts: self }
    }
}

/// Where each matrix of a chunk lies in the chunk's slab of saved values: all h_l, then all
/// s_l, then all t_l (l ≥ 1), each `[rows, width]`.
struct SlabLayout<'p> {
    rows: usize,
    starts: &'p SlabStarts,
}

impl SlabLayout<'_> {
    /// Values of the h block (and of the s block).
    fn block(&self) -> usize {
        self.rows * self.starts.layers[self.starts.layers.len() - 1]
    }

    /// Layer l's matrix within the h or the s block.
    fn layer(&self, l: usize) -> Range<usize> {
        self.rows * self.starts.layers[l]..self.rows * self.starts.layers[l + 1]
    }

    /// t_l (l ≥ 1) within the t block.
    fn t(&self, l: usize) -> Range<usize> {
        self.rows * self.starts.t[l - 1]..self.rows * self.starts.t[l]
    }

    /// The slab as (h block, s block, t block).
    fn split<'s, E>(&self, slab: &'s [E]) -> (&'s [E], &'s [E], &'s [E]) {
        let (h, rest) = slab.split_at(self.block());
        let (s, t) = rest.split_at(self.block());
        (h, s, t)
    }

    fn split_mut<'s, E>(&self, slab: &'s mut [E]) -> (&'s mut [E], &'s mut [E], &'s mut [E]) {
        let (h, rest) = slab.split_at_mut(self.block());
        let (s, t) = rest.split_at_mut(self.block());
        (h, s, t)
    }
}

fn prefix_sums(values: &[usize]) -> Vec<usize> {
    let mut acc = 0;
    let mut out = Vec::with_capacity(values.len() + 1);
    out.push(0);
    for v in values {
        acc += v;
        out.push(acc);
    }
    out
}

/// Why the kernel's inputs do not fit together.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KernelError {
    /// A buffer has the wrong length.
    #[error("{what} has {len} values, expected {expected}")]
    Length {
        /// Which buffer.
        what: &'static str,
        /// Its length.
        len: usize,
        /// What the shape implies.
        expected: usize,
    },
    /// The shape itself is unusable.
    #[error("network shape: {0}")]
    Shape(&'static str),
}

/// The network's parameters and per-group offsets, borrowed for one pass.
///
/// Rows of the points are split into `groups` equal consecutive groups (one per shape); row
/// r takes the offset rows `r / (rows / groups)` of `first` (`[groups, w_0]`: z·W_z + b of
/// layer 0) and `skip` (`[groups, w_skip]`: the same for the skip layer, scaled by 1/√2).
#[derive(Debug, Clone, Copy)]
pub struct Network<'a, E> {
    shape: &'a KernelShape,
    params: &'a [E],
    first: &'a [E],
    skip: &'a [E],
    groups: usize,
    chunk_rows: usize,
}

/// Parameter and offset gradients of the backward pass (layouts as the inputs).
#[derive(Debug, Clone, PartialEq)]
pub struct NetworkGradients<E> {
    /// ∂L/∂params, flat like the parameters.
    pub params: Vec<E>,
    /// ∂L/∂first, `[groups, w_0]`.
    pub first: Vec<E>,
    /// ∂L/∂skip, `[groups, w_skip]`.
    pub skip: Vec<E>,
}

impl<'a, E: KernelFloat> Network<'a, E> {
    /// Checks the sizes of the parameters and offsets against `shape`.
    pub fn new(
        shape: &'a KernelShape,
        params: &'a [E],
        first: &'a [E],
        skip: &'a [E],
        groups: usize,
    ) -> Result<Self, KernelError> {
        if shape.layers() < 2 || shape.widths.contains(&0) {
            return Err(KernelError::Shape(
                "at least two hidden layers of width ≥ 1",
            ));
        }
        if shape.skip == 0 || shape.skip >= shape.layers() {
            return Err(KernelError::Shape("skip layer outside 1..L"));
        }
        if groups == 0 {
            return Err(KernelError::Shape("no offset groups"));
        }
        let check = |what, len: usize, expected| {
            if len == expected {
                Ok(())
            } else {
                Err(KernelError::Length {
                    what,
                    len,
                    expected,
                })
            }
        };
        check("params", params.len(), shape.param_len())?;
        check("first", first.len(), groups * shape.widths[0])?;
        check("skip", skip.len(), groups * shape.widths[shape.skip])?;
        Ok(Self {
            shape,
            params,
            first,
            skip,
            groups,
            chunk_rows: shape.chunk_rows(),
        })
    }

    /// Processes `rows` points per chunk instead of the size chosen for the cache (at least
    /// one); results agree to rounding whatever the chunk size.
    pub fn with_chunk_rows(mut self, rows: usize) -> Self {
        self.chunk_rows = rows.max(1);
        self
    }

    fn check_rows(&self, points: &[E]) -> Result<usize, KernelError> {
        let rows = points.len() / 3;
        if !points.len().is_multiple_of(3) || !rows.is_multiple_of(self.groups) {
            return Err(KernelError::Length {
                what: "points",
                len: points.len(),
                expected: 3 * (rows / self.groups).max(1) * self.groups,
            });
        }
        Ok(rows)
    }

    /// f (and ∇ₓf when `with_gradient`) at `points` (`[N, 3]`, grouped as the offsets) into
    /// `out` (`[N, 1]` or `[N, 4]`: f, ∂f/∂x, ∂f/∂y, ∂f/∂z). With `saved` (`[N ·
    /// saved_per_row]`) also keeps what [`Self::backward`] needs.
    pub fn forward(
        &self,
        points: &[E],
        with_gradient: bool,
        out: &mut [E],
        saved: Option<&mut [E]>,
    ) -> Result<(), KernelError> {
        let rows = self.check_rows(points)?;
        let cols = KernelShape::output_cols(with_gradient);
        let per_row = self.shape.saved_per_row(with_gradient);
        if out.len() != rows * cols {
            return Err(KernelError::Length {
                what: "output",
                len: out.len(),
                expected: rows * cols,
            });
        }
        if let Some(s) = &saved
            && s.len() != rows * per_row
        {
            return Err(KernelError::Length {
                what: "saved",
                len: s.len(),
                expected: rows * per_row,
            });
        }
        let c = self.chunk_rows;
        let saving = saved.is_some();
        let saved_chunks: Vec<Option<&mut [E]>> = match saved {
            Some(s) => s.chunks_mut(c * per_row).map(Some).collect(),
            None => (0..rows.div_ceil(c)).map(|_| None).collect(),
        };
        let jobs: Vec<ForwardJob<'_, E>> = points
            .chunks(3 * c)
            .zip(out.chunks_mut(c * cols))
            .zip(saved_chunks)
            .enumerate()
            .map(|(k, ((x, out), saved))| ForwardJob {
                first_row: k * c,
                x,
                out,
                saved,
            })
            .collect();
        let kernel = self.pass(with_gradient, rows);
        let slab = !saving;
        jobs.into_par_iter().for_each_init(
            || ForwardScratch::new(self.shape, c, slab),
            |scratch, job| run_vectorized(&kernel, job.first_row, (job, scratch)),
        );
        Ok(())
    }

    /// The gradients of a loss with output gradient `grad` (∂L/∂out, laid out as the forward
    /// output) with respect to the parameters and offsets, from the forward pass's `saved`.
    pub fn backward(
        &self,
        points: &[E],
        with_gradient: bool,
        grad: &[E],
        saved: &[E],
    ) -> Result<NetworkGradients<E>, KernelError> {
        let rows = self.check_rows(points)?;
        let cols = KernelShape::output_cols(with_gradient);
        let per_row = self.shape.saved_per_row(with_gradient);
        for (what, len, expected) in [
            ("output gradient", grad.len(), rows * cols),
            ("saved", saved.len(), rows * per_row),
        ] {
            if len != expected {
                return Err(KernelError::Length {
                    what,
                    len,
                    expected,
                });
            }
        }
        let c = self.chunk_rows;
        let chunks = rows.div_ceil(c);
        let kernel = self.pass(with_gradient, rows);
        let lanes: Vec<LaneSums<E>> = (0..LANES)
            .into_par_iter()
            .map(|lane| {
                let mut acc = LaneSums {
                    params: Buffer::zeroed(self.params.len()),
                    first: Buffer::zeroed(self.first.len()),
                    skip: Buffer::zeroed(self.skip.len()),
                };
                let mut scratch = BackwardScratch::new(self.shape, c);
                for k in lane * chunks / LANES..(lane + 1) * chunks / LANES {
                    let r = k * c..((k + 1) * c).min(rows);
                    let job = BackwardJob {
                        x: &points[3 * r.start..3 * r.end],
                        grad: &grad[cols * r.start..cols * r.end],
                        saved: &saved[per_row * r.start..per_row * r.end],
                        acc: &mut acc,
                    };
                    run_vectorized(&kernel, r.start, (job, &mut scratch));
                }
                acc
            })
            .collect();
        let mut total = NetworkGradients {
            params: vec![E::ZERO; self.params.len()],
            first: vec![E::ZERO; self.first.len()],
            skip: vec![E::ZERO; self.skip.len()],
        };
        for lane in &lanes {
            for (t, l) in [
                (&mut total.params, &lane.params),
                (&mut total.first, &lane.first),
                (&mut total.skip, &lane.skip),
            ] {
                t.iter_mut().zip(l.iter()).for_each(|(t, &v)| *t += v);
            }
        }
        Ok(total)
    }

    /// The chunk passes over `rows` points.
    fn pass(&self, with_gradient: bool, rows: usize) -> Pass<'_, 'a, E> {
        Pass {
            net: self,
            with_gradient,
            layout: self.shape.param_layout(),
            slab: SlabStarts::new(self.shape),
            group_rows: rows / self.groups,
        }
    }
}

/// One chunk of the forward pass.
struct ForwardJob<'a, E> {
    first_row: usize,
    x: &'a [E],
    out: &'a mut [E],
    saved: Option<&'a mut [E]>,
}

/// One chunk of the backward pass, accumulating into its lane's gradients.
struct BackwardJob<'a, E: KernelFloat> {
    x: &'a [E],
    grad: &'a [E],
    saved: &'a [E],
    acc: &'a mut LaneSums<E>,
}

/// The gradients summed over one lane's chunks (layouts as [`NetworkGradients`]).
struct LaneSums<E: KernelFloat> {
    params: Buffer<E>,
    first: Buffer<E>,
    skip: Buffer<E>,
}

/// Per-thread buffers of a forward chunk, reused from chunk to chunk (and from pass to pass);
/// every chunk writes what it reads first.
struct ForwardScratch<E: KernelFloat> {
    /// The chunk's slab when the pass does not save one.
    slab: Option<Buffer<E>>,
    /// δ_l and δ_{l−1} of the reverse pass.
    a: Buffer<E>,
    b: Buffer<E>,
}

impl<E: KernelFloat> ForwardScratch<E> {
    fn new(shape: &KernelShape, rows: usize, slab: bool) -> Self {
        let widest = shape.widths.iter().copied().max().unwrap_or(0);
        Self {
            slab: slab.then(|| Buffer::reused(rows * shape.saved_per_row(true))),
            a: Buffer::reused(rows * widest),
            b: Buffer::reused(rows * widest),
        }
    }
}

/// Per-thread buffers of a backward chunk, reused from chunk to chunk (and from pass to pass);
/// every chunk writes what it reads first.
struct BackwardScratch<E: KernelFloat> {
    /// ∂y_l of every layer.
    dy: Buffer<E>,
    /// Three matrices of the chunk's widest activation (δ, ε, ∂t, ∂h).
    a: Buffer<E>,
    b: Buffer<E>,
    c: Buffer<E>,
}

impl<E: KernelFloat> BackwardScratch<E> {
    fn new(shape: &KernelShape, rows: usize) -> Self {
        let all: usize = shape.widths.iter().sum();
        let widest = shape.widths.iter().copied().max().unwrap_or(0);
        let take = |n: usize| Buffer::reused(n * rows);
        Self {
            dy: take(all),
            a: take(widest),
            b: take(widest),
            c: take(widest),
        }
    }
}

/// The forward or backward pass over one chunk, run by [`run_vectorized`].
struct Pass<'n, 'a, E> {
    net: &'n Network<'a, E>,
    with_gradient: bool,
    layout: ParamLayout,
    slab: SlabStarts,
    /// Rows per offset group (points per shape).
    group_rows: usize,
}

impl<'j, E: KernelFloat> BlockKernel<(ForwardJob<'j, E>, &mut ForwardScratch<E>)>
    for Pass<'_, '_, E>
{
    type Output = ();

    #[inline(always)]
    fn run(&self, first_row: usize, (job, scratch): (ForwardJob<'j, E>, &mut ForwardScratch<E>)) {
        self.forward_chunk(first_row, job, scratch);
    }
}

impl<'j, E: KernelFloat> BlockKernel<(BackwardJob<'j, E>, &mut BackwardScratch<E>)>
    for Pass<'_, '_, E>
{
    type Output = ();

    #[inline(always)]
    fn run(&self, first_row: usize, (job, scratch): (BackwardJob<'j, E>, &mut BackwardScratch<E>)) {
        self.backward_chunk(first_row, job, scratch);
    }
}

impl<E: KernelFloat> Pass<'_, '_, E> {
    fn shape(&self) -> &KernelShape {
        self.net.shape
    }

    fn param(&self, range: &Range<usize>) -> &[E] {
        &self.net.params[range.clone()]
    }

    /// W_l (l ≥ 1) as a `[w_{l−1}, w_l]` view.
    fn weight(&self, l: usize) -> View<'_, E> {
        let w = &self.shape().widths;
        View::dense(self.param(&self.layout.weights[l - 1]), w[l - 1], w[l])
    }

    /// The bias of layer l ≥ 1, or the x rows `[3, w_l]` of the skip layer.
    fn extra(&self, l: usize) -> &[E] {
        self.param(&self.layout.extras[l - 1])
    }

    /// The group (shape) of point row `row`.
    #[inline(always)]
    fn group(&self, row: usize) -> usize {
        row / self.group_rows
    }

    #[inline(always)]
    fn forward_chunk(
        &self,
        first_row: usize,
        job: ForwardJob<'_, E>,
        scratch: &mut ForwardScratch<E>,
    ) {
        let shape = self.shape();
        let (w, layers, skip) = (&shape.widths, shape.layers(), shape.skip);
        let rows = job.x.len() / 3;
        let (beta, inv_beta) = (E::of(shape.beta), E::of(1.0 / shape.beta));
        let at = self.slab.for_rows(rows);
        // The backward and ∇ₓf need the slopes s_l; f alone does not.
        let slopes = self.with_gradient || job.saved.is_some();
        let ForwardScratch { slab, a, b } = scratch;
        let slab: &mut [E] = match job.saved {
            Some(saved) => saved,
            None => {
                let own = slab.as_mut().expect("a pass that does not save has a slab");
                &mut own[..rows * shape.saved_per_row(true)]
            }
        };
        let (h, s, t) = at.split_mut(slab);
        for l in 0..layers {
            // y_l is written into h_l's place and turned into h_l there.
            let (below, above) = h.split_at_mut(at.layer(l).start);
            let y = &mut above[..rows * w[l]];
            if l == 0 {
                let x_rows = self.param(&self.layout.first_x);
                for (r, (y, x)) in y
                    .chunks_exact_mut(w[0])
                    .zip(job.x.chunks_exact(3))
                    .enumerate()
                {
                    let g = self.group(first_row + r);
                    y.copy_from_slice(&self.net.first[g * w[0]..(g + 1) * w[0]]);
                    add_x_rows(y, x, x_rows);
                }
            } else {
                let h_prev = &below[at.layer(l - 1)];
                product_into(
                    y,
                    View::dense(h_prev, rows, w[l - 1]),
                    self.weight(l),
                    false,
                );
                let extra = self.extra(l);
                for (r, (y, x)) in y
                    .chunks_exact_mut(w[l])
                    .zip(job.x.chunks_exact(3))
                    .enumerate()
                {
                    if l == skip {
                        let g = self.group(first_row + r);
                        add(y, &self.net.skip[g * w[l]..(g + 1) * w[l]]);
                        add_x_rows(y, x, extra);
                    } else {
                        add(y, extra);
                    }
                }
            }
            if slopes {
                for (h, s) in y.iter_mut().zip(&mut s[at.layer(l)]) {
                    let (sp, slope) = E::softplus_unit(beta * *h);
                    *h = sp * inv_beta;
                    *s = slope;
                }
            } else {
                for h in y.iter_mut() {
                    *h = E::softplus_unit(beta * *h).0 * inv_beta;
                }
            }
        }
        let last = layers - 1;
        let out_w = self.param(&self.layout.out_weight);
        let out_b = self.net.params[self.layout.out_bias];
        let cols = KernelShape::output_cols(self.with_gradient);
        for (o, h) in job
            .out
            .chunks_exact_mut(cols)
            .zip(h[at.layer(last)].chunks_exact(w[last]))
        {
            o[0] = dot(h, out_w) + out_b;
        }
        if !self.with_gradient {
            return;
        }
        // The reverse pass for ∇ₓf: δ_l in `a`, δ_{l−1} built in `b`.
        scale_rows(&mut a[..rows * w[last]], &s[at.layer(last)], out_w);
        for o in job.out.chunks_exact_mut(4) {
            o[1..].fill(E::ZERO);
        }
        for l in (1..layers).rev() {
            let delta = &a[..rows * w[l]];
            if l == skip {
                add_x_gradient(job.out, delta, w[l], self.extra(l));
            }
            let t_l = &mut t[at.t(l)];
            product_into(
                t_l,
                View::dense(delta, rows, w[l]),
                self.weight(l).transposed(),
                false,
            );
            multiply(&mut b[..rows * w[l - 1]], &s[at.layer(l - 1)], t_l);
            std::mem::swap(a, b);
        }
        add_x_gradient(
            job.out,
            &a[..rows * w[0]],
            w[0],
            self.param(&self.layout.first_x),
        );
    }

    #[inline(always)]
    fn backward_chunk(
        &self,
        first_row: usize,
        job: BackwardJob<'_, E>,
        scratch: &mut BackwardScratch<E>,
    ) {
        let shape = self.shape();
        let (w, layers, skip) = (&shape.widths, shape.layers(), shape.skip);
        let rows = job.x.len() / 3;
        let beta = E::of(shape.beta);
        let cols = KernelShape::output_cols(self.with_gradient);
        let at = self.slab.for_rows(rows);
        let (h, s, t) = at.split(job.saved);
        let BackwardScratch { dy, a, b, c } = scratch;
        let acc = job.acc;
        let last = layers - 1;
        let out_w = self.param(&self.layout.out_weight);
        let d_slope = |s: E| beta * s * (E::ONE - s);
        if self.with_gradient {
            // Upwards through the reverse pass; ε_l in `a`.
            let first_x = self.param(&self.layout.first_x);
            for (e, g) in a[..rows * w[0]]
                .chunks_exact_mut(w[0])
                .zip(job.grad.chunks_exact(4))
            {
                e.fill(E::ZERO);
                add_x_rows(e, &g[1..], first_x);
            }
            // ∂W_x of layer 0 += G_gᵀ·δ_0, δ_0 = s_0 ⊙ t_1.
            multiply(&mut c[..rows * w[0]], &s[at.layer(0)], &t[at.t(1)]);
            let d_first_x = &mut acc.params[self.layout.first_x.clone()];
            add_outer_x(d_first_x, job.grad, 4, 1, &c[..rows * w[0]], w[0]);
            for l in 1..layers {
                // ∂t_l = ε_{l−1} ⊙ s_{l−1} into `b`; ε_{l−1} ⊙ t_l through σ' into ∂y_{l−1}.
                let (eps, dt) = (&a[..rows * w[l - 1]], &mut b[..rows * w[l - 1]]);
                for ((((dt, dy), &e), &s), &t) in dt
                    .iter_mut()
                    .zip(&mut dy[at.layer(l - 1)])
                    .zip(eps)
                    .zip(&s[at.layer(l - 1)])
                    .zip(&t[at.t(l)])
                {
                    *dt = e * s;
                    *dy = e * t * d_slope(s);
                }
                // δ_l = s_l ⊙ t_{l+1} (the output weights above the last layer) into `c`.
                let delta = &mut c[..rows * w[l]];
                if l == last {
                    scale_rows(delta, &s[at.layer(l)], out_w);
                } else {
                    multiply(delta, &s[at.layer(l)], &t[at.t(l + 1)]);
                }
                let dt = View::dense(&b[..rows * w[l - 1]], rows, w[l - 1]);
                let d_weight = &mut acc.params[self.layout.weights[l - 1].clone()];
                product_into(
                    d_weight,
                    dt.transposed(),
                    View::dense(delta, rows, w[l]),
                    true,
                );
                let eps_next = &mut a[..rows * w[l]];
                product_into(eps_next, dt, self.weight(l), false);
                if l == skip {
                    let x_rows = self.extra(l);
                    for (e, g) in eps_next
                        .chunks_exact_mut(w[l])
                        .zip(job.grad.chunks_exact(4))
                    {
                        add_x_rows(e, &g[1..], x_rows);
                    }
                    let d_x_rows = &mut acc.params[self.layout.extras[l - 1].clone()];
                    add_outer_x(d_x_rows, job.grad, 4, 1, &c[..rows * w[l]], w[l]);
                }
            }
            // Above the last layer: δ_{L−1} = s_{L−1} ⊙ w.
            let eps = &a[..rows * w[last]];
            let d_out_w = &mut acc.params[self.layout.out_weight.clone()];
            for ((e, s), dy) in eps
                .chunks_exact(w[last])
                .zip(s[at.layer(last)].chunks_exact(w[last]))
                .zip(dy[at.layer(last)].chunks_exact_mut(w[last]))
            {
                for ((((dw, dy), &e), &s), &wo) in
                    d_out_w.iter_mut().zip(dy).zip(e).zip(s).zip(out_w)
                {
                    *dw += e * s;
                    *dy = e * wo * d_slope(s);
                }
            }
        } else {
            dy[at.layer(last)].fill(E::ZERO);
        }
        // Downwards through the forward pass.
        {
            let d_out_w = &mut acc.params[self.layout.out_weight.clone()];
            let mut d_out_b = E::ZERO;
            for (((dy, s), h), g) in dy[at.layer(last)]
                .chunks_exact_mut(w[last])
                .zip(s[at.layer(last)].chunks_exact(w[last]))
                .zip(h[at.layer(last)].chunks_exact(w[last]))
                .zip(job.grad.chunks_exact(cols))
            {
                let gf = g[0];
                d_out_b += gf;
                for ((((dy, &s), &h), &wo), dw) in dy
                    .iter_mut()
                    .zip(s)
                    .zip(h)
                    .zip(out_w)
                    .zip(d_out_w.iter_mut())
                {
                    *dy += gf * wo * s;
                    *dw += gf * h;
                }
            }
            acc.params[self.layout.out_bias] += d_out_b;
        }
        for l in (1..layers).rev() {
            let (below, above) = dy.split_at_mut(at.layer(l).start);
            let dy_l = &above[..rows * w[l]];
            let d_weight = &mut acc.params[self.layout.weights[l - 1].clone()];
            product_into(
                d_weight,
                View::dense(&h[at.layer(l - 1)], rows, w[l - 1]).transposed(),
                View::dense(dy_l, rows, w[l]),
                true,
            );
            if l == skip {
                let d_x_rows = &mut acc.params[self.layout.extras[l - 1].clone()];
                add_outer_x(d_x_rows, job.x, 3, 0, dy_l, w[l]);
                add_group_sums(&mut acc.skip, dy_l, w[l], first_row, self.group_rows);
            } else {
                let d_bias = &mut acc.params[self.layout.extras[l - 1].clone()];
                for row in dy_l.chunks_exact(w[l]) {
                    add(d_bias, row);
                }
            }
            let dh = &mut a[..rows * w[l - 1]];
            product_into(
                dh,
                View::dense(dy_l, rows, w[l]),
                self.weight(l).transposed(),
                false,
            );
            let dy_prev = &mut below[at.layer(l - 1)];
            let s_prev = &s[at.layer(l - 1)];
            if self.with_gradient {
                dy_prev
                    .iter_mut()
                    .zip(dh.iter())
                    .zip(s_prev)
                    .for_each(|((dy, &d), &s)| *dy += d * s);
            } else {
                multiply(dy_prev, dh, s_prev);
            }
        }
        let dy0 = &dy[at.layer(0)];
        let d_first_x = &mut acc.params[self.layout.first_x.clone()];
        add_outer_x(d_first_x, job.x, 3, 0, dy0, w[0]);
        add_group_sums(&mut acc.first, dy0, w[0], first_row, self.group_rows);
    }
}

/// `out = a ⊙ b`.
#[inline(always)]
fn multiply<E: KernelFloat>(out: &mut [E], a: &[E], b: &[E]) {
    out.iter_mut()
        .zip(a)
        .zip(b)
        .for_each(|((o, &a), &b)| *o = a * b);
}

/// `out[r] = m[r] ⊙ v` for every row r of `m` (v one row).
#[inline(always)]
fn scale_rows<E: KernelFloat>(out: &mut [E], m: &[E], v: &[E]) {
    let w = v.len();
    for (o, m) in out.chunks_exact_mut(w).zip(m.chunks_exact(w)) {
        multiply(o, m, v);
    }
}

/// `row += b`.
#[inline(always)]
fn add<E: KernelFloat>(row: &mut [E], b: &[E]) {
    row.iter_mut().zip(b).for_each(|(v, &b)| *v += b);
}

/// `row += x·X` for a point (or any 3-vector) `x` and the `[3, H]` rows `X`.
#[inline(always)]
fn add_x_rows<E: KernelFloat>(row: &mut [E], x: &[E], x_rows: &[E]) {
    let h = row.len();
    let (r0, r1, r2) = (&x_rows[..h], &x_rows[h..2 * h], &x_rows[2 * h..3 * h]);
    let (x0, x1, x2) = (x[0], x[1], x[2]);
    for (((v, &a), &b), &c) in row.iter_mut().zip(r0).zip(r1).zip(r2) {
        *v += x0 * a + x1 * b + x2 * c;
    }
}

/// `out[r][1 + k] += δ_r · X_k` for the `[3, H]` rows `X` (∇ₓf columns of a `[rows, 4]` output).
#[inline(always)]
fn add_x_gradient<E: KernelFloat>(out: &mut [E], delta: &[E], width: usize, x_rows: &[E]) {
    for (o, d) in out.chunks_exact_mut(4).zip(delta.chunks_exact(width)) {
        for k in 0..3 {
            o[1 + k] += dot(d, &x_rows[k * width..(k + 1) * width]);
        }
    }
}

/// `acc[k][j] += Σ_r v[r][first + k] · m[r][j]`: a `[3, H]` block of `vᵀ·m` where `v` has
/// `stride` values per row (points, or the ∇ₓf columns of an output gradient).
#[inline(always)]
fn add_outer_x<E: KernelFloat>(
    acc: &mut [E],
    v: &[E],
    stride: usize,
    first: usize,
    m: &[E],
    width: usize,
) {
    let (a0, rest) = acc.split_at_mut(width);
    let (a1, a2) = rest.split_at_mut(width);
    for (vr, mr) in v.chunks_exact(stride).zip(m.chunks_exact(width)) {
        let (v0, v1, v2) = (vr[first], vr[first + 1], vr[first + 2]);
        for (((a0, a1), a2), &m) in a0.iter_mut().zip(a1.iter_mut()).zip(a2.iter_mut()).zip(mr) {
            *a0 += v0 * m;
            *a1 += v1 * m;
            *a2 += v2 * m;
        }
    }
}

/// Adds each row of `m` (chunk rows from `first_row` on) to its group's row of `acc`.
#[inline(always)]
fn add_group_sums<E: KernelFloat>(
    acc: &mut [E],
    m: &[E],
    width: usize,
    first_row: usize,
    group_rows: usize,
) {
    for (r, row) in m.chunks_exact(width).enumerate() {
        let g = (first_row + r) / group_rows;
        add(&mut acc[g * width..(g + 1) * width], row);
    }
}

/// `a · b` with eight partial sums, so the loop vectorises.
#[inline(always)]
fn dot<E: KernelFloat>(a: &[E], b: &[E]) -> E {
    let mut acc = [E::ZERO; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let mut tail = E::ZERO;
    for (&x, &y) in ca.remainder().iter().zip(cb.remainder()) {
        tail += x * y;
    }
    for (x, y) in ca.zip(cb) {
        for ((s, &x), &y) in acc.iter_mut().zip(x).zip(y) {
            *s += x * y;
        }
    }
    let mut sum = tail;
    for s in acc {
        sum += s;
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic values in [−r, r).
    fn values(n: usize, seed: u64, r: f64) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let v = (i as u64 + 1)
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(seed.wrapping_mul(1_442_695_040_888_963_407));
                (((v >> 31) % 20_000) as f64 / 10_000.0 - 1.0) * r
            })
            .collect()
    }

    struct Case {
        shape: KernelShape,
        params: Vec<f64>,
        first: Vec<f64>,
        skip: Vec<f64>,
        points: Vec<f64>,
        groups: usize,
    }

    fn case(widths: Vec<usize>, skip: usize, groups: usize, per_group: usize) -> Case {
        let shape = KernelShape {
            widths,
            skip,
            beta: 10.0,
        };
        let w = &shape.widths;
        Case {
            params: values(shape.param_len(), 1, 0.5),
            first: values(groups * w[0], 2, 0.3),
            skip: values(groups * w[skip], 3, 0.3),
            points: values(3 * groups * per_group, 4, 0.9),
            groups,
            shape,
        }
    }

    fn forward(c: &Case, chunk: usize, with_gradient: bool) -> (Vec<f64>, Vec<f64>) {
        let net = Network::new(&c.shape, &c.params, &c.first, &c.skip, c.groups)
            .unwrap()
            .with_chunk_rows(chunk);
        let rows = c.points.len() / 3;
        let mut out = vec![0.0; rows * KernelShape::output_cols(with_gradient)];
        let mut saved = vec![0.0; rows * c.shape.saved_per_row(with_gradient)];
        net.forward(&c.points, with_gradient, &mut out, Some(&mut saved))
            .unwrap();
        (out, saved)
    }

    fn backward(
        c: &Case,
        chunk: usize,
        with_gradient: bool,
        grad: &[f64],
        saved: &[f64],
    ) -> NetworkGradients<f64> {
        Network::new(&c.shape, &c.params, &c.first, &c.skip, c.groups)
            .unwrap()
            .with_chunk_rows(chunk)
            .backward(&c.points, with_gradient, grad, saved)
            .unwrap()
    }

    fn assert_close(what: &str, a: &[f64], b: &[f64], tol: f64) {
        assert_eq!(a.len(), b.len(), "{what}: sizes");
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!(
                (x - y).abs() <= tol * (1.0 + y.abs()),
                "{what}[{i}]: {x} vs {y}"
            );
        }
    }

    /// Chunks of 7 rows (chunks cross group boundaries and outnumber the lanes) give the
    /// single-chunk results to rounding, forward and backward, with and without ∇ₓf; the
    /// forward without saving equals the forward with.
    #[test]
    fn results_do_not_depend_on_the_chunk_size() {
        for (widths, skip) in [(vec![6, 5, 4, 7, 6], 3), (vec![9, 9, 9], 1)] {
            let c = case(widths, skip, 3, 20);
            for with_gradient in [true, false] {
                let (out_one, saved_one) = forward(&c, 1000, with_gradient);
                let (out_many, saved_many) = forward(&c, 7, with_gradient);
                assert_close("output", &out_many, &out_one, 1e-13);
                let grad = values(out_one.len(), 9, 1.0);
                let one = backward(&c, 1000, with_gradient, &grad, &saved_one);
                let many = backward(&c, 7, with_gradient, &grad, &saved_many);
                assert_close("∂params", &many.params, &one.params, 1e-12);
                assert_close("∂first", &many.first, &one.first, 1e-12);
                assert_close("∂skip", &many.skip, &one.skip, 1e-12);

                let net = Network::new(&c.shape, &c.params, &c.first, &c.skip, c.groups).unwrap();
                let mut plain = vec![0.0; out_one.len()];
                net.forward(&c.points, with_gradient, &mut plain, None)
                    .unwrap();
                assert_eq!(plain, out_one, "forward without saving");
            }
        }
    }

    /// The backward against central differences of L = Σ grad ⊙ out in f64, for entries of
    /// every parameter block and both offsets, with and without ∇ₓf in the output.
    #[test]
    fn backward_matches_central_differences() {
        let c = case(vec![5, 6, 4, 5], 2, 2, 9);
        for with_gradient in [true, false] {
            let (out, saved) = forward(&c, 4, with_gradient);
            let grad = values(out.len(), 11, 1.0);
            let analytic = backward(&c, 4, with_gradient, &grad, &saved);
            let loss = |params: &[f64], first: &[f64], skip: &[f64]| {
                let net = Network::new(&c.shape, params, first, skip, c.groups).unwrap();
                let mut out = vec![0.0; grad.len()];
                net.forward(&c.points, with_gradient, &mut out, None)
                    .unwrap();
                out.iter().zip(&grad).map(|(o, g)| o * g).sum::<f64>()
            };
            let h = 1e-6;
            let fd = |which: usize, i: usize| {
                let shifted = |s: f64| {
                    let (mut p, mut f, mut k) = (c.params.clone(), c.first.clone(), c.skip.clone());
                    [&mut p, &mut f, &mut k][which][i] += s;
                    loss(&p, &f, &k)
                };
                (shifted(h) - shifted(-h)) / (2.0 * h)
            };
            let mut start = 0;
            for (block, [r, cols]) in c.shape.param_blocks() {
                for i in [start, start + r * cols / 2, start + r * cols - 1] {
                    let (a, f) = (analytic.params[i], fd(0, i));
                    assert!(
                        (a - f).abs() <= 1e-6 * (1.0 + f.abs()),
                        "{block:?} [{i}] (∇f {with_gradient}): {a} vs FD {f}"
                    );
                }
                start += r * cols;
            }
            for (which, name, g) in [(1, "first", &analytic.first), (2, "skip", &analytic.skip)] {
                for i in [0, g.len() / 2 + 1, g.len() - 1] {
                    let f = fd(which, i);
                    assert!(
                        (g[i] - f).abs() <= 1e-6 * (1.0 + f.abs()),
                        "{name}[{i}] (∇f {with_gradient}): {} vs FD {f}",
                        g[i]
                    );
                }
            }
        }
    }

    /// ∇ₓf of the forward pass against central differences of f in f64.
    #[test]
    fn input_gradient_matches_central_differences() {
        let c = case(vec![7, 7, 5, 7, 6], 3, 2, 10);
        let (out, _) = forward(&c, 6, true);
        let net = Network::new(&c.shape, &c.params, &c.first, &c.skip, c.groups).unwrap();
        let f_at = |points: &[f64]| {
            let mut f = vec![0.0; points.len() / 3];
            net.forward(points, false, &mut f, None).unwrap();
            f
        };
        let h = 1e-6;
        for k in 0..3 {
            let shifted = |s: f64| {
                let mut p = c.points.clone();
                p.iter_mut().skip(k).step_by(3).for_each(|v| *v += s);
                f_at(&p)
            };
            let (plus, minus) = (shifted(h), shifted(-h));
            for i in 0..plus.len() {
                let fd = (plus[i] - minus[i]) / (2.0 * h);
                let an = out[4 * i + 1 + k];
                assert!(
                    (fd - an).abs() <= 1e-7 * (1.0 + fd.abs()),
                    "point {i} axis {k}: {an} vs FD {fd}"
                );
            }
        }
    }

    #[test]
    fn mismatched_buffers_are_errors() {
        let c = case(vec![4, 4, 4], 1, 2, 3);
        assert!(matches!(
            Network::new(&c.shape, &c.params[1..], &c.first, &c.skip, 2),
            Err(KernelError::Length { what: "params", .. })
        ));
        let bad_skip = KernelShape {
            skip: 3,
            ..c.shape.clone()
        };
        assert!(matches!(
            Network::new(&bad_skip, &c.params, &c.first, &c.skip, 2),
            Err(KernelError::Shape(_))
        ));
        let net = Network::new(&c.shape, &c.params, &c.first, &c.skip, 2).unwrap();
        let mut out = vec![0.0; 7];
        assert!(matches!(
            net.forward(&c.points[..15], true, &mut out, None),
            Err(KernelError::Length { what: "points", .. })
        ));
        assert!(matches!(
            net.forward(&c.points, true, &mut out, None),
            Err(KernelError::Length { what: "output", .. })
        ));
    }
}
