//! The whole SDF network (f and ∇ₓf) as one burn operation with its own backward, through a
//! backend extension over the host passes of [`crate::sdf::kernels::passes`].
//!
//! burn's autodiff still builds and differentiates everything around it: the per-shape
//! latent offsets (`z·W_z + b`, a matrix product of the latent table), the flat parameter
//! vector (slices, scalings and a concatenation of the layers' `Param`s), the loss on f and
//! ∇ₓf, and the optimiser step. The operation's backward hands burn the gradients of the
//! offsets and of the flat parameters, from which burn's own backward of those operations
//! reaches every `Param` and the latent table. The points are constants of the operation
//! (`SdfNetwork::evaluate` uses the composed path when they require a gradient).

#![allow(missing_docs)]
// the backend-extension macro generates undocumented items
// The generated dispatch names NdArray, which upstream deprecates; it is kept deliberately as
// the comparison backend.
#![allow(deprecated)]

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, backend_extension};
use burn::tensor::{DType, Tensor, TensorData};

use std::sync::Arc;

use crate::sdf::kernels::buffers::Buffer;
use crate::sdf::kernels::passes::{KernelFloat, KernelShape, Network, NetworkGradients};

/// What one call evaluates: the network's sizes and whether ∇ₓf is part of the output.
#[derive(Debug, Clone, PartialEq)]
pub struct NetworkSpec {
    /// Layer widths, skip layer and β.
    pub shape: KernelShape,
    /// Output `[N, 4]` (f, ∇ₓf) rather than `[N, 1]` (f).
    pub with_gradient: bool,
}

/// The network operation (see the module documentation).
#[backend_extension(
    Flex: cfg(feature = "flex"),
    NdArray: cfg(feature = "ndarray"),
    Autodiff,
)]
pub trait NetworkOps: Backend {
    /// f (and ∇ₓf) at `points` `[N, 3]` for offsets `first` `[S, w_0]` and `skip`
    /// `[S, w_skip]` (S groups of N/S consecutive points) and the flat `params`.
    fn network(
        points: FloatTensor<Self>,
        first: FloatTensor<Self>,
        skip: FloatTensor<Self>,
        params: FloatTensor<Self>,
        spec: NetworkSpec,
    ) -> FloatTensor<Self>;
}

/// The saving forward and the backward of [`NetworkOps::network`] on a backend that runs the
/// host passes (what `Autodiff` needs of its inner backend).
pub trait NetworkKernelOps: Backend {
    /// The forward output and, when `save`, the values saved for the backward.
    fn network_forward(
        points: FloatTensor<Self>,
        first: FloatTensor<Self>,
        skip: FloatTensor<Self>,
        params: FloatTensor<Self>,
        spec: &NetworkSpec,
        save: bool,
    ) -> (FloatTensor<Self>, Option<Saved>);

    /// (∂first, ∂skip, ∂params) for the output gradient `grad` of the pass `forward`.
    fn network_backward(
        grad: FloatTensor<Self>,
        forward: &SavedForward<Self>,
        spec: &NetworkSpec,
    ) -> [FloatTensor<Self>; 3];
}

/// What the backward reads of a forward pass: its inputs and its saved values.
#[derive(Debug, Clone)]
pub struct SavedForward<B: Backend> {
    pub points: FloatTensor<B>,
    pub first: FloatTensor<B>,
    pub skip: FloatTensor<B>,
    pub params: FloatTensor<B>,
    pub saved: Saved,
}

/// What a forward pass saved for its backward: host memory that returns to its pool (and is
/// reused by the next step) once the backward has run and the graph is dropped.
#[derive(Clone)]
pub enum Saved {
    F32(Arc<Buffer<f32>>),
    F64(Arc<Buffer<f64>>),
}

impl std::fmt::Debug for Saved {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Saved::F32(b) => write!(f, "Saved::F32({} values)", b.len()),
            Saved::F64(b) => write!(f, "Saved::F64({} values)", b.len()),
        }
    }
}

/// The element type of saved values, to read them back in the backward.
pub trait SavedFloat: KernelFloat {
    /// Wraps a buffer.
    fn wrap(buffer: Buffer<Self>) -> Saved;
    /// The buffer, if `saved` holds this type.
    fn unwrap(saved: &Saved) -> &[Self];
}

/// Implements [`SavedFloat`] for a type and its [`Saved`] variant.
macro_rules! saved_float {
    ($float:ty, $variant:ident) => {
        impl SavedFloat for $float {
            fn wrap(buffer: Buffer<Self>) -> Saved {
                Saved::$variant(Arc::new(buffer))
            }
            fn unwrap(saved: &Saved) -> &[Self] {
                match saved {
                    Saved::$variant(b) => b,
                    other => panic!(
                        "network backward: {other:?} for a {} pass",
                        stringify!($float)
                    ),
                }
            }
        }
    };
}

