//! Inference: f and ∇ₓf of one shape (one latent) at many points.
//!
//! The latent's contribution to layer 0 and to the skip layer (`z·W_z + b`) is computed once
//! when the field is built; each evaluation then only multiplies the points' own activations.
//! Points are processed in chunks so memory stays bounded for dense grids. With f32 weights
//! the host forward pass of [`crate::sdf::kernels::passes`] does the work (on any backend: it reads the
//! weights once); otherwise burn's composition of tensor operations
//! ([`SdfNetwork::evaluate_composed`]).

use burn::module::Module;
use burn::tensor::{DType, Tensor, TensorData};

use crate::sdf::kernels::passes::{KernelShape, Network};
use crate::sdf::model::network::{LatentOffsets, SdfNetwork};

/// Points per network evaluation: large enough for efficient matrix products, small enough
/// that the widest configuration (H = 512) stays near 100 MB of activations.
pub const DEFAULT_CHUNK_POINTS: usize = 32_768;

/// Why a field cannot be built or evaluated.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FieldError {
    /// The latent's length differs from the network's d.
    #[error("latent has {len} values but the network expects d = {expected}")]
    LatentLength {
        /// Given length.
        len: usize,
        /// The network's latent size.
        expected: usize,
    },
    /// Output buffers do not match the number of points.
    #[error("{what} has {len} entries for {points} points")]
    BufferLength {
        /// Which buffer.
        what: &'static str,
        /// Its length.
        len: usize,
        /// Number of points.
        points: usize,
    },
}

/// The SDF of one shape: a network (without autodiff) and its precomputed latent offsets.
#[derive(Debug, Clone)]
pub struct SdfField {
    network: SdfNetwork,
    offsets: LatentOffsets,
    chunk_points: usize,
    host: Option<HostNetwork>,
}

/// The network and one shape's offsets as host values, for the forward pass of
/// [`crate::sdf::kernels::passes`].
#[derive(Debug, Clone)]
struct HostNetwork {
    shape: KernelShape,
    params: Vec<f32>,
    first: Vec<f32>,
    skip: Vec<f32>,
}

impl HostNetwork {
    fn new(network: &SdfNetwork, offsets: &LatentOffsets) -> Self {
        Self {
            shape: network.kernel_shape(),
            params: to_f32(network.kernel_parameters()),
            first: to_f32(offsets.first.clone()),
            skip: to_f32(offsets.skip.clone()),
        }
    }

    /// f into `values` and, when given, ∇ₓf into `gradients` (one shape: one offset group).
    fn eval(&self, points: &[[f32; 3]], values: &mut [f32], gradients: Option<&mut [[f32; 3]]>) {
        let net = Network::new(&self.shape, &self.params, &self.first, &self.skip, 1)
            .expect("host network built from the model");
        let x = points.as_flattened();
        let run = |out: &mut [f32], with_gradient| {
            net.forward(x, with_gradient, out, None)
                .expect("buffers sized by the caller");
        };
        match gradients {
            None => run(values, false),
            Some(gradients) => {
                let mut out = vec![0.0f32; 4 * points.len()];
                run(&mut out, true);
                for ((o, v), g) in out.chunks_exact(4).zip(values).zip(gradients) {
                    *v = o[0];
                    *g = [o[1], o[2], o[3]];
                }
            }
        }
    }
}

impl SdfField {
    /// The field of latent `z` (length d). The network is detached from autodiff if needed.
    pub fn new(network: &SdfNetwork, latent: &[f32]) -> Result<Self, FieldError> {
        let expected = network.latent_dim;
        if latent.len() != expected {
            return Err(FieldError::LatentLength {
                len: latent.len(),
                expected,
            });
        }
        let network = network.valid();
        let z = Tensor::<2>::from_data(
            TensorData::new(latent.to_vec(), [1, expected]),
            (&network.device(), network.dtype()),
        );
        let offsets = network.latent_offsets(z);
        let host = (network.dtype() == DType::F32).then(|| HostNetwork::new(&network, &offsets));
        Ok(Self {
            network,
            offsets,
            chunk_points: DEFAULT_CHUNK_POINTS,
            host,
        })
    }

    /// Evaluates through burn's composition of tensor operations
    /// ([`SdfNetwork::evaluate_composed`]) even where the host pass applies: the reference
    /// the host pass is checked against.
    pub fn with_tensor_forward(mut self) -> Self {
        self.host = None;
        self
    }

