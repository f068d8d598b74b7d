//! The network and its burn operation: the DeepSDF/IGR MLP with its explicit input gradient
//! ∇ₓf ([`network`]), the whole network as one burn operation with its own backward
//! ([`network_op`]), the fused softplus and reverse-pass gate of a hidden layer ([`fused`]),
//! and the auto-decoder that pairs the network with one latent per training shape
//! ([`decoder`]).

pub mod decoder;
pub mod fused;
pub mod network;
pub mod network_op;
