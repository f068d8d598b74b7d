//! Softplus_β and its slope σ(βy) on host slices: branch-free scalar approximations the
//! compiler vectorises, and the fused per-layer loops behind the operations of
//! [`crate::sdf::model::fused`] (the composed network, the reference for [`crate::sdf::kernels::passes`], which uses
//! the same scalar functions).
//!
//! A hidden layer's pre-activation is `pre + offset`, where `offset` has one row per group of
//! consecutive rows (the per-shape latent offsets of layer 0 and of the skip layer, with
//! `groups` = shapes) or a single row (a bias, `groups` = 1). Every loop here reads `pre` and
//! the offset once, evaluates one exponential per element and writes its outputs once, in
//! parallel over fixed blocks of rows. Reductions (offset and broadcast gradients) sum
//! per-block partials in block order, so results do not depend on the thread count.

use std::f32::consts::LOG2_E;

use rayon::prelude::*;

/// Rows per parallel block: big enough to amortise scheduling, small enough to balance.
const BLOCK_ROWS: usize = 256;

/// A float type the fused loops run on: f32 with the vectorisable approximations below,
/// f64 with the standard library (exact references for finite-difference tests).
pub trait HostFloat:
    Copy
    + Send
    + Sync
    + PartialOrd
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::AddAssign
    + 'static
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// The value of an f64 constant.
    fn of(v: f64) -> Self;
    /// (ln(1 + eᵗ), σ(t)) from one exponential.
    fn softplus_unit(t: Self) -> (Self, Self);
    /// σ(t).
    fn sigmoid(t: Self) -> Self;
}

impl HostFloat for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn of(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    fn softplus_unit(t: f32) -> (f32, f32) {
        let e = exp_neg(t.abs());
        let inv = 1.0 / (1.0 + e);
        let s = if t >= 0.0 { inv } else { e * inv };
        (t.max(0.0) + ln_1p_unit(e), s)
    }
    #[inline(always)]
    fn sigmoid(t: f32) -> f32 {
        let e = exp_neg(t.abs());
        let inv = 1.0 / (1.0 + e);
        if t >= 0.0 { inv } else { e * inv }
    }
}

impl HostFloat for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn of(v: f64) -> Self {
        v
    }
    fn softplus_unit(t: f64) -> (f64, f64) {
        let e = (-t.abs()).exp();
        let s = if t >= 0.0 {
            1.0 / (1.0 + e)
        } else {
            e / (1.0 + e)
        };
        (t.max(0.0) + e.ln_1p(), s)
    }
    fn sigmoid(t: f64) -> f64 {
        Self::softplus_unit(t).1
    }
}

/// Below e^(−EXP_CUTOFF) the exponential is flushed to 0, so that neither it nor softplus/β
/// nor the slope becomes a subnormal float (subnormal arithmetic is many times slower, in
/// these loops and in the matrix products that consume their outputs).
pub const EXP_CUTOFF: f32 = 75.0;

/// e^(−a) for a ≥ 0 (0 beyond [`EXP_CUTOFF`]), branch-free and vectorisable.
#[inline(always)]
pub fn exp_neg(a: f32) -> f32 {
    let x = (-a).max(-EXP_CUTOFF);
    // Round x·log₂e to the nearest integer n with the 1.5·2²³ trick: the sum's low mantissa
    // bits then hold n, read as integer bits (no float-to-int conversion, which would not
    // vectorise); e^x = 2ⁿ·e^r with |r| ≤ ln2/2.
    const MAGIC: f32 = 12_582_912.0;
    let shifted = x * LOG2_E + MAGIC;
    let n = shifted - MAGIC;
    let n_int = shifted.to_bits().wrapping_sub(MAGIC.to_bits());
    let r = x - n * 0.693_145_75 - n * 1.428_606_8e-6;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0
                    + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r / 5040.0))))));
    let scale = f32::from_bits(n_int.wrapping_add(127) << 23);
    let e = p * scale;
    if a >= EXP_CUTOFF { 0.0 } else { e }
}

