//! The IGR loss (DESIGN §2, eq. 4) over a batch of shapes.
//!
//! Per shape k: mean|f(z_k; x_i)| over its surface samples + mean‖∇ₓf − n_i‖² + τ·mean
//! (‖∇ₓf‖ − 1)² over its eikonal samples + λ‖z_k‖; the batch loss is the mean over shapes.
//! Every shape of a batch has the same numbers of surface and eikonal samples, so the mean
//! over shapes of per-shape means equals the mean over all samples of the batch.

use burn::config::Config;
use burn::tensor::{Tensor, TensorData};

use crate::sdf::model::decoder::SdfAutoDecoder;

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
            if len.is_multiple_of(b) {
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

#[cfg(test)]
mod tests {
    use burn::module::Param;
    use burn::optim::GradientsParams;
    use burn::tensor::{DType, Tensor, TensorData};

    use super::*;
    use crate::sdf::Backend;
    use crate::sdf::model::network::SdfNetworkConfig;
    use crate::sdf::model::network::test_support::{perturbed, random_points, to_f64};

    fn p3(v: &[f64]) -> [f32; 3] {
        [v[0] as f32, v[1] as f32, v[2] as f32]
    }

    fn tiny_batch() -> TrainingBatch {
        let surface: Vec<[f32; 3]> = random_points(8, 0.8, 21).iter().map(|p| p3(p)).collect();
        let normals = random_points(8, 1.0, 22)
            .iter()
            .map(|p| {
                let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                p3(&p.iter().map(|c| c / n).collect::<Vec<_>>())
            })
            .collect();
        let eikonal = random_points(6, 1.0, 23).iter().map(|p| p3(p)).collect();
        TrainingBatch {
            shape_indices: vec![1, 0],
            surface_points: surface,
            surface_normals: normals,
            eikonal_points: eikonal,
        }
    }

    fn loss_value(model: &SdfAutoDecoder, batch: &TrainingBatch) -> f64 {
        to_f64(igr_loss(model, batch, &IgrLossConfig::new()).unwrap().total)[0]
    }

    /// Central difference of the loss w.r.t. entry `index` of the parameter chosen by `pick`.
    fn finite_difference<const D: usize>(
        model: &SdfAutoDecoder,
        batch: &TrainingBatch,
        pick: fn(&mut SdfAutoDecoder) -> &mut Param<Tensor<D>>,
        index: usize,
    ) -> f64 {
        let h = 1e-6;
        let shifted = |s: f64| {
            let mut m = model.clone();
            let param = pick(&mut m);
            let p = param.clone();
            *param = p.map(|t| {
                let shape = t.shape();
                let mut onehot = vec![0.0; shape.num_elements()];
                onehot[index] = s;
                t.clone()
                    + Tensor::from_data(TensorData::new(onehot, shape), (&t.device(), t.dtype()))
            });
            loss_value(&m, batch)
        };
        (shifted(h) - shifted(-h)) / (2.0 * h)
    }

    #[test]
    fn parameter_gradients_of_the_loss_match_finite_differences() {
        let device = Backend::Flex.device(true).unwrap();
        let config = SdfNetworkConfig::new().with_latent_dim(4).with_hidden(12);
        let model = SdfAutoDecoder::new_with_dtype(&config, 3, 5, &device, DType::F64).unwrap();
        let model = perturbed(model, 6, 0.1);
        let batch = tiny_batch();
        let terms = igr_loss(&model, &batch, &IgrLossConfig::new()).unwrap();
        let grads = GradientsParams::from_grads(terms.total.backward(), &model);

        let check = |name: &str, analytic: Vec<f64>, fd: &dyn Fn(usize) -> f64, idx: usize| {
            let (a, f) = (analytic[idx], fd(idx));
            assert!(
                (a - f).abs() <= 1e-6 * (1.0 + f.abs()),
                "{name}[{idx}]: autodiff {a} vs FD {f}"
            );
        };
        let w = |l: usize| -> Vec<f64> {
            to_f64(grads.get::<2>(model.network.layers[l].weight.id).unwrap())
        };
        // Layer 0 is [7, 12]: rows 0..4 multiply z, rows 4..7 multiply x.
        check(
            "layer0.weight(z row)",
            w(0),
            &|i| finite_difference(&model, &batch, |m| &mut m.network.layers[0].weight, i),
            12 + 5,
        );
        check(
            "layer0.weight(x row)",
            w(0),
            &|i| finite_difference(&model, &batch, |m| &mut m.network.layers[0].weight, i),
            5 * 12 + 2,
        );
        // Skip layer 4 is [12, 12]: rows 0..5 activation, 5..9 z, 9..12 x.
        for i in [2 * 12 + 3, 6 * 12 + 1, 10 * 12 + 7] {
            check(
                "layer4.weight",
                w(4),
                &|i| finite_difference(&model, &batch, |m| &mut m.network.layers[4].weight, i),
                i,
            );
        }
        check(
            "layer6.weight",
            w(6),
            &|i| finite_difference(&model, &batch, |m| &mut m.network.layers[6].weight, i),
            40,
        );
        check(
            "output.weight",
            w(8),
            &|i| finite_difference(&model, &batch, |m| &mut m.network.layers[8].weight, i),
            3,
        );
        let bias = to_f64(
            grads
                .get::<1>(model.network.layers[2].bias.as_ref().unwrap().id)
                .unwrap(),
        );
        check(
            "layer2.bias",
            bias,
            &|i| {
                finite_difference(
                    &model,
                    &batch,
                    |m| m.network.layers[2].bias.as_mut().unwrap(),
                    i,
                )
            },
            4,
        );
        let latents = to_f64(grads.get::<2>(model.latents.id).unwrap());
        // Shape 1 is in the batch (row 1), shape 2 is not: its gradient is exactly zero.
        check(
            "latents",
            latents.clone(),
            &|i| finite_difference(&model, &batch, |m| &mut m.latents, i),
            4 + 2,
        );
        assert!(
            latents[8..12].iter().all(|&g| g == 0.0),
            "unused latent row got a gradient"
        );
    }

    #[test]
    fn loss_terms_add_up_and_match_a_direct_evaluation() {
        let device = Backend::Flex.device(false).unwrap();
        let config = SdfNetworkConfig::new().with_latent_dim(4).with_hidden(12);
        let model = SdfAutoDecoder::new_with_dtype(&config, 2, 1, &device, DType::F64).unwrap();
        let model = perturbed(model, 2, 0.1);
        let batch = tiny_batch();
        let cfg = IgrLossConfig::new();
        let terms = igr_loss(&model, &batch, &cfg).unwrap();
        let get = |t: &Tensor<1>| to_f64(t.clone())[0];
        let sum =
            get(&terms.surface) + get(&terms.normal) + get(&terms.eikonal) + get(&terms.latent);
        assert!((get(&terms.total) - sum).abs() < 1e-12);
        // λ·mean‖z‖ over the batch's shapes (1 and 0), computed on the host.
        let z = model.latents_to_vec();
        let norm = |v: &Vec<f32>| v.iter().map(|&c| (c as f64).powi(2)).sum::<f64>().sqrt();
        let expected = cfg.lambda * (norm(&z[1]) + norm(&z[0])) / 2.0;
        assert!((get(&terms.latent) - expected).abs() < 1e-9 * expected.max(1e-12) + 1e-12);
    }

    #[test]
    fn malformed_batches_are_rejected_with_the_field_named() {
        let b = tiny_batch();
        assert_eq!(b.dims(2), Ok((2, 4, 3)));
        assert_eq!(
            b.dims(1),
            Err(BatchError::ShapeIndex {
                position: 0,
                index: 1,
                num_shapes: 1
            })
        );
        let mut odd = b.clone();
        odd.eikonal_points.pop();
        assert!(matches!(
            odd.dims(2),
            Err(BatchError::Length {
                what: "eikonal_points",
                ..
            })
        ));
        let mut normals = b.clone();
        normals.surface_normals.pop();
        assert!(matches!(
            normals.dims(2),
            Err(BatchError::Length {
                what: "surface_normals",
                ..
            })
        ));
        let mut nan = b.clone();
        nan.surface_points[3][1] = f32::NAN;
        assert_eq!(
            nan.dims(2),
            Err(BatchError::NotFinite {
                what: "surface_points",
                row: 3
            })
        );
        assert_eq!(
            TrainingBatch::default().dims(2),
            Err(BatchError::Empty("no shape_indices"))
        );
    }
}
