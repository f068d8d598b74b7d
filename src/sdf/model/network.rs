//! The DeepSDF / IGR network f(z; x) and its input gradient ∇ₓf as ordinary tensor operations.
//!
//! Layout (DESIGN §2, identical to the reference `sdf_net.py`): input `[z ‖ x]` (z ∈ R^d,
//! x ∈ R³), `hidden_layers` linear layers of width H with softplus(β), the input re-concatenated
//! (scaled by 1/√2) in front of layer `skip_layer`, and a linear output layer → 1 value.
//! The layer before the skip outputs H − (d+3) features when H > d+3; otherwise it keeps width H
//! and the skip layer takes H + d + 3 inputs.
//!
//! Weights are `[d_in, d_out]` (y = x·W + b). The rows of layer 0 and of the skip layer that
//! multiply z are the same for every point of a shape, so their product with z is computed once
//! per shape ([`LatentOffsets`]) and broadcast over the shape's points — in training and in
//! inference alike; that is the same function with fewer operations.
//!
//! burn's autodiff is first order only, so ∇ₓf (needed inside the IGR loss) is computed by a
//! hand-written reverse pass: with δ_l = ∂f/∂y_l, δ_{L−1} = σ(βy_{L−1}) ⊙ w_Lᵀ and
//! δ_{l−1} = σ(βy_{l−1}) ⊙ (δ_l W_lᵀ), splitting the skip layer's rows into the activation part
//! (propagated further) and the x part (added to ∇ₓf). Autodiff over these operations then gives
//! every parameter gradient of a loss that contains ∇ₓf.

use std::f64::consts::{FRAC_1_SQRT_2, PI};

use burn::config::Config;
use burn::module::{Module, Param};
use burn::nn::Linear;
use burn::tensor::{DType, Device, Tensor, TensorData};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::sdf::kernels::passes::KernelShape;
use crate::sdf::model::fused::{gate, softplus_offset};
use crate::sdf::model::network_op::{self, NetworkSpec};

/// Architecture and initialisation of the SDF network (defaults: the paper's configuration).
#[derive(Config, Debug)]
pub struct SdfNetworkConfig {
    /// Latent size d.
    #[config(default = 256)]
    pub latent_dim: usize,
    /// Hidden width H.
    #[config(default = 512)]
    pub hidden: usize,
    /// Number of hidden (softplus) layers before the linear output layer.
    #[config(default = 8)]
    pub hidden_layers: usize,
    /// Index (0-based) of the layer that receives the re-concatenated input.
    #[config(default = 4)]
    pub skip_layer: usize,
    /// Softplus sharpness β (IGR: 100).
    #[config(default = 100.0)]
    pub beta: f64,
    /// Radius r of the sphere f ≈ ‖x‖ − r that the geometric initialisation starts from.
    /// 0.5 rather than IGR's 1.0: shapes are normalised so that their farthest vertex lies on
    /// the unit sphere, so the start should cut through the typical shape. Unlike IGR the
    /// output bias is then calibrated so that the mean of f over the sphere of radius r is 0:
    /// with softplus (β = 100) every unit carries an offset ln 2/β that IGR's bias −r ignores,
    /// and at H = 512 this shifts f(0) from −r to ≈ −r + 0.45 (also in the PyTorch reference),
    /// so IGR's "radius 1" actually starts as a blob of radius ≈ 0.5.
    #[config(default = 0.5)]
    pub radius_init: f64,
}

/// Why a network configuration is unusable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NetworkConfigError {
    /// Width, latent size or depth is zero.
    #[error("network {0} must be at least 1")]
    Zero(&'static str),
    /// The skip layer must be a hidden layer after the first one.
    #[error("skip_layer {skip} must lie in 1..{hidden_layers} (hidden_layers)")]
    SkipOutOfRange {
        /// Requested skip index.
        skip: usize,
        /// Number of hidden layers.
        hidden_layers: usize,
    },
}

