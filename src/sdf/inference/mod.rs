//! Using a trained model: fast evaluation of f and ∇f for one latent ([`field`]), meshes by
//! surface extraction ([`reconstruct`]), reconstruction fidelity ([`evaluation`]), a shape's
//! distance to the training set ([`novelty`]) and the latent of a mixture ([`mixing`]).

pub mod evaluation;
pub mod field;
pub mod mixing;
pub mod novelty;
pub mod reconstruct;