    /// Whether evaluations run on the host forward pass.
    pub fn uses_host_forward(&self) -> bool {
        self.host.is_some()
    }

    /// Sets the number of points per network call (at least 1).
    pub fn with_chunk_points(mut self, chunk_points: usize) -> Self {
        self.chunk_points = chunk_points.max(1);
        self
    }

    /// Evaluates f (and ∇ₓf when `gradients` is given) at `points`.
    pub fn try_eval_batch(
        &self,
        points: &[[f32; 3]],
        values: &mut [f32],
        mut gradients: Option<&mut [[f32; 3]]>,
    ) -> Result<(), FieldError> {
        let n = points.len();
        if values.len() != n {
            return Err(FieldError::BufferLength {
                what: "values",
                len: values.len(),
                points: n,
            });
        }
        if let Some(g) = gradients.as_deref()
            && g.len() != n
        {
            return Err(FieldError::BufferLength {
                what: "gradients",
                len: g.len(),
                points: n,
            });
        }
        if let Some(host) = &self.host {
            for (c, chunk) in points.chunks(self.chunk_points).enumerate() {
                let rows = c * self.chunk_points..c * self.chunk_points + chunk.len();
                let g = gradients.as_deref_mut().map(|g| &mut g[rows.clone()]);
                host.eval(chunk, &mut values[rows], g);
            }
            return Ok(());
        }
        let (device, dtype) = (self.network.device(), self.network.dtype());
        for (c, chunk) in points.chunks(self.chunk_points).enumerate() {
            let start = c * self.chunk_points;
            let flat: Vec<f32> = chunk.iter().flatten().copied().collect();
            let x =
                Tensor::<2>::from_data(TensorData::new(flat, [chunk.len(), 3]), (&device, dtype));
            let out = self
                .network
                .evaluate_composed(&self.offsets, x, gradients.is_some());
            let f = to_f32(out.values);
            values[start..start + chunk.len()].copy_from_slice(&f);
            if let (Some(dst), Some(g)) = (gradients.as_deref_mut(), out.gradients) {
                let g = to_f32(g);
                for (d, s) in dst[start..start + chunk.len()]
                    .iter_mut()
                    .zip(g.chunks_exact(3))
                {
                    *d = [s[0], s[1], s[2]];
                }
            }
        }
        Ok(())
    }

    /// [`Self::try_eval_batch`] for callers that size the buffers themselves.
    ///
    /// # Panics
    /// When `values` (or `gradients`) does not have one entry per point.
    pub fn eval_batch(
        &self,
        points: &[[f32; 3]],
        values: &mut [f32],
        gradients: Option<&mut [[f32; 3]]>,
    ) {
        if let Err(e) = self.try_eval_batch(points, values, gradients) {
            panic!("SdfField::eval_batch: {e}");
        }
    }
}

fn to_f32<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .expect("converted to f32")
}

#[cfg(test)]
mod tests {
    use burn::tensor::DType;

    use super::*;
    use crate::sdf::model::network::SdfNetworkConfig;
    use crate::sdf::model::network::test_support::{perturbed, random_points, tensor2, to_f64};
    use crate::sdf::{Backend, SdfAutoDecoder};

    fn model(backend: Backend) -> SdfAutoDecoder {
        let device = backend.device(false).unwrap();
        let config = SdfNetworkConfig::new().with_latent_dim(8).with_hidden(32);
        let model = SdfAutoDecoder::new(&config, 3, 4, &device).unwrap();
        perturbed(model, 8, 0.05)
    }

    fn field_values(field: &SdfField, points: &[[f32; 3]]) -> (Vec<f32>, Vec<[f32; 3]>) {
        let mut values = vec![0.0; points.len()];
        let mut grads = vec![[0.0; 3]; points.len()];
        field.eval_batch(points, &mut values, Some(&mut grads));
        (values, grads)
    }

    fn points(n: usize) -> Vec<[f32; 3]> {
        random_points(n, 1.0, 17)
            .iter()
            .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
            .collect()
    }