impl SdfNetworkConfig {
    /// Checks the sizes before any tensor is allocated.
    pub fn validate(&self) -> Result<(), NetworkConfigError> {
        for (name, v) in [
            ("latent_dim", self.latent_dim),
            ("hidden", self.hidden),
            ("hidden_layers", self.hidden_layers),
        ] {
            if v == 0 {
                return Err(NetworkConfigError::Zero(name));
            }
        }
        if self.skip_layer == 0 || self.skip_layer >= self.hidden_layers {
            return Err(NetworkConfigError::SkipOutOfRange {
                skip: self.skip_layer,
                hidden_layers: self.hidden_layers,
            });
        }
        Ok(())
    }

    /// `(d_in, d_out)` of every linear layer, output layer last.
    pub fn layer_dims(&self) -> Vec<(usize, usize)> {
        let d_in = self.latent_dim + 3;
        let subtracts = self.hidden > d_in;
        let mut dims = Vec::with_capacity(self.hidden_layers + 1);
        let mut input = d_in;
        for l in 0..=self.hidden_layers {
            let mut out = if l == self.hidden_layers {
                1
            } else {
                self.hidden
            };
            if l + 1 == self.skip_layer && subtracts {
                out -= d_in;
            }
            dims.push((input, out));
            input = if l + 1 == self.skip_layer {
                out + d_in
            } else {
                out
            };
        }
        dims
    }

    /// Builds the network with IGR's geometric initialisation (f ≈ ‖x‖ − r), latent rows of
    /// layer 0 and of the skip layer zeroed, f32 parameters. Seeded on the host (ChaCha8), so
    /// the weights are identical on every backend and platform.
    pub fn init(&self, seed: u64, device: &Device) -> Result<SdfNetwork, NetworkConfigError> {
        self.init_with_dtype(seed, device, DType::F32)
    }

    /// [`Self::init`] with an explicit float dtype (f64 for exact finite-difference checks).
    pub fn init_with_dtype(
        &self,
        seed: u64,
        device: &Device,
        dtype: DType,
    ) -> Result<SdfNetwork, NetworkConfigError> {
        self.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let dims = self.layer_dims();
        let last = dims.len() - 1;
        let d = self.latent_dim;
        let layers = dims
            .iter()
            .enumerate()
            .map(|(l, &(d_in, d_out))| {
                let (mean, std, bias) = if l == last {
                    ((PI.sqrt() / (d_in as f64).sqrt()), 1e-5, -self.radius_init)
                } else {
                    (0.0, 2f64.sqrt() / (d_out as f64).sqrt(), 0.0)
                };
                let normal = Normal::new(mean, std).expect("finite positive std");
                let mut w: Vec<f64> = (0..d_in * d_out).map(|_| normal.sample(&mut rng)).collect();
                let latent_rows = match l {
                    0 => Some(0),
                    l if l == self.skip_layer => Some(d_in - d - 3),
                    _ => None,
                };
                if let Some(start) = latent_rows {
                    w[start * d_out..(start + d) * d_out].fill(0.0);
                }
                let weight = TensorData::new(w, [d_in, d_out]);
                let bias = TensorData::new(vec![bias; d_out], [d_out]);
                Linear {
                    weight: Param::from_tensor(Tensor::from_data(weight, (device, dtype))),
                    bias: Some(Param::from_tensor(Tensor::from_data(bias, (device, dtype)))),
                }
            })
            .collect();
        let network = SdfNetwork {
            layers,
            latent_dim: d,
            skip_layer: self.skip_layer,
            beta: self.beta,
        };
        Ok(network.centre_on_sphere(self.radius_init))
    }
}

/// The SDF MLP (parameters only; latents live in [`crate::sdf::SdfAutoDecoder`]).
#[derive(Module, Debug)]
pub struct SdfNetwork {
    /// Hidden layers then the output layer; weights `[d_in, d_out]`.
    pub layers: Vec<Linear>,
    /// Latent size d.
    pub latent_dim: usize,
    /// Index of the layer receiving the re-concatenated input.
    pub skip_layer: usize,
    /// Softplus sharpness β.
    pub beta: f64,
}