/// ln(1 + e) for e ∈ [0, 1], as 2·atanh(s), s = e/(2+e) ≤ 1/3 (series to s¹⁹); ln(1 + e) = e
/// to float precision below 2⁻²⁶, where the series is skipped (its powers would underflow).
#[inline(always)]
pub fn ln_1p_unit(e: f32) -> f32 {
    const TINY: f32 = 1.0 / 67_108_864.0;
    let s = e.max(TINY) / (2.0 + e);
    let s2 = s * s;
    let series = 1.0
        + s2 * (1.0 / 3.0
            + s2 * (1.0 / 5.0
                + s2 * (1.0 / 7.0
                    + s2 * (1.0 / 9.0
                        + s2 * (1.0 / 11.0
                            + s2 * (1.0 / 13.0
                                + s2 * (1.0 / 15.0 + s2 * (1.0 / 17.0 + s2 / 19.0))))))));
    if e < TINY { e } else { 2.0 * s * series }
}

/// Row layout shared by the fused loops: `rows` rows of `width`, offset row `r / group_rows`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RowGroups {
    /// Total rows.
    pub rows: usize,
    /// Columns.
    pub width: usize,
    /// Offset rows (groups of equal size; 1 for a bias).
    pub groups: usize,
}

impl RowGroups {
    /// Rows per group.
    #[inline(always)]
    pub fn group_rows(&self) -> usize {
        self.rows / self.groups
    }

    /// Checks that `pre` and `offset` lengths fit the layout.
    fn check<E>(&self, pre: &[E], offset: &[E]) {
        assert!(
            self.groups > 0 && self.rows.is_multiple_of(self.groups),
            "{} rows do not split into {} groups",
            self.rows,
            self.groups
        );
        assert_eq!(pre.len(), self.rows * self.width, "pre-activation size");
        assert_eq!(offset.len(), self.groups * self.width, "offset size");
    }
}

/// A loop over one block of rows, run by `for_blocks` compiled for the CPU's widest vector
/// instructions. `B` is what the block owns (its rows of the outputs).
///
/// The portable build targets baseline x86-64 (SSE2), where these loops run at half the width
/// AVX2 allows; pulp picks AVX2 + FMA (or AVX-512 with `x86-v4`) at run time and compiles
/// [`pulp::WithSimd::with_simd`] for it. Only what is inlined into that function profits, so
/// every `run` is `#[inline(always)]` and so is everything it calls.
pub trait BlockKernel<B>: Sync {
    /// What one block returns (partial reductions).
    type Output: Send;
    /// Processes the rows `first_row..` held by `block`.
    fn run(&self, first_row: usize, block: B) -> Self::Output;
}

/// One block of a [`BlockKernel`] as a pulp operation.
struct OnBlock<'k, K, B> {
    kernel: &'k K,
    first_row: usize,
    block: B,
}

impl<K: BlockKernel<B>, B> pulp::WithSimd for OnBlock<'_, K, B> {
    type Output = K::Output;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> K::Output {
        self.kernel.run(self.first_row, self.block)
    }
}

/// Runs `kernel` on one block with the CPU's widest vector instructions.
#[inline(always)]
pub fn run_vectorized<K: BlockKernel<B>, B>(kernel: &K, first_row: usize, block: B) -> K::Output {
    pulp::Arch::new().dispatch(OnBlock {
        kernel,
        first_row,
        block,
    })
}

/// Runs `kernel` on fixed blocks of `BLOCK_ROWS` rows of `out`, in parallel, and returns what
/// each block returned, in block order.
fn for_blocks<'a, E: Send, K: BlockKernel<&'a mut [E]>>(
    out: &'a mut [E],
    width: usize,
    kernel: &K,
) -> Vec<K::Output> {
    out.par_chunks_mut(BLOCK_ROWS * width)
        .enumerate()
        .map(|(b, block)| run_vectorized(kernel, b * BLOCK_ROWS, block))
        .collect()
}

/// Sums per-block `[groups·width]` partials in block order.
fn sum_partials<'a, E: HostFloat>(
    partials: impl IntoIterator<Item = &'a [E]>,
    len: usize,
) -> Vec<E> {
    let mut total = vec![E::ZERO; len];
    for p in partials {
        total.iter_mut().zip(p).for_each(|(t, &v)| *t += v);
    }
    total
}

/// The inputs every layer loop reads: `pre`, the offset rows and β.
#[derive(Clone, Copy)]
struct LayerInputs<'a, E> {
    pre: &'a [E],
    offset: &'a [E],
    layout: RowGroups,
    beta: E,
    inv_beta: E,
}