saved_float!(f32, F32);
saved_float!(f64, F64);

/// f (and ∇ₓf): `[N, 1]` or `[N, 4]` (see [`NetworkOps::network`]).
pub fn network(
    points: Tensor<2>,
    first: Tensor<2>,
    skip: Tensor<2>,
    params: Tensor<1>,
    spec: NetworkSpec,
) -> Tensor<2> {
    Tensor::from_dispatch(<Dispatch as NetworkOps>::network(
        points.into_dispatch(),
        first.into_dispatch(),
        skip.into_dispatch(),
        params.into_dispatch(),
        spec,
    ))
}

/// Whether the operation takes tensors of `dtype`.
pub fn supports(dtype: DType) -> bool {
    matches!(dtype, DType::F32 | DType::F64)
}

/// The host passes on slices, shared by the backends.
mod host {
    use std::borrow::Cow;

    use super::*;

    /// The inputs as host slices (borrowed from tensor storage where possible): points,
    /// first, skip, params.
    pub struct Inputs<'a, E: Clone>(pub [Cow<'a, [E]>; 4]);

    impl<E: SavedFloat> Inputs<'_, E> {
        fn network<'s>(&'s self, spec: &'s NetworkSpec) -> Network<'s, E> {
            let [_, first, skip, params] = &self.0;
            let groups = first.len() / spec.shape.widths[0].max(1);
            Network::new(&spec.shape, params, first, skip, groups)
                .unwrap_or_else(|e| panic!("network operation: {e}"))
        }

        /// Number of points.
        pub fn rows(&self) -> usize {
            self.0[0].len() / 3
        }

        /// The output `[rows · cols]` and, when `save`, the values for the backward.
        pub fn forward(&self, spec: &NetworkSpec, save: bool) -> (Vec<E>, Option<Saved>) {
            let rows = self.rows();
            let mut out = vec![E::ZERO; rows * KernelShape::output_cols(spec.with_gradient)];
            let mut saved =
                save.then(|| Buffer::reused(rows * spec.shape.saved_per_row(spec.with_gradient)));
            self.network(spec)
                .forward(
                    &self.0[0],
                    spec.with_gradient,
                    &mut out,
                    saved.as_deref_mut(),
                )
                .unwrap_or_else(|e| panic!("network operation: {e}"));
            (out, saved.map(E::wrap))
        }

        /// The gradients for the output gradient `grad`.
        pub fn backward(
            &self,
            spec: &NetworkSpec,
            grad: &[E],
            saved: &Saved,
        ) -> NetworkGradients<E> {
            self.network(spec)
                .backward(&self.0[0], spec.with_gradient, grad, E::unwrap(saved))
                .unwrap_or_else(|e| panic!("network operation: {e}"))
        }
    }
}

/// Implements the operation for a backend through the host passes, given how to read a
/// tensor as a host slice and how to build a tensor from host values.
macro_rules! host_backed {
    ($backend:ty, $values:ident, $tensor:ident, $shape:ident) => {
        impl NetworkOps for $backend {
            fn network(
                points: FloatTensor<Self>,
                first: FloatTensor<Self>,
                skip: FloatTensor<Self>,
                params: FloatTensor<Self>,
                spec: NetworkSpec,
            ) -> FloatTensor<Self> {
                let (out, _) = <$backend as NetworkKernelOps>::network_forward(
                    points, first, skip, params, &spec, false,
                );
                out
            }
        }

        impl NetworkKernelOps for $backend {
            fn network_forward(
                points: FloatTensor<Self>,
                first: FloatTensor<Self>,
                skip: FloatTensor<Self>,
                params: FloatTensor<Self>,
                spec: &NetworkSpec,
                save: bool,
            ) -> (FloatTensor<Self>, Option<Saved>) {
                fn typed<E: SavedFloat + burn::tensor::Element + bytemuck::Pod>(
                    inputs: [&FloatTensor<$backend>; 4],
                    spec: &NetworkSpec,
                    save: bool,
                ) -> (FloatTensor<$backend>, Option<Saved>) {
                    let host = host::Inputs(inputs.map(|t| $values::<E>(t)));
                    let rows = host.rows();
                    let (out, saved) = host.forward(spec, save);
                    let cols = KernelShape::output_cols(spec.with_gradient);
                    ($tensor(out, vec![rows, cols]), saved)
                }
                let inputs = [&points, &first, &skip, &params];
                match points.dtype() {
                    DType::F32 => typed::<f32>(inputs, spec, save),
                    DType::F64 => typed::<f64>(inputs, spec, save),
                    other => panic!("network operation on {other:?}"),
                }
            }

            fn network_backward(
                grad: FloatTensor<Self>,
                inputs: &SavedForward<Self>,
                spec: &NetworkSpec,
            ) -> [FloatTensor<Self>; 3] {
                fn typed<E: SavedFloat + burn::tensor::Element + bytemuck::Pod>(
                    grad: &FloatTensor<$backend>,
                    inputs: &SavedForward<$backend>,
                    spec: &NetworkSpec,
                ) -> [FloatTensor<$backend>; 3] {
                    let host = host::Inputs(
                        [&inputs.points, &inputs.first, &inputs.skip, &inputs.params]
                            .map(|t| $values::<E>(t)),
                    );
                    let grad = $values::<E>(grad);
                    let grads = host.backward(spec, &grad, &inputs.saved);
                    [
                        $tensor(grads.first, $shape(&inputs.first)),
                        $tensor(grads.skip, $shape(&inputs.skip)),
                        $tensor(grads.params, $shape(&inputs.params)),
                    ]
                }
                match inputs.points.dtype() {
                    DType::F32 => typed::<f32>(&grad, inputs, spec),
                    DType::F64 => typed::<f64>(&grad, inputs, spec),
                    other => panic!("network operation on {other:?}"),
                }
            }
        }
    };
}

