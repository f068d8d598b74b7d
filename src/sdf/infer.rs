//! Inference-only forward (and ∇ₓf reverse) pass of [`SdfNetwork`] for one shape, on host
//! arrays with burn-flex's matrix product.
//!
//! The tensor path spends most of its time outside the matrix products: every softplus is
//! four element-wise passes over the activations with scalar `exp`/`ln_1p`, single-threaded.
//! Here each layer is one matrix product followed by one fused pass (bias or latent offset,
//! softplus and, for gradients, its slope) with a branch-free softplus the compiler
//! vectorises; points are split into chunks processed in parallel. The weights are those
//! of the network; the latent's share of layer 0 and of the skip layer is added as one
//! precomputed row. Results agree with [`SdfNetwork::evaluate`] to float rounding.

use std::f32::consts::FRAC_1_SQRT_2;

use burn::module::Module;
use burn::tensor::{Tensor, TensorData};
use burn_flex::FlexTensor;
use rayon::prelude::*;

use super::network::{LatentOffsets, SdfNetwork};
use super::softplus::{BlockKernel, HostFloat, run_vectorized};

/// Points per parallel chunk: the activations of a chunk stay in the outer caches.
const CHUNK: usize = 2048;

/// A matrix `[rows, cols]` as a flex tensor, with its transpose for the reverse pass.
#[derive(Debug, Clone)]
struct Matrix {
    forward: FlexTensor,
    transposed: FlexTensor,
    cols: usize,
}

impl Matrix {
    fn new(values: Vec<f32>, rows: usize, cols: usize) -> Self {
        let mut t = vec![0.0f32; values.len()];
        for r in 0..rows {
            for c in 0..cols {
                t[c * rows + r] = values[r * cols + c];
            }
        }
        Self {
            forward: FlexTensor::from_data(TensorData::new(values, [rows, cols])),
            transposed: FlexTensor::from_data(TensorData::new(t, [cols, rows])),
            cols,
        }
    }
}

/// `a · b` for host rows `a` (`[n, k]`) and a flex matrix `b`.
fn product(a: Vec<f32>, k: usize, b: &FlexTensor) -> Vec<f32> {
    let n = a.len() / k;
    let lhs = FlexTensor::from_data(TensorData::new(a, [n, k]));
    burn_flex::ops::matmul::matmul(lhs, b.clone())
        .into_data()
        .try_into_vec::<f32>()
        .expect("f32 product")
}

/// One hidden layer after the first: `y = h·W + x·W_x + offset` (W and W_x pre-scaled by
/// 1/√2 on the skip layer, `offset` = bias, or the latent offset on the skip layer).
#[derive(Debug, Clone)]
struct Hidden {
    weight: Matrix,
    /// `[3, H]` rows multiplying x (skip layer only).
    x_rows: Option<Vec<f32>>,
    offset: Vec<f32>,
}

/// The network of one shape, ready for host evaluation.
#[derive(Debug, Clone)]
pub struct HostForward {
    beta: f32,
    /// `[3, H₀]`: x rows of layer 0.
    first_x: Vec<f32>,
    /// `[H₀]`: z·W_z + b of layer 0.
    first_offset: Vec<f32>,
    hidden: Vec<Hidden>,
    /// `[H_last]` output weights and the output bias.
    out_weight: Vec<f32>,
    out_bias: f32,
}

fn host(t: Tensor<2>) -> Vec<f32> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .expect("converted to f32")
}

fn host1(t: Tensor<1>) -> Vec<f32> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .expect("converted to f32")
}