/// The per-shape constant part of layer 0 and of the skip layer: `z·W_z + b` (the skip part
/// scaled by 1/√2), one row per shape. Computed once per shape, broadcast over its points.
#[derive(Debug, Clone)]
pub struct LatentOffsets {
    /// `[S, H]`: layer 0.
    pub first: Tensor<2>,
    /// `[S, H]`: the skip layer.
    pub skip: Tensor<2>,
}

/// f and, when requested, ∇ₓf for a batch of points.
#[derive(Debug, Clone)]
pub struct SdfOutput {
    /// `[S·P, 1]`: signed distances.
    pub values: Tensor<2>,
    /// `[S·P, 3]`: ∇ₓf.
    pub gradients: Option<Tensor<2>>,
}

/// Directions for calibrating the initial output bias: a Fibonacci sphere (deterministic,
/// near-uniform).
const CALIBRATION_DIRECTIONS: usize = 256;

impl SdfNetwork {
    /// Shifts the output bias so that f averages 0 over the sphere of radius `radius` (the
    /// latent rows are zero at initialisation, so the latent does not matter).
    fn centre_on_sphere(mut self, radius: f64) -> Self {
        let (device, dtype) = (self.device(), self.dtype());
        let n = CALIBRATION_DIRECTIONS;
        let golden = PI * (3.0 - 5f64.sqrt());
        let points: Vec<f64> = (0..n)
            .flat_map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let rho = (1.0 - z * z).sqrt();
                let phi = golden * i as f64;
                [
                    radius * rho * phi.cos(),
                    radius * rho * phi.sin(),
                    radius * z,
                ]
            })
            .collect();
        let points = Tensor::from_data(TensorData::new(points, [n, 3]), (&device, dtype));
        let zero = Tensor::zeros([1, self.latent_dim], (&device, dtype));
        let offsets = self.latent_offsets(zero);
        // Read back and rebuild the bias as a fresh leaf, so no autodiff graph of this
        // calibration stays attached to the parameters.
        let mean = self.evaluate(&offsets, points, false).values.mean();
        let mean: f64 = mean
            .into_data()
            .convert::<f64>()
            .try_to_vec::<f64>()
            .expect("f64")[0];
        let last = self.layers.len() - 1;
        let bias = self.layers[last]
            .bias
            .take()
            .expect("SDF layers have biases");
        let value: Vec<f64> = bias
            .val()
            .into_data()
            .convert::<f64>()
            .try_to_vec()
            .expect("f64");
        let value: Vec<f64> = value.iter().map(|b| b - mean).collect();
        let len = value.len();
        self.layers[last].bias = Some(Param::from_tensor(Tensor::from_data(
            TensorData::new(value, [len]),
            (&device, dtype),
        )));
        self
    }

    /// Number of inputs of `layer` that carry the previous activation (the rest are z, x).
    fn activation_inputs(&self, layer: usize) -> usize {
        let d_in = self.layers[layer].weight.dims()[0];
        if layer == self.skip_layer {
            d_in - self.latent_dim - 3
        } else {
            d_in
        }
    }

    /// The float dtype of the parameters (inputs are converted to it).
    pub fn dtype(&self) -> DType {
        self.layers[0].weight.val().dtype()
    }

    /// The device holding the parameters.
    pub fn device(&self) -> Device {
        self.layers[0].weight.val().device()
    }

    /// `z·W_z + b` for layer 0 and the skip layer, for latents `[S, d]`.
    pub fn latent_offsets(&self, latents: Tensor<2>) -> LatentOffsets {
        let d = self.latent_dim;
        let part = |layer: usize, scale: f64| {
            let lin = &self.layers[layer];
            let start = if layer == 0 {
                0
            } else {
                self.activation_inputs(layer)
            };
            let w_z = lin.weight.val().narrow(0, start, d);
            let bias = lin.bias.as_ref().expect("SDF layers have biases").val();
            latents.clone().matmul(w_z).mul_scalar(scale) + bias.unsqueeze_dim::<2>(0)
        };
        LatentOffsets {
            first: part(0, 1.0),
            skip: part(self.skip_layer, FRAC_1_SQRT_2),
        }
    }

    /// f (and ∇ₓf if `with_gradient`) at `points` `[S·P, 3]`, grouped by shape in the order of
    /// the offsets' rows (P points per shape).
    ///
    /// The whole network is one burn operation with its own backward ([`network_op`]) for
    /// f32 and f64 parameters and constant points; otherwise (other dtypes, or points that
    /// require a gradient) the composition of [`Self::evaluate_composed`].
    pub fn evaluate(
        &self,
        offsets: &LatentOffsets,
        points: Tensor<2>,
        with_gradient: bool,
    ) -> SdfOutput {
        if !network_op::supports(self.dtype()) || points.is_tracked() {
            return self.evaluate_composed(offsets, points, with_gradient);
        }
        let spec = NetworkSpec {
            shape: self.kernel_shape(),
            with_gradient,
        };
        let out = network_op::network(
            points,
            offsets.first.clone(),
            offsets.skip.clone(),
            self.kernel_parameters(),
            spec,
        );
        let gradients = with_gradient.then(|| out.clone().narrow(1, 1, 3));
        SdfOutput {
            values: if with_gradient {
                out.narrow(1, 0, 1)
            } else {
                out
            },
            gradients,
        }
    }

    /// The network's sizes as the host kernel sees them.
    pub fn kernel_shape(&self) -> KernelShape {
        let last = self.layers.len() - 1;
        KernelShape {
            widths: (0..last).map(|l| self.layers[l].weight.dims()[1]).collect(),
            skip: self.skip_layer,
            beta: self.beta,
        }
    }

    /// The kernel's flat parameter vector (blocks in the order of
    /// [`KernelShape::param_blocks`]), built from the layers by differentiable burn operations
    /// so that its gradient reaches every `Param`.
    pub fn kernel_parameters(&self) -> Tensor<1> {
        let d = self.latent_dim;
        let flat = |t: Tensor<2>| {
            let [r, c] = t.dims();
            t.reshape([r * c])
        };
        let bias = |l: usize| {
            self.layers[l]
                .bias
                .as_ref()
                .expect("SDF layers have biases")
                .val()
        };
        let last = self.layers.len() - 1;
        let mut parts = vec![flat(self.layers[0].weight.val().narrow(0, d, 3))];
        for l in 1..last {
            if l == self.skip_layer {
                let c = self.activation_inputs(l);
                let w = self.skip_weight();
                parts.push(flat(w.clone().narrow(0, 0, c)));
                parts.push(flat(w.narrow(0, c + d, 3)));
            } else {
                parts.push(flat(self.layers[l].weight.val()));
                parts.push(bias(l));
            }
        }
        parts.push(flat(self.layers[last].weight.val()));
        parts.push(bias(last));
        Tensor::cat(parts, 0)
    }

    /// [`Self::evaluate`] as a composition of burn operations: each hidden layer a matrix
    /// product followed by one fused `softplus_offset` (which adds the bias, or the shape's
    /// latent offset); the reverse pass reuses the layers' pre-activations through the fused
    /// `gate`. The reference the network operation is tested against.
    pub fn evaluate_composed(
        &self,
        offsets: &LatentOffsets,
        points: Tensor<2>,
        with_gradient: bool,
    ) -> SdfOutput {
        let d = self.latent_dim;
        let last = self.layers.len() - 1;
        let w0_x = self.layers[0].weight.val().narrow(0, d, 3);
        let skip_weight = self.skip_weight();
        // (pre-activation, offset) of every hidden layer, kept for the reverse pass.
        let mut pre_activations = Vec::with_capacity(if with_gradient { last } else { 0 });
        let mut layer = |pre: Tensor<2>, offset: Tensor<2>| {
            let h = softplus_offset(pre.clone(), offset.clone(), self.beta);
            if with_gradient {
                pre_activations.push((pre, offset));
            }
            h
        };
        let mut h = layer(points.clone().matmul(w0_x.clone()), offsets.first.clone());
        for l in 1..last {
            let lin = &self.layers[l];
            let (pre, offset) = if l == self.skip_layer {
                let c = self.activation_inputs(l);
                let pre = h.matmul(skip_weight.clone().narrow(0, 0, c))
                    + points
                        .clone()
                        .matmul(skip_weight.clone().narrow(0, c + d, 3));
                (pre, offsets.skip.clone())
            } else {
                (h.matmul(lin.weight.val()), row_bias(lin))
            };
            h = layer(pre, offset);
        }
        let values = self.layers[last].forward(h);
        let gradients =
            with_gradient.then(|| self.input_gradient(&w0_x, &skip_weight, pre_activations));
        SdfOutput { values, gradients }
    }

    /// The skip layer's weights scaled by 1/√2 (the scale of the re-concatenated input),
    /// so that no full-size activation has to be scaled.
    fn skip_weight(&self) -> Tensor<2> {
        self.layers[self.skip_layer]
            .weight
            .val()
            .mul_scalar(FRAC_1_SQRT_2)
    }

    /// The reverse pass δ_{l−1} = σ_{l−1} ⊙ (δ_l W_lᵀ) down to the x rows, with σ_l = σ(βy_l)
    /// evaluated inside the fused `gate` from the kept pre-activations.
    fn input_gradient(
        &self,
        w0_x: &Tensor<2>,
        skip_weight: &Tensor<2>,
        mut pre_activations: Vec<(Tensor<2>, Tensor<2>)>,
    ) -> Tensor<2> {
        let d = self.latent_dim;
        let last = self.layers.len() - 1;
        let w_out = self.layers[last].weight.val();
        let width = w_out.dims()[0];
        let mut next = || pre_activations.pop().expect("one per hidden layer");
        let (pre, offset) = next();
        let mut delta = gate(w_out.reshape([1, width]), pre, offset, self.beta);
        let mut grad_x = None;
        for l in (1..last).rev() {
            let back = if l == self.skip_layer {
                let c = self.activation_inputs(l);
                let w = skip_weight.clone();
                grad_x = Some(
                    delta
                        .clone()
                        .matmul(w.clone().narrow(0, c + d, 3).transpose()),
                );
                delta.matmul(w.narrow(0, 0, c).transpose())
            } else {
                delta.matmul(self.layers[l].weight.val().transpose())
            };
            let (pre, offset) = next();
            delta = gate(back, pre, offset, self.beta);
        }
        let g0 = delta.matmul(w0_x.clone().transpose());
        match grad_x {
            Some(gx) => g0 + gx,
            None => g0,
        }
    }
}