/// Flex: the passes read the tensors' storage in place.
#[cfg(feature = "flex")]
mod flex {
    use std::borrow::Cow;

    use burn::backend::Flex;
    use burn::tensor::Element;
    use burn_flex::FlexTensor;

    use super::*;

    /// The tensor's elements as a contiguous slice (copied when they are not).
    fn values<E: Element + bytemuck::Pod>(t: &FlexTensor) -> Cow<'_, [E]> {
        match t.as_slice::<E>() {
            Some(s) => Cow::Borrowed(s),
            None => Cow::Owned(
                t.clone()
                    .into_data()
                    .into_vec::<E>()
                    .expect("checked dtype"),
            ),
        }
    }

    fn tensor<E: Element>(values: Vec<E>, shape: Vec<usize>) -> FlexTensor {
        FlexTensor::from_data(TensorData::new(values, shape))
    }

    fn shape(t: &FlexTensor) -> Vec<usize> {
        t.layout().shape().to_vec()
    }

    host_backed!(Flex, values, tensor, shape);
}

/// NdArray (the comparison backend): the passes run on host copies of the tensors.
#[cfg(feature = "ndarray")]
mod ndarray {
    use std::borrow::Cow;

    use burn::backend::ops::FloatTensorOps;
    use burn::backend::{NdArray, NdArrayDevice, TensorMetadata};
    use burn::tensor::Element;

    use super::*;

    fn values<E: Element>(t: &FloatTensor<NdArray>) -> Cow<'static, [E]> {
        Cow::Owned(
            burn::tensor::read_sync(NdArray::float_into_data(t.clone()))
                .expect("host tensor")
                .into_vec::<E>()
                .expect("checked dtype"),
        )
    }

    fn tensor<E: Element>(values: Vec<E>, shape: Vec<usize>) -> FloatTensor<NdArray> {
        NdArray::float_from_data(TensorData::new(values, shape), &NdArrayDevice::default())
    }

    fn shape(t: &FloatTensor<NdArray>) -> Vec<usize> {
        t.shape().to_vec()
    }

    host_backed!(NdArray, values, tensor, shape);
}

/// Backward of `network`: parents (first, skip, params).
#[derive(Debug)]
struct NetworkBackward;

impl<B: Backend + NetworkKernelOps> Backward<B, 3> for NetworkBackward {
    type State = (SavedForward<B>, NetworkSpec);

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let (forward, spec) = ops.state;
        let grad = grads.consume::<B>(&ops.node);
        let results = B::network_backward(grad, &forward, &spec);
        for (node, grad) in ops.parents.into_iter().zip(results) {
            if let Some(node) = node {
                grads.register::<B>(node.id, grad);
            }
        }
    }
}

impl<B: Backend + NetworkKernelOps, C: CheckpointStrategy> NetworkOps for Autodiff<B, C> {
    fn network(
        points: FloatTensor<Self>,
        first: FloatTensor<Self>,
        skip: FloatTensor<Self>,
        params: FloatTensor<Self>,
        spec: NetworkSpec,
    ) -> FloatTensor<Self> {
        let guards = [first.node(), skip.node(), params.node()];
        let points = points.into_primitive();
        let (first, skip, params) = (
            first.into_primitive(),
            skip.into_primitive(),
            params.into_primitive(),
        );
        match NetworkBackward
            .prepare::<C>(guards)
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (out, saved) = B::network_forward(
                    points.clone(),
                    first.clone(),
                    skip.clone(),
                    params.clone(),
                    &spec,
                    true,
                );
                let saved = saved.expect("a saving forward pass returns its saved values");
                let state = SavedForward {
                    points,
                    first,
                    skip,
                    params,
                    saved,
                };
                prep.finish((state, spec), out)
            }
            OpsKind::UnTracked(prep) => {
                let (out, _) = B::network_forward(points, first, skip, params, &spec, false);
                prep.finish(out)
            }
        }
    }
}