impl HostForward {
    /// Copies the weights of `network` and the offsets of one shape (`offsets` with one row).
    pub fn new(network: &SdfNetwork, offsets: &LatentOffsets) -> Self {
        let network = network.valid();
        let d = network.latent_dim;
        let last = network.layers.len() - 1;
        let weight = |l: usize| host(network.layers[l].weight.val());
        let dims = |l: usize| network.layers[l].weight.dims();
        let w0 = weight(0);
        let h0 = dims(0)[1];
        let first_x = w0[d * h0..(d + 3) * h0].to_vec();
        let hidden = (1..last)
            .map(|l| {
                let [rows, cols] = dims(l);
                let w = weight(l);
                if l == network.skip_layer {
                    let c = rows - d - 3;
                    let scale = |s: &[f32]| s.iter().map(|v| v * FRAC_1_SQRT_2).collect();
                    Hidden {
                        weight: Matrix::new(scale(&w[..c * cols]), c, cols),
                        x_rows: Some(scale(&w[(c + d) * cols..])),
                        offset: host(offsets.skip.clone()),
                    }
                } else {
                    let bias = network.layers[l]
                        .bias
                        .as_ref()
                        .expect("SDF layers have biases")
                        .val();
                    Hidden {
                        weight: Matrix::new(w, rows, cols),
                        x_rows: None,
                        offset: host1(bias),
                    }
                }
            })
            .collect();
        let out_bias = host1(
            network.layers[last]
                .bias
                .as_ref()
                .expect("SDF layers have biases")
                .val(),
        )[0];
        Self {
            beta: network.beta as f32,
            first_x,
            first_offset: host(offsets.first.clone()),
            hidden,
            out_weight: weight(last),
            out_bias,
        }
    }

    /// f at `points` into `values` and, when given, ∇ₓf into `gradients`.
    pub fn eval(
        &self,
        points: &[[f32; 3]],
        values: &mut [f32],
        gradients: Option<&mut [[f32; 3]]>,
    ) {
        match gradients {
            Some(g) => points
                .par_chunks(CHUNK)
                .zip(values.par_chunks_mut(CHUNK))
                .zip(g.par_chunks_mut(CHUNK))
                .for_each(|((p, v), g)| run_vectorized(self, 0, (p, v, Some(g)))),
            None => points
                .par_chunks(CHUNK)
                .zip(values.par_chunks_mut(CHUNK))
                .for_each(|(p, v)| run_vectorized(self, 0, (p, v, None))),
        }
    }

    #[inline(always)]
    fn chunk(&self, points: &[[f32; 3]], values: &mut [f32], gradients: Option<&mut [[f32; 3]]>) {
        let want_slopes = gradients.is_some();
        let mut slopes: Vec<Vec<f32>> = Vec::new();
        let width = self.first_offset.len();
        let mut h = vec![0.0f32; points.len() * width];
        for (row, p) in h.chunks_exact_mut(width).zip(points) {
            add_x_rows(row, p, &self.first_x, &self.first_offset);
        }
        let mut width = width;
        for layer in &self.hidden {
            let s = softplus(&mut h, self.beta, want_slopes);
            slopes.extend(s);
            let mut y = product(h, width, &layer.weight.forward);
            width = layer.weight.cols;
            for (row, p) in y.chunks_exact_mut(width).zip(points) {
                match &layer.x_rows {
                    Some(x_rows) => add_x_rows(row, p, x_rows, &layer.offset),
                    None => row.iter_mut().zip(&layer.offset).for_each(|(v, b)| *v += b),
                }
            }
            h = y;
        }
        slopes.extend(softplus(&mut h, self.beta, want_slopes));
        for (v, row) in values.iter_mut().zip(h.chunks_exact(width)) {
            *v = dot(row, &self.out_weight) + self.out_bias;
        }
        if let Some(gradients) = gradients {
            self.gradient(slopes, gradients);
        }
    }

    /// The reverse pass of [`SdfNetwork::evaluate`]: δ ← (δ·Wᵀ) ⊙ σ, x rows into ∇ₓf.
    #[inline(always)]
    fn gradient(&self, mut slopes: Vec<Vec<f32>>, out: &mut [[f32; 3]]) {
        let mut delta = slopes.pop().expect("one slope per hidden layer");
        let width = self.out_weight.len();
        for row in delta.chunks_exact_mut(width) {
            row.iter_mut()
                .zip(&self.out_weight)
                .for_each(|(d, w)| *d *= w);
        }
        out.iter_mut().for_each(|g| *g = [0.0; 3]);
        for layer in self.hidden.iter().rev() {
            let cols = layer.weight.cols;
            if let Some(x_rows) = &layer.x_rows {
                accumulate_x(&delta, cols, x_rows, out);
            }
            let mut back = product(delta, cols, &layer.weight.transposed);
            let slope = slopes.pop().expect("one slope per hidden layer");
            back.iter_mut().zip(&slope).for_each(|(b, s)| *b *= s);
            delta = back;
        }
        accumulate_x(&delta, self.first_offset.len(), &self.first_x, out);
    }
}