impl<'a, E: HostFloat> LayerInputs<'a, E> {
    fn new(pre: &'a [E], offset: &'a [E], layout: RowGroups, beta: f64) -> Self {
        layout.check(pre, offset);
        Self {
            pre,
            offset,
            layout,
            beta: E::of(beta),
            inv_beta: E::of(1.0 / beta),
        }
    }

    /// Row `r` of `pre` and its offset row, with the offset row's start.
    #[inline(always)]
    fn row(&self, r: usize) -> (&'a [E], &'a [E], usize) {
        let w = self.layout.width;
        let g0 = (r / self.layout.group_rows()) * w;
        (&self.pre[r * w..(r + 1) * w], &self.offset[g0..g0 + w], g0)
    }
}

/// softplus_β(pre + offset) = ln(1 + e^{β(pre+offset)})/β.
pub fn softplus_forward<E: HostFloat>(
    pre: &[E],
    offset: &[E],
    layout: RowGroups,
    beta: f64,
) -> Vec<E> {
    let inputs = LayerInputs::new(pre, offset, layout, beta);
    let mut out = vec![E::ZERO; pre.len()];
    for_blocks(&mut out, layout.width, &SoftplusKernel(inputs));
    out
}

struct SoftplusKernel<'a, E>(LayerInputs<'a, E>);

impl<E: HostFloat> BlockKernel<&mut [E]> for SoftplusKernel<'_, E> {
    type Output = ();

    #[inline(always)]
    fn run(&self, first: usize, block: &mut [E]) {
        let x = &self.0;
        let (b, inv_b) = (x.beta, x.inv_beta);
        for (i, row) in block.chunks_exact_mut(x.layout.width).enumerate() {
            let (p, off, _) = x.row(first + i);
            for ((o, &p), &c) in row.iter_mut().zip(p).zip(off) {
                *o = E::softplus_unit(b * (p + c)).0 * inv_b;
            }
        }
    }
}

/// Gradients of [`softplus_forward`] given the output gradient `grad`: `(∂pre, ∂offset)`.
pub fn softplus_backward<E: HostFloat>(
    grad: &[E],
    pre: &[E],
    offset: &[E],
    layout: RowGroups,
    beta: f64,
) -> (Vec<E>, Vec<E>) {
    let mut grad_pre = grad.to_vec();
    let grad_offset = softplus_backward_in_place(&mut grad_pre, pre, offset, layout, beta);
    (grad_pre, grad_offset)
}

/// [`softplus_backward`] overwriting the output gradient with ∂pre (no new activation-sized
/// buffer); returns ∂offset.
pub fn softplus_backward_in_place<E: HostFloat>(
    grad: &mut [E],
    pre: &[E],
    offset: &[E],
    layout: RowGroups,
    beta: f64,
) -> Vec<E> {
    let inputs = LayerInputs::new(pre, offset, layout, beta);
    assert_eq!(grad.len(), pre.len(), "gradient size");
    let partials = for_blocks(grad, layout.width, &SoftplusBackwardKernel(inputs));
    sum_partials(partials.iter().map(Vec::as_slice), offset.len())
}

struct SoftplusBackwardKernel<'a, E>(LayerInputs<'a, E>);

impl<E: HostFloat> BlockKernel<&mut [E]> for SoftplusBackwardKernel<'_, E> {
    type Output = Vec<E>;

    #[inline(always)]
    fn run(&self, first: usize, block: &mut [E]) -> Vec<E> {
        let x = &self.0;
        let w = x.layout.width;
        let mut partial = vec![E::ZERO; x.offset.len()];
        for (i, g) in block.chunks_exact_mut(w).enumerate() {
            let (p, off, g0) = x.row(first + i);
            let acc = &mut partial[g0..g0 + w];
            for (((g, &p), &c), a) in g.iter_mut().zip(p).zip(off).zip(acc) {
                let v = *g * E::sigmoid(x.beta * (p + c));
                *g = v;
                *a += v;
            }
        }
        partial
    }
}

/// u ⊙ σ(β(pre + offset)): one step of the reverse pass for ∇ₓf. `u` has one row per row of
/// `pre`, or a single row broadcast over all rows (the output layer's weights).
pub fn gate_forward<E: HostFloat>(
    u: &[E],
    pre: &[E],
    offset: &[E],
    layout: RowGroups,
    beta: f64,
) -> Vec<E> {
    let inputs = LayerInputs::new(pre, offset, layout, beta);
    let broadcast = check_gate_input(u, layout);
    let mut out = vec![E::ZERO; pre.len()];
    for_blocks(
        &mut out,
        layout.width,
        &GateKernel {
            inputs,
            u,
            broadcast,
        },
    );
    out
}

