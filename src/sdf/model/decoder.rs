//! The auto-decoder: the SDF network plus one learned latent vector per training shape.

use burn::module::{Module, Param};
use burn::tensor::{DType, Device, Int, Tensor, TensorData};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::sdf::model::network::{NetworkConfigError, SdfNetwork, SdfNetworkConfig};

/// Standard deviation of the initial latents (DESIGN §2: N(0, 0.01²)).
pub const LATENT_INIT_STD: f64 = 0.01;

/// Network + latent table, optimised together (DeepSDF auto-decoder).
#[derive(Module, Debug)]
pub struct SdfAutoDecoder {
    /// The shared SDF network f(z; x).
    pub network: SdfNetwork,
    /// `[num_shapes, d]`: row k is shape k's latent z_k.
    pub latents: Param<Tensor<2>>,
}

impl SdfAutoDecoder {
    /// A fresh model for `num_shapes` shapes: geometric init for the network, N(0, 0.01²)
    /// latents, all drawn from `seed` on the host (identical on every backend).
    pub fn new(
        config: &SdfNetworkConfig,
        num_shapes: usize,
        seed: u64,
        device: &Device,
    ) -> Result<Self, NetworkConfigError> {
        Self::new_with_dtype(config, num_shapes, seed, device, DType::F32)
    }

    /// [`Self::new`] with an explicit float dtype.
    pub fn new_with_dtype(
        config: &SdfNetworkConfig,
        num_shapes: usize,
        seed: u64,
        device: &Device,
        dtype: DType,
    ) -> Result<Self, NetworkConfigError> {
        if num_shapes == 0 {
            return Err(NetworkConfigError::Zero("num_shapes"));
        }
        let network = config.init_with_dtype(seed, device, dtype)?;
        // A different stream than the network's, so adding shapes never changes the weights.
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6c61_7465_6e74_7321);
        let normal = Normal::new(0.0, LATENT_INIT_STD).expect("finite positive std");
        let d = config.latent_dim;
        let values: Vec<f64> = (0..num_shapes * d)
            .map(|_| normal.sample(&mut rng))
            .collect();
        let latents = Tensor::from_data(TensorData::new(values, [num_shapes, d]), (device, dtype));
        Ok(Self {
            network,
            latents: Param::from_tensor(latents),
        })
    }

    /// Number of training shapes (rows of the latent table).
    pub fn num_shapes(&self) -> usize {
        self.latents.dims()[0]
    }

    /// Latent size d.
    pub fn latent_dim(&self) -> usize {
        self.network.latent_dim
    }

    /// Rows `indices` of the latent table, `[indices.len(), d]`; a differentiable gather, so
    /// the loss's gradient reaches exactly these rows.
    pub fn gather_latents(&self, indices: &[usize]) -> Tensor<2> {
        let device = self.latents.val().device();
        let idx: Vec<i64> = indices.iter().map(|&i| i as i64).collect();
        let idx = Tensor::<1, Int>::from_data(TensorData::new(idx, [indices.len()]), &device);
        self.latents.val().select(0, idx)
    }

    /// All latents copied to the host, one `Vec` of length d per shape.
    pub fn latents_to_vec(&self) -> Vec<Vec<f32>> {
        let d = self.latent_dim();
        let flat: Vec<f32> = self
            .latents
            .val()
            .into_data()
            .convert::<f32>()
            .try_into_vec()
            .expect("latent table converts to f32");
        flat.chunks(d).map(<[f32]>::to_vec).collect()
    }
}