/// A chunk of points: (points, values, ∇ₓf), evaluated by [`HostForward::chunk`].
type Chunk<'a> = (&'a [[f32; 3]], &'a mut [f32], Option<&'a mut [[f32; 3]]>);

impl<'a> BlockKernel<Chunk<'a>> for HostForward {
    type Output = ();

    #[inline(always)]
    fn run(&self, _first_row: usize, (points, values, gradients): Chunk<'a>) {
        self.chunk(points, values, gradients);
    }
}

/// `row = offset + x·X` for the `[3, H]` rows `X`.
#[inline(always)]
fn add_x_rows(row: &mut [f32], p: &[f32; 3], x_rows: &[f32], offset: &[f32]) {
    let h = row.len();
    let (a, b, c) = (&x_rows[..h], &x_rows[h..2 * h], &x_rows[2 * h..3 * h]);
    for ((((v, o), a), b), c) in row.iter_mut().zip(offset).zip(a).zip(b).zip(c) {
        *v += o + p[0] * a + p[1] * b + p[2] * c;
    }
}

/// `out[i] += δ_i · Xᵀ` for the `[3, H]` rows `X`.
#[inline(always)]
fn accumulate_x(delta: &[f32], width: usize, x_rows: &[f32], out: &mut [[f32; 3]]) {
    for (g, d) in out.iter_mut().zip(delta.chunks_exact(width)) {
        for (k, gk) in g.iter_mut().enumerate() {
            *gk += dot(d, &x_rows[k * width..(k + 1) * width]);
        }
    }
}

#[inline(always)]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    // Eight partial sums, so the loop vectorises.
    let mut acc = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for ((s, x), y) in acc.iter_mut().zip(x).zip(y) {
            *s += x * y;
        }
    }
    acc.iter().sum::<f32>() + tail
}

/// softplus_β in place; returns σ(βy) (the slope) when asked.
#[inline(always)]
fn softplus(y: &mut [f32], beta: f32, slopes: bool) -> Option<Vec<f32>> {
    let inv_beta = 1.0 / beta;
    if slopes {
        let mut s = vec![0.0f32; y.len()];
        for (v, s) in y.iter_mut().zip(s.iter_mut()) {
            let (softplus, slope) = f32::softplus_unit(beta * *v);
            *s = slope;
            *v = softplus * inv_beta;
        }
        Some(s)
    } else {
        for v in y.iter_mut() {
            *v = f32::softplus_unit(beta * *v).0 * inv_beta;
        }
        None
    }
}

/// Whether `network` can use [`HostForward`] (f32 parameters).
pub fn supported(network: &SdfNetwork) -> bool {
    network.dtype() == burn::tensor::DType::F32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn softplus_matches_the_reference_formula() {
        let beta = 100.0f32;
        let mut y: Vec<f32> = (-400..400).map(|i| i as f32 * 0.0021).collect();
        let reference: Vec<(f32, f32)> = y
            .iter()
            .map(|&v| {
                let t = f64::from(beta * v);
                let sp = (t.max(0.0) + (-t.abs()).exp().ln_1p()) / f64::from(beta);
                (sp as f32, (1.0 / (1.0 + (-t).exp())) as f32)
            })
            .collect();
        let slopes = softplus(&mut y, beta, true).unwrap();
        for ((v, s), (rv, rs)) in y.iter().zip(&slopes).zip(reference) {
            assert!((v - rv).abs() <= 1e-7 + 1e-6 * rv.abs(), "{v} vs {rv}");
            assert!((s - rs).abs() <= 1e-6, "{s} vs {rs}");
        }
    }
}