struct GateKernel<'a, E> {
    inputs: LayerInputs<'a, E>,
    u: &'a [E],
    broadcast: bool,
}

impl<E: HostFloat> BlockKernel<&mut [E]> for GateKernel<'_, E> {
    type Output = ();

    #[inline(always)]
    fn run(&self, first: usize, block: &mut [E]) {
        let x = &self.inputs;
        let w = x.layout.width;
        for (i, row) in block.chunks_exact_mut(w).enumerate() {
            let r = first + i;
            let (p, off, _) = x.row(r);
            let u = if self.broadcast {
                self.u
            } else {
                &self.u[r * w..(r + 1) * w]
            };
            for (((o, &p), &c), &u) in row.iter_mut().zip(p).zip(off).zip(u) {
                *o = u * E::sigmoid(x.beta * (p + c));
            }
        }
    }
}

/// Whether `u` is a broadcast row; panics when it fits neither form.
fn check_gate_input<E>(u: &[E], layout: RowGroups) -> bool {
    let broadcast = u.len() == layout.width && layout.rows != 1;
    assert!(
        broadcast || u.len() == layout.rows * layout.width,
        "gate input has {} values for {} rows of {}",
        u.len(),
        layout.rows,
        layout.width
    );
    broadcast
}

/// Gradients of [`gate_forward`] given the output gradient `grad`: `(∂u, ∂pre, ∂offset)`,
/// with ∂u summed over rows when `u` was broadcast. With s = σ(β(pre+offset)):
/// ∂u = grad ⊙ s and ∂pre = grad ⊙ u ⊙ β·s(1 − s).
pub fn gate_backward<E: HostFloat>(
    grad: &[E],
    u: &[E],
    pre: &[E],
    offset: &[E],
    layout: RowGroups,
    beta: f64,
) -> (Vec<E>, Vec<E>, Vec<E>) {
    let (mut grad_pre, mut grad_u) = (grad.to_vec(), u.to_vec());
    let grad_offset = gate_backward_in_place(&mut grad_pre, &mut grad_u, pre, offset, layout, beta);
    (grad_u, grad_pre, grad_offset)
}

/// [`gate_backward`] in place: `grad` becomes ∂pre and `u` becomes ∂u (a broadcast row its
/// sum over rows); returns ∂offset.
pub fn gate_backward_in_place<E: HostFloat>(
    grad: &mut [E],
    u: &mut [E],
    pre: &[E],
    offset: &[E],
    layout: RowGroups,
    beta: f64,
) -> Vec<E> {
    let inputs = LayerInputs::new(pre, offset, layout, beta);
    assert_eq!(grad.len(), pre.len(), "gradient size");
    let w = layout.width;
    let block_len = BLOCK_ROWS * w;
    let broadcast = check_gate_input(u, layout);
    let partials: Vec<(Vec<E>, Vec<E>)> = if broadcast {
        // Every block reads the one row of u and sums its own partial ∂u.
        let kernel = GateBackwardKernel { inputs, u: &*u };
        grad.par_chunks_mut(block_len)
            .enumerate()
            .map(|(b, g)| run_vectorized(&kernel, b * BLOCK_ROWS, GateRows::Broadcast(g)))
            .collect()
    } else {
        let kernel = GateBackwardKernel { inputs, u: &[] };
        grad.par_chunks_mut(block_len)
            .zip(u.par_chunks_mut(block_len))
            .enumerate()
            .map(|(b, (g, u))| run_vectorized(&kernel, b * BLOCK_ROWS, GateRows::PerRow(g, u)))
            .collect()
    };
    if broadcast {
        u.copy_from_slice(&sum_partials(
            partials.iter().map(|(du, _)| du.as_slice()),
            w,
        ));
    }
    sum_partials(partials.iter().map(|(_, off)| off.as_slice()), offset.len())
}