    #[test]
    fn field_equals_the_training_forward() {
        let model = model(Backend::Flex);
        let pts = points(50);
        // Training path: gathered latent row 2, offsets for a batch of one shape.
        let offsets = model.network.latent_offsets(model.gather_latents(&[2]));
        let rows: Vec<Vec<f64>> = pts
            .iter()
            .map(|p| p.iter().map(|&c| c as f64).collect())
            .collect();
        let x = tensor2(&rows, &model.network.device(), DType::F32);
        let out = model.network.evaluate(&offsets, x, true);
        let (f_ref, g_ref) = (to_f64(out.values), to_f64(out.gradients.unwrap()));
        // Chunks of 7 so that chunk boundaries are exercised.
        let latent = model.latents_to_vec().swap_remove(2);
        let field = SdfField::new(&model.network, &latent)
            .unwrap()
            .with_chunk_points(7);
        let (f, g) = field_values(&field, &pts);
        for i in 0..pts.len() {
            assert!(
                (f[i] as f64 - f_ref[i]).abs() < 1e-5,
                "f at {i}: {} vs {}",
                f[i],
                f_ref[i]
            );
            for k in 0..3 {
                assert!(
                    (g[i][k] as f64 - g_ref[3 * i + k]).abs() < 1e-5,
                    "∇f at {i}"
                );
            }
        }
        let mut only_f = vec![0.0; pts.len()];
        field.eval_batch(&pts, &mut only_f, None);
        assert_eq!(only_f, f);
    }

    /// The host forward pass against the tensor forward it replaces, f and ∇ₓf, on networks
    /// with and without the narrowed layer before the skip, across chunk boundaries.
    #[test]
    fn host_forward_equals_the_tensor_forward() {
        let device = Backend::Flex.device(false).unwrap();
        for (d, h) in [(8, 32), (8, 10), (16, 64)] {
            let config = SdfNetworkConfig::new().with_latent_dim(d).with_hidden(h);
            let model = perturbed(
                SdfAutoDecoder::new(&config, 2, 5, &device).unwrap(),
                9,
                0.05,
            );
            let latent = model.latents_to_vec().swap_remove(1);
            let host = SdfField::new(&model.network, &latent).unwrap();
            assert!(host.uses_host_forward());
            let tensor = host.clone().with_tensor_forward();
            assert!(!tensor.uses_host_forward());
            let pts = points(2100);
            let (f1, g1) = field_values(&host, &pts);
            let (f2, g2) = field_values(&tensor, &pts);
            for i in 0..pts.len() {
                assert!(
                    (f1[i] - f2[i]).abs() <= 2e-6 * (1.0 + f2[i].abs()),
                    "(d, H) = ({d}, {h}), f at {i}: host {} tensor {}",
                    f1[i],
                    f2[i]
                );
                for k in 0..3 {
                    assert!(
                        (g1[i][k] - g2[i][k]).abs() <= 1e-5 * (1.0 + g2[i][k].abs()),
                        "(d, H) = ({d}, {h}), ∇f at {i}: {:?} vs {:?}",
                        g1[i],
                        g2[i]
                    );
                }
            }
            let mut only_f = vec![0.0; pts.len()];
            host.eval_batch(&pts, &mut only_f, None);
            assert_eq!(only_f, f1, "f does not depend on whether ∇f is asked");
        }
    }

    #[test]
    fn flex_and_ndarray_give_the_same_field() {
        if !(Backend::Flex.is_compiled() && Backend::NdArray.is_compiled()) {
            return;
        }
        let pts = points(200);
        let eval = |backend| {
            let model = model(backend);
            let latent = model.latents_to_vec().swap_remove(1);
            field_values(&SdfField::new(&model.network, &latent).unwrap(), &pts)
        };
        let (f1, g1) = eval(Backend::Flex);
        let (f2, g2) = eval(Backend::NdArray);
        for i in 0..pts.len() {
            assert!(
                (f1[i] - f2[i]).abs() < 1e-4,
                "f at {i}: flex {} ndarray {}",
                f1[i],
                f2[i]
            );
            for k in 0..3 {
                assert!(
                    (g1[i][k] - g2[i][k]).abs() < 1e-4,
                    "∇f at {i}: {:?} {:?}",
                    g1[i],
                    g2[i]
                );
            }
        }
    }

    #[test]
    fn wrong_sizes_are_reported() {
        let model = model(Backend::Flex);
        assert_eq!(
            SdfField::new(&model.network, &[0.0; 3]).unwrap_err(),
            FieldError::LatentLength {
                len: 3,
                expected: 8
            }
        );
        let field = SdfField::new(&model.network, &[0.0; 8]).unwrap();
        let mut values = vec![0.0; 2];
        assert_eq!(
            field.try_eval_batch(&points(3), &mut values, None),
            Err(FieldError::BufferLength {
                what: "values",
                len: 2,
                points: 3
            })
        );
    }
}
