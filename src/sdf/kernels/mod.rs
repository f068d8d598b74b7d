//! Host kernels behind the burn operations: passes of the whole network over chunks of points
//! that stay in cache ([`passes`]), the vectorised softplus and slope loops ([`softplus`]),
//! matrix products through gemm into caller-owned buffers ([`product`]) and the host buffers
//! those passes reuse from step to step ([`buffers`]). Plain host code, no burn types.

pub mod buffers;
pub mod passes;
pub mod product;
pub mod softplus;