/// (∂u, ∂pre) of one element of the gate for output gradient `g` at t = β(pre + offset):
/// with s = σ(t), ∂u = g·s and ∂pre = g·u·β·s(1 − s).
#[inline(always)]
fn gate_step<E: HostFloat>(g: E, u: E, t: E, beta: E) -> (E, E) {
    let s = E::sigmoid(t);
    let gs = g * s;
    (gs, gs * u * beta * (E::ONE - s))
}

/// The rows of one [`gate_backward_in_place`] block: the output gradient (→ ∂pre) and, unless
/// u is a broadcast row, the same rows of u (→ ∂u).
enum GateRows<'a, E> {
    Broadcast(&'a mut [E]),
    PerRow(&'a mut [E], &'a mut [E]),
}

struct GateBackwardKernel<'a, E> {
    inputs: LayerInputs<'a, E>,
    /// The broadcast row of u (empty when u is per row).
    u: &'a [E],
}

impl<E: HostFloat> BlockKernel<GateRows<'_, E>> for GateBackwardKernel<'_, E> {
    /// (partial ∂u of a broadcast u, or empty; partial ∂offset)
    type Output = (Vec<E>, Vec<E>);

    #[inline(always)]
    fn run(&self, first: usize, rows: GateRows<'_, E>) -> (Vec<E>, Vec<E>) {
        let x = &self.inputs;
        let (w, beta) = (x.layout.width, x.beta);
        let mut offset_partial = vec![E::ZERO; x.offset.len()];
        match rows {
            GateRows::Broadcast(grad) => {
                let mut du = vec![E::ZERO; w];
                for (i, g) in grad.chunks_exact_mut(w).enumerate() {
                    let (p, off, g0) = x.row(first + i);
                    let acc = &mut offset_partial[g0..g0 + w];
                    for (((((g, &p), &c), a), &u), d) in g
                        .iter_mut()
                        .zip(p)
                        .zip(off)
                        .zip(acc)
                        .zip(self.u)
                        .zip(du.iter_mut())
                    {
                        let (du_v, dp) = gate_step(*g, u, beta * (p + c), beta);
                        *d += du_v;
                        *g = dp;
                        *a += dp;
                    }
                }
                (du, offset_partial)
            }
            GateRows::PerRow(grad, u) => {
                for (i, (g, u)) in grad
                    .chunks_exact_mut(w)
                    .zip(u.chunks_exact_mut(w))
                    .enumerate()
                {
                    let (p, off, g0) = x.row(first + i);
                    let acc = &mut offset_partial[g0..g0 + w];
                    for ((((g, u), &p), &c), a) in g.iter_mut().zip(u).zip(p).zip(off).zip(acc) {
                        let (du_v, dp) = gate_step(*g, *u, beta * (p + c), beta);
                        *u = du_v;
                        *g = dp;
                        *a += dp;
                    }
                }
                (Vec::new(), offset_partial)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::LN_2;

    #[test]
    fn exp_and_log1p_approximations_are_accurate() {
        let mut a = 0.0f32;
        while a < 100.0 {
            let (ours, std) = (exp_neg(a), (-a).exp());
            if a >= EXP_CUTOFF {
                assert_eq!(ours, 0.0, "exp(-{a}) is flushed");
            } else {
                assert!(ours >= f32::MIN_POSITIVE, "exp(-{a}) = {ours} is normal");
                assert!(
                    (ours - std).abs() <= 4e-7 * std,
                    "exp(-{a}): {ours} vs {std}"
                );
            }
            let e = (-a).exp();
            let (ours, std) = (ln_1p_unit(e), e.ln_1p());
            assert!(
                (ours - std).abs() <= 4e-7 * std + 1e-38,
                "ln1p({e}): {ours} vs {std}"
            );
            a += 0.0137;
        }
        assert_eq!(exp_neg(0.0), 1.0);
        assert!((ln_1p_unit(1.0) - LN_2).abs() < 1e-7);
    }

    #[test]
    fn f32_softplus_and_slope_match_f64() {
        let mut t = -120.0f64;
        while t < 120.0 {
            let (sp, s) = f32::softplus_unit(t as f32);
            let (rsp, rs) = f64::softplus_unit(t);
            assert!(
                (f64::from(sp) - rsp).abs() <= 1e-6 * (1.0 + rsp.abs()),
                "sp({t})"
            );
            assert!((f64::from(s) - rs).abs() <= 1e-6, "σ({t})");
            assert_eq!(f32::sigmoid(t as f32), s);
            t += 0.0731;
        }
    }

    /// Random inputs for a layout, deterministic.
    fn values(n: usize, seed: u64, scale: f64) -> Vec<f64> {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n).map(|_| rng.random_range(-scale..scale)).collect()
    }

    /// A layout with several blocks and groups that straddle block boundaries.
    const LAYOUT: RowGroups = RowGroups {
        rows: 3 * 250,
        width: 5,
        groups: 3,
    };
    const BETA: f64 = 100.0;

    /// Sum of `weights ⊙ f(x)` (a scalar whose gradient is the backward with grad = weights).
    fn dot(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }

    #[test]
    fn softplus_backward_matches_central_differences() {
        let l = LAYOUT;
        let (pre, off) = (
            values(l.rows * l.width, 1, 0.03),
            values(l.groups * l.width, 2, 0.03),
        );
        let weights = values(l.rows * l.width, 3, 1.0);
        let loss = |pre: &[f64], off: &[f64]| dot(&weights, &softplus_forward(pre, off, l, BETA));
        let (d_pre, d_off) = softplus_backward(&weights, &pre, &off, l, BETA);
        let h = 1e-7;
        for &i in &[0, 7, 1999, l.rows * l.width - 1] {
            let (mut p, mut m) = (pre.clone(), pre.clone());
            p[i] += h;
            m[i] -= h;
            let fd = (loss(&p, &off) - loss(&m, &off)) / (2.0 * h);
            assert!(
                (fd - d_pre[i]).abs() < 1e-6 * (1.0 + fd.abs()),
                "pre[{i}]: {fd} vs {}",
                d_pre[i]
            );
        }
        for i in 0..off.len() {
            let (mut p, mut m) = (off.clone(), off.clone());
            p[i] += h;
            m[i] -= h;
            let fd = (loss(&pre, &p) - loss(&pre, &m)) / (2.0 * h);
            assert!(
                (fd - d_off[i]).abs() < 1e-6 * (1.0 + fd.abs()),
                "off[{i}]: {fd} vs {}",
                d_off[i]
            );
        }
    }

    #[test]
    fn gate_backward_matches_central_differences_per_row_and_broadcast() {
        let l = LAYOUT;
        let (pre, off) = (
            values(l.rows * l.width, 4, 0.03),
            values(l.groups * l.width, 5, 0.03),
        );
        let weights = values(l.rows * l.width, 6, 1.0);
        for u in [values(l.rows * l.width, 7, 1.0), values(l.width, 8, 1.0)] {
            let loss = |u: &[f64], pre: &[f64], off: &[f64]| {
                dot(&weights, &gate_forward(u, pre, off, l, BETA))
            };
            let (d_u, d_pre, d_off) = gate_backward(&weights, &u, &pre, &off, l, BETA);
            assert_eq!(d_u.len(), u.len());
            let h = 1e-7;
            let fd = |which: usize, i: usize| {
                let mut args = [u.clone(), pre.clone(), off.clone()];
                args[which][i] += h;
                let plus = loss(&args[0], &args[1], &args[2]);
                args[which][i] -= 2.0 * h;
                let minus = loss(&args[0], &args[1], &args[2]);
                (plus - minus) / (2.0 * h)
            };
            for (which, analytic) in [(0, &d_u), (1, &d_pre), (2, &d_off)] {
                let n = analytic.len();
                for i in [0, n / 3, n / 2 + 1, n - 1] {
                    let f = fd(which, i);
                    assert!(
                        (f - analytic[i]).abs() < 1e-6 * (1.0 + f.abs()),
                        "argument {which}[{i}] (u of {}): {f} vs {}",
                        u.len(),
                        analytic[i]
                    );
                }
            }
        }
    }

    #[test]
    fn reductions_do_not_depend_on_the_thread_count() {
        let l = RowGroups {
            rows: 4096,
            width: 64,
            groups: 8,
        };
        let f = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect::<Vec<f32>>();
        let (pre, off) = (
            f(values(l.rows * l.width, 9, 0.03)),
            f(values(l.groups * l.width, 10, 0.03)),
        );
        let (grad, u) = (
            f(values(l.rows * l.width, 11, 1.0)),
            f(values(l.width, 12, 1.0)),
        );
        let run = || gate_backward(&grad, &u, &pre, &off, l, BETA);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let three = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        assert_eq!(one.install(run), three.install(run));
    }
}
