//! Softplus_β and its slope σ(βy) on host slices: branch-free scalar approximations the
//! compiler vectorises, and the fused per-layer loops behind the training operations of
//! [`super::fused`] and the inference pass of `infer`.
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

    /// The offset row of `row`.
    fn offset_row<'a, E>(&self, offset: &'a [E], row: usize) -> &'a [E] {
        let g = row / self.group_rows();
        &offset[g * self.width..(g + 1) * self.width]
    }
}

/// Calls `body(first_row, block)` for fixed blocks of `BLOCK_ROWS` rows of `out`, in parallel,
/// and returns what each block returned, in block order.
fn for_blocks<E: Send, R: Send>(
    out: &mut [E],
    width: usize,
    body: impl Fn(usize, &mut [E]) -> R + Sync,
) -> Vec<R> {
    out.par_chunks_mut(BLOCK_ROWS * width)
        .enumerate()
        .map(|(b, block)| body(b * BLOCK_ROWS, block))
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

/// softplus_β(pre + offset) = ln(1 + e^{β(pre+offset)})/β.
pub fn softplus_forward<E: HostFloat>(
    pre: &[E],
    offset: &[E],
    layout: RowGroups,
    beta: f64,
) -> Vec<E> {
    layout.check(pre, offset);
    let (b, inv_b) = (E::of(beta), E::of(1.0 / beta));
    let w = layout.width;
    let mut out = vec![E::ZERO; pre.len()];
    for_blocks(&mut out, w, |first, block| {
        for (i, row) in block.chunks_exact_mut(w).enumerate() {
            let r = first + i;
            let off = layout.offset_row(offset, r);
            let p = &pre[r * w..(r + 1) * w];
            for ((o, &p), &c) in row.iter_mut().zip(p).zip(off) {
                *o = E::softplus_unit(b * (p + c)).0 * inv_b;
            }
        }
    });
    out
}

/// Gradients of [`softplus_forward`] given the output gradient `grad`: `(∂pre, ∂offset)`.
pub fn softplus_backward<E: HostFloat>(
    grad: &[E],
    pre: &[E],
    offset: &[E],
    layout: RowGroups,
    beta: f64,
) -> (Vec<E>, Vec<E>) {
    layout.check(pre, offset);
    assert_eq!(grad.len(), pre.len(), "gradient size");
    let b = E::of(beta);
    let w = layout.width;
    let mut grad_pre = vec![E::ZERO; pre.len()];
    let partials = for_blocks(&mut grad_pre, w, |first, block| {
        let mut partial = vec![E::ZERO; offset.len()];
        for (i, row) in block.chunks_exact_mut(w).enumerate() {
            let r = first + i;
            let g0 = (r / layout.group_rows()) * w;
            let off = &offset[g0..g0 + w];
            let acc = &mut partial[g0..g0 + w];
            let (p, g) = (&pre[r * w..(r + 1) * w], &grad[r * w..(r + 1) * w]);
            for ((((o, &p), &c), &g), a) in row.iter_mut().zip(p).zip(off).zip(g).zip(acc) {
                let v = g * E::sigmoid(b * (p + c));
                *o = v;
                *a += v;
            }
        }
        partial
    });
    (
        grad_pre,
        sum_partials(partials.iter().map(Vec::as_slice), offset.len()),
    )
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
    layout.check(pre, offset);
    let broadcast = check_gate_input(u, layout);
    let b = E::of(beta);
    let w = layout.width;
    let mut out = vec![E::ZERO; pre.len()];
    for_blocks(&mut out, w, |first, block| {
        for (i, row) in block.chunks_exact_mut(w).enumerate() {
            let r = first + i;
            let off = layout.offset_row(offset, r);
            let p = &pre[r * w..(r + 1) * w];
            let u = if broadcast { u } else { &u[r * w..(r + 1) * w] };
            for (((o, &p), &c), &u) in row.iter_mut().zip(p).zip(off).zip(u) {
                *o = u * E::sigmoid(b * (p + c));
            }
        }
    });
    out
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
    layout.check(pre, offset);
    assert_eq!(grad.len(), pre.len(), "gradient size");
    let broadcast = check_gate_input(u, layout);
    let b = E::of(beta);
    let w = layout.width;
    let mut grad_pre = vec![E::ZERO; pre.len()];
    let block_len = BLOCK_ROWS * w;
    // ∂u storage per block: its rows of ∂u, or for a broadcast u one partial row per block
    // (summed in block order below).
    let (mut du_store, du_len) = if broadcast {
        (vec![E::ZERO; pre.len().div_ceil(block_len) * w], w)
    } else {
        (vec![E::ZERO; pre.len()], block_len)
    };
    let offset_partials: Vec<Vec<E>> = grad_pre
        .par_chunks_mut(block_len)
        .zip(du_store.par_chunks_mut(du_len))
        .enumerate()
        .map(|(b_idx, (block, du))| {
            let first = b_idx * BLOCK_ROWS;
            gate_block(grad, u, pre, offset, layout, b, first, block, du, broadcast)
        })
        .collect();
    let grad_u = if broadcast {
        sum_partials(du_store.chunks(w), w)
    } else {
        du_store
    };
    (
        grad_u,
        grad_pre,
        sum_partials(offset_partials.iter().map(Vec::as_slice), offset.len()),
    )
}

/// One block of [`gate_backward`]; returns its partial offset gradient.
#[allow(clippy::too_many_arguments)]
fn gate_block<E: HostFloat>(
    grad: &[E],
    u: &[E],
    pre: &[E],
    offset: &[E],
    layout: RowGroups,
    beta: E,
    first: usize,
    block: &mut [E],
    du: &mut [E],
    broadcast: bool,
) -> Vec<E> {
    let w = layout.width;
    let mut partial = vec![E::ZERO; offset.len()];
    for (i, row) in block.chunks_exact_mut(w).enumerate() {
        let r = first + i;
        let g0 = (r / layout.group_rows()) * w;
        let off = &offset[g0..g0 + w];
        let acc = &mut partial[g0..g0 + w];
        let (p, g) = (&pre[r * w..(r + 1) * w], &grad[r * w..(r + 1) * w]);
        // ∂u accumulates: over all rows for a broadcast u, once into a zeroed row otherwise.
        let (u, du) = if broadcast {
            (u, &mut du[..])
        } else {
            (&u[r * w..(r + 1) * w], &mut du[i * w..(i + 1) * w])
        };
        for (((((o, &p), &c), &g), a), (&u, d)) in row
            .iter_mut()
            .zip(p)
            .zip(off)
            .zip(g)
            .zip(acc.iter_mut())
            .zip(u.iter().zip(du.iter_mut()))
        {
            let s = E::sigmoid(beta * (p + c));
            let gs = g * s;
            *d += gs;
            let v = gs * u * beta * (E::ONE - s);
            *o = v;
            *a += v;
        }
    }
    partial
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
