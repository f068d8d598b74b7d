//! The IGR loss (DESIGN §2, eq. 4) over a batch of shapes.
//!
//! Per shape k: mean|f(z_k; x_i)| over its surface samples + mean‖∇ₓf − n_i‖² + τ·mean
//! (‖∇ₓf‖ − 1)² over its eikonal samples + λ‖z_k‖; the batch loss is the mean over shapes.
//! Every shape of a batch has the same numbers of surface and eikonal samples, so the mean
//! over shapes of per-shape means equals the mean over all samples of the batch.

use burn::config::Config;
use burn::tensor::{Tensor, TensorData};

use super::decoder::SdfAutoDecoder;

/// Weights of the loss terms.
#[derive(Config, Debug)]
pub struct IgrLossConfig {
    /// τ: weight of the eikonal term.
    #[config(default = 0.5)]
    pub tau: f64,
    /// λ: weight of the latent-norm term.
    #[config(default = 1e-4)]
    pub lambda: f64,
}

/// One optimisation batch, built by the caller. Samples are grouped by shape: shape
/// `shape_indices[b]` owns surface rows `b·N..(b+1)·N` and eikonal rows `b·M..(b+1)·M`,
/// all in unit-ball coordinates.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TrainingBatch {
    /// B rows of the latent table (repeats allowed).
    pub shape_indices: Vec<usize>,
    /// `[B·N]` surface points.
    pub surface_points: Vec<[f32; 3]>,
    /// `[B·N]` unit outward normals at the surface points.
    pub surface_normals: Vec<[f32; 3]>,
    /// `[B·M]` eikonal points (IGR's D: half Gaussian around surface points, half uniform).
    pub eikonal_points: Vec<[f32; 3]>,
}

/// A batch whose sizes do not fit together or with the model.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BatchError {
    /// No shapes, or no surface samples.
    #[error("training batch is empty: {0}")]
    Empty(&'static str),
    /// A shape index beyond the latent table.
    #[error("shape_indices[{position}] = {index} but the model has {num_shapes} latents")]
    ShapeIndex {
        /// Position in `shape_indices`.
        position: usize,
        /// The offending index.
        index: usize,
        /// Rows of the latent table.
        num_shapes: usize,
    },
    /// Sample counts not divisible by the number of shapes, or normals not matching points.
    #[error("{what} has {len} rows, expected {expected}")]
    Length {
        /// Which field.
        what: &'static str,
        /// Its length.
        len: usize,
        /// What the other fields imply.
        expected: String,
    },
    /// A NaN or infinite coordinate.
    #[error("{what}[{row}] is not finite")]
    NotFinite {
        /// Which field.
        what: &'static str,
        /// The row.
        row: usize,
    },
}

impl TrainingBatch {
    /// Checks the batch against a latent table of `num_shapes` rows; returns (B, N, M).
    pub fn dims(&self, num_shapes: usize) -> Result<(usize, usize, usize), BatchError> {
        let b = self.shape_indices.len();
        if b == 0 {
            return Err(BatchError::Empty("no shape_indices"));
        }
        if self.surface_points.is_empty() {
            return Err(BatchError::Empty("no surface_points"));
        }
        if let Some((position, &index)) = self
            .shape_indices
            .iter()
            .enumerate()
            .find(|&(_, &i)| i >= num_shapes)
        {
            return Err(BatchError::ShapeIndex {
                position,
                index,
                num_shapes,
            });
        }
        let per_shape = |what, len: usize| {
            if len % b == 0 {
                Ok(len / b)
            } else {
                Err(BatchError::Length {
                    what,
                    len,
                    expected: format!("a multiple of {b} shapes"),
                })
            }
        };
        let n = per_shape("surface_points", self.surface_points.len())?;
        let m = per_shape("eikonal_points", self.eikonal_points.len())?;
        if self.surface_normals.len() != self.surface_points.len() {
            return Err(BatchError::Length {
                what: "surface_normals",
                len: self.surface_normals.len(),
                expected: format!("{} (one per surface point)", self.surface_points.len()),
            });
        }
        for (what, rows) in [
            ("surface_points", &self.surface_points),
            ("surface_normals", &self.surface_normals),
            ("eikonal_points", &self.eikonal_points),
        ] {
            if let Some(row) = rows.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
                return Err(BatchError::NotFinite { what, row });
            }
        }
        Ok((b, n, m))
    }

    /// Points in network order: per shape, its N surface then its M eikonal points.
    fn network_points(&self, b: usize, n: usize, m: usize) -> Vec<f32> {
        let mut flat = Vec::with_capacity(b * (n + m) * 3);
        for s in 0..b {
            let surface = &self.surface_points[s * n..(s + 1) * n];
            let eikonal = &self.eikonal_points[s * m..(s + 1) * m];
            flat.extend(surface.iter().chain(eikonal).flatten());
        }
        flat
    }
}

/// The loss and its terms (each already weighted, as summed into `total`), scalar tensors.
#[derive(Debug, Clone)]
pub struct LossTerms {
    /// The sum of the four terms; differentiate this.
    pub total: Tensor<1>,
    /// mean |f| on surface points.
    pub surface: Tensor<1>,
    /// mean ‖∇f − n‖² on surface points.
    pub normal: Tensor<1>,
    /// τ · mean (‖∇f‖ − 1)² on eikonal points.
    pub eikonal: Tensor<1>,
    /// λ · mean over the batch's shapes of ‖z‖.
    pub latent: Tensor<1>,
}

/// The IGR loss of `model` on `batch` (on the model's device and dtype).
pub fn igr_loss(
    model: &SdfAutoDecoder,
    batch: &TrainingBatch,
    config: &IgrLossConfig,
) -> Result<LossTerms, BatchError> {
    let (b, n, m) = batch.dims(model.num_shapes())?;
    let network = &model.network;
    let (device, dtype) = (network.device(), network.dtype());
    let tensor3 = |flat: Vec<f32>, rows: usize| {
        Tensor::<3>::from_data(TensorData::new(flat, [b, rows, 3]), (&device, dtype))
    };
    let points = tensor3(batch.network_points(b, n, m), n + m).reshape([b * (n + m), 3]);
    let normals = tensor3(batch.surface_normals.iter().flatten().copied().collect(), n);

    let latents = model.gather_latents(&batch.shape_indices);
    let offsets = network.latent_offsets(latents.clone());
    let out = network.evaluate(&offsets, points, true);
    let values = out.values.reshape([b, n + m, 1]);
    let grads = out
        .gradients
        .expect("gradient requested")
        .reshape([b, n + m, 3]);

    let surface = values.narrow(1, 0, n).abs().mean();
    let normal = (grads.clone().narrow(1, 0, n) - normals)
        .square()
        .sum_dim(2)
        .mean();
    let eikonal = if m > 0 {
        let norm = grads.narrow(1, n, m).square().sum_dim(2).sqrt();
        norm.sub_scalar(1.0).square().mean().mul_scalar(config.tau)
    } else {
        surface.zeros_like()
    };
    let latent = latents
        .square()
        .sum_dim(1)
        .sqrt()
        .mean()
        .mul_scalar(config.lambda);
    let total = surface.clone() + normal.clone() + eikonal.clone() + latent.clone();
    Ok(LossTerms {
        total,
        surface,
        normal,
        eikonal,
        latent,
    })
}