/// A layer's bias as a `[1, H]` offset row.
fn row_bias(layer: &Linear) -> Tensor<2> {
    let bias = layer.bias.as_ref().expect("SDF layers have biases").val();
    let width = bias.dims()[0];
    bias.reshape([1, width])
}

/// Helpers shared by the SDF tests: random perturbations and host conversions.
#[cfg(test)]
pub(crate) mod test_support {
    use burn::module::{Module, ModuleMapper, Param};
    use burn::tensor::{DType, Device, Tensor, TensorData};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    struct Perturb {
        rng: ChaCha8Rng,
        normal: Normal<f64>,
    }

    impl ModuleMapper for Perturb {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            param.map(|t| {
                let shape = t.shape();
                let noise: Vec<f64> = (0..shape.num_elements())
                    .map(|_| self.normal.sample(&mut self.rng))
                    .collect();
                let noise =
                    Tensor::from_data(TensorData::new(noise, shape), (&t.device(), t.dtype()));
                // A fresh leaf, so autodiff reports gradients under the parameter's id.
                let sum = (t + noise).detach();
                if sum.device().is_autodiff() {
                    sum.require_grad()
                } else {
                    sum
                }
            })
        }
    }

    /// Adds N(0, scale²) noise to every parameter, so zeroed latent rows and symmetric
    /// initial weights no longer hide errors.
    pub fn perturbed<M: Module>(module: M, seed: u64, scale: f64) -> M {
        module.map(&mut Perturb {
            rng: ChaCha8Rng::seed_from_u64(seed),
            normal: Normal::new(0.0, scale).unwrap(),
        })
    }

    /// Host rows → `[rows, cols]` tensor of `dtype`.
    pub fn tensor2(rows: &[Vec<f64>], device: &Device, dtype: DType) -> Tensor<2> {
        let cols = rows[0].len();
        let flat: Vec<f64> = rows.iter().flatten().copied().collect();
        Tensor::from_data(TensorData::new(flat, [rows.len(), cols]), (device, dtype))
    }

    /// Tensor → host f64 values (row-major).
    pub fn to_f64<const D: usize>(t: Tensor<D>) -> Vec<f64> {
        t.into_data()
            .convert::<f64>()
            .try_into_vec::<f64>()
            .unwrap()
    }

    /// `n` points uniform in [-r, r]³.
    pub fn random_points(n: usize, r: f64, seed: u64) -> Vec<Vec<f64>> {
        use rand::RngExt;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| (0..3).map(|_| rng.random_range(-r..r)).collect())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::{perturbed, random_points, tensor2, to_f64};
    use super::*;
    use crate::sdf::Backend;

    fn f64_net(latent_dim: usize, hidden: usize, seed: u64) -> SdfNetwork {
        let device = Backend::Flex.device(false).unwrap();
        let config = SdfNetworkConfig::new()
            .with_latent_dim(latent_dim)
            .with_hidden(hidden);
        perturbed(
            config.init_with_dtype(seed, &device, DType::F64).unwrap(),
            seed + 1,
            0.05,
        )
    }

    /// ∇ₓf of the reverse pass against central differences of f, in f64.
    fn check_input_gradient(latent_dim: usize, hidden: usize) {
        let net = f64_net(latent_dim, hidden, 7);
        let (device, dtype) = (net.device(), DType::F64);
        let (shapes, per_shape) = (2, 6);
        let latents: Vec<Vec<f64>> = random_points(shapes * latent_dim, 0.5, 3)
            .into_iter()
            .map(|p| p[0])
            .collect::<Vec<_>>()
            .chunks(latent_dim)
            .map(<[f64]>::to_vec)
            .collect();
        let offsets = net.latent_offsets(tensor2(&latents, &device, dtype));
        let points = random_points(shapes * per_shape, 0.9, 11);
        let out = net.evaluate(&offsets, tensor2(&points, &device, dtype), true);
        let grad = to_f64(out.gradients.unwrap());
        let h = 1e-6;
        for k in 0..3 {
            let shifted = |s: f64| {
                let p: Vec<Vec<f64>> = points
                    .iter()
                    .map(|p| {
                        let mut q = p.clone();
                        q[k] += s;
                        q
                    })
                    .collect();
                to_f64(
                    net.evaluate(&offsets, tensor2(&p, &device, dtype), false)
                        .values,
                )
            };
            let (plus, minus) = (shifted(h), shifted(-h));
            for i in 0..points.len() {
                let fd = (plus[i] - minus[i]) / (2.0 * h);
                let an = grad[3 * i + k];
                assert!(
                    (fd - an).abs() <= 1e-6 * (1.0 + fd.abs()),
                    "d={latent_dim} H={hidden} point {i} axis {k}: analytic {an} vs FD {fd}"
                );
            }
        }
    }

    /// The network operation (one burn operation with its own backward) against the
    /// composition of burn operations it replaces, on every compiled backend, in f64 and f32:
    /// f, ∇ₓf, and the gradient of a loss nonlinear in both with respect to every parameter
    /// and the latents, for a network wider than its input and one that is not.
    #[test]
    fn network_operation_equals_the_composed_network_with_all_gradients() {
        use crate::sdf::SdfAutoDecoder;
        use burn::optim::GradientsParams;

        for backend in Backend::ALL.into_iter().filter(|b| b.is_compiled()) {
            let device = backend.device(true).unwrap();
            for (dtype, tol) in [(DType::F64, 1e-10), (DType::F32, 2e-4)] {
                for (latent_dim, hidden) in [(8, 32), (8, 10)] {
                    let label = format!("{backend} {dtype:?} d={latent_dim} H={hidden}");
                    let config = SdfNetworkConfig::new()
                        .with_latent_dim(latent_dim)
                        .with_hidden(hidden);
                    let model =
                        SdfAutoDecoder::new_with_dtype(&config, 4, 3, &device, dtype).unwrap();
                    let model = perturbed(model, 4, 0.1);
                    let (shapes, per_shape) = (3, 40);
                    let points = random_points(shapes * per_shape, 0.9, 5);
                    let a = tensor2(&random_points(shapes * per_shape, 1.0, 6), &device, dtype)
                        .narrow(1, 0, 1);
                    let b = tensor2(&random_points(shapes * per_shape, 1.0, 7), &device, dtype);
                    let run = |composed: bool| {
                        let latents = model.gather_latents(&[2, 0, 3]);
                        let offsets = model.network.latent_offsets(latents);
                        let x = tensor2(&points, &device, dtype);
                        let out = if composed {
                            model.network.evaluate_composed(&offsets, x, true)
                        } else {
                            model.network.evaluate(&offsets, x, true)
                        };
                        let g = out.gradients.unwrap();
                        let loss = (out.values.clone() * a.clone()).sum()
                            + (g.clone().square() * b.clone()).sum();
                        let grads = GradientsParams::from_grads(loss.backward(), &model);
                        (to_f64(out.values), to_f64(g), grads)
                    };
                    let (f_op, g_op, grads_op) = run(false);
                    let (f_ref, g_ref, grads_ref) = run(true);
                    let close = |what: &str, got: &[f64], want: &[f64]| {
                        assert_eq!(got.len(), want.len(), "{label} {what}: sizes");
                        let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
                        for (i, (x, y)) in got.iter().zip(want).enumerate() {
                            assert!(
                                (x - y).abs() <= tol * scale,
                                "{label} {what}[{i}]: operation {x} vs composed {y}"
                            );
                        }
                    };
                    close("f", &f_op, &f_ref);
                    close("∇f", &g_op, &g_ref);
                    let mut ids = vec![("latents".to_string(), model.latents.id)];
                    for (l, layer) in model.network.layers.iter().enumerate() {
                        ids.push((format!("layer{l}.weight"), layer.weight.id));
                        ids.push((format!("layer{l}.bias"), layer.bias.as_ref().unwrap().id));
                    }
                    for (name, id) in ids {
                        let get = |g: &GradientsParams| match name.as_str() {
                            n if n.ends_with("bias") => to_f64(g.get::<1>(id).expect("∂bias")),
                            _ => to_f64(g.get::<2>(id).expect("∂weight")),
                        };
                        close(&name, &get(&grads_op), &get(&grads_ref));
                    }
                }
            }
        }
    }

    #[test]
    fn input_gradient_matches_finite_differences() {
        check_input_gradient(8, 32);
    }

    #[test]
    fn input_gradient_matches_finite_differences_when_width_does_not_exceed_input() {
        // H ≤ d+3: the layer before the skip keeps width H.
        let config = SdfNetworkConfig::new().with_latent_dim(8).with_hidden(10);
        assert_eq!(config.layer_dims()[3], (10, 10));
        assert_eq!(config.layer_dims()[4], (21, 10));
        check_input_gradient(8, 10);
    }

    #[test]
    fn layer_dims_follow_the_reference_layout() {
        let dims = SdfNetworkConfig::new()
            .with_latent_dim(256)
            .with_hidden(512)
            .layer_dims();
        assert_eq!(dims.len(), 9);
        assert_eq!(dims[0], (259, 512));
        assert_eq!(dims[3], (512, 253));
        assert_eq!(dims[4], (512, 512));
        assert_eq!(dims[8], (512, 1));
    }

    #[test]
    fn invalid_configurations_are_rejected() {
        let device = Backend::Flex.device(false).unwrap();
        let bad_skip = SdfNetworkConfig::new().with_skip_layer(8);
        assert_eq!(
            bad_skip.init(0, &device).unwrap_err(),
            NetworkConfigError::SkipOutOfRange {
                skip: 8,
                hidden_layers: 8
            }
        );
        let zero = SdfNetworkConfig::new().with_hidden(0);
        assert_eq!(
            zero.init(0, &device).unwrap_err(),
            NetworkConfigError::Zero("hidden")
        );
    }

    /// After IGR's geometric initialisation and the bias calibration, f ≈ ‖x‖ − r on average
    /// over directions from the sphere of radius r outwards, with a ≈ 10 % spread over
    /// directions (a finite-width random network; the PyTorch reference spreads as much), f
    /// increases along every ray (star-shaped zero set around the origin) and ∇f points
    /// outwards. Inside, softplus smooths the cone: f(0) ≈ −r/2 rather than −r.
    #[test]
    fn geometric_init_is_close_to_the_sphere_sdf_on_average() {
        let device = Backend::Flex.device(false).unwrap();
        let r = 0.5;
        let config = SdfNetworkConfig::new()
            .with_latent_dim(16)
            .with_hidden(512)
            .with_radius_init(r);
        let net = config.init_with_dtype(1, &device, DType::F64).unwrap();
        // The latent rows start at zero, so any latent gives the same field.
        let latent = vec![
            random_points(16, 1.0, 2)
                .into_iter()
                .map(|p| p[0])
                .collect(),
        ];
        let offsets = net.latent_offsets(tensor2(&latent, &device, DType::F64));
        let dirs: Vec<Vec<f64>> = random_points(300, 1.0, 5)
            .into_iter()
            .map(|p| {
                let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                p.iter().map(|c| c / n).collect()
            })
            .collect();
        let at = |rho: f64| {
            let pts: Vec<Vec<f64>> = dirs
                .iter()
                .map(|d| d.iter().map(|c| c * rho).collect())
                .collect();
            let out = net.evaluate(&offsets, tensor2(&pts, &device, DType::F64), true);
            (to_f64(out.values), to_f64(out.gradients.unwrap()))
        };
        let mut previous: Option<Vec<f64>> = None;
        for rho in [0.1, 0.3, 0.5, 0.75, 1.0] {
            let (f, g) = at(rho);
            let n = f.len() as f64;
            let mean = f.iter().sum::<f64>() / n;
            let spread = (f.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
            if rho >= r {
                let expected = rho - r;
                assert!(
                    (mean - expected).abs() < 0.03,
                    "ρ = {rho}: mean f {mean} vs {expected}"
                );
                assert!(
                    spread < 0.15 * rho,
                    "ρ = {rho}: f spreads by {spread} over directions"
                );
            } else {
                assert!(
                    f.iter().all(|&v| v < 0.0),
                    "ρ = {rho} < r: f must be negative"
                );
            }
            for (i, d) in dirs.iter().enumerate() {
                let gi = &g[3 * i..3 * i + 3];
                let norm = (gi[0] * gi[0] + gi[1] * gi[1] + gi[2] * gi[2]).sqrt();
                let cos = (gi[0] * d[0] + gi[1] * d[1] + gi[2] * d[2]) / norm;
                // Near the origin the smoothed cone's gradient is small and less radial.
                let min_cos = if rho < 0.3 { 0.5 } else { 0.8 };
                assert!(
                    cos > min_cos,
                    "ρ = {rho}, direction {i}: cos(∇f, x̂) = {cos}"
                );
                if let Some(prev) = &previous {
                    assert!(f[i] > prev[i], "ρ = {rho}, direction {i}: f not increasing");
                }
            }
            previous = Some(f);
        }
    }
}
