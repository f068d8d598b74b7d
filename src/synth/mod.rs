//! The embedded default dataset: parametric aortic-root surfaces in millimetres.
//!
//! A root is drawn from published normal adult ranges ([`params`]), swept along a straight
//! then circular centreline ([`centreline`]) with a three-lobed sinus cross-section
//! ([`surface`]). Each shape `i` of a cohort uses its own ChaCha8 stream of the seed, so a
//! shape does not depend on how many others are generated, nor on the platform.

pub mod centreline;
pub mod params;
pub mod ply;
pub mod surface;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::geometry::TriMesh;
pub use params::{AorticRootParams, ParamsError, sample_params};
pub use surface::{SurfaceResolution, build_root, build_root_with};

/// The parameters of shape `index` of the cohort drawn with `seed`.
pub fn params_for(seed: u64, index: u64) -> AorticRootParams {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index);
    sample_params(&mut rng)
}

/// Parameters and surface of shape `index` of the cohort drawn with `seed`.
pub fn generate_root(seed: u64, index: u64, closed: bool) -> (AorticRootParams, TriMesh) {
    let params = params_for(seed, index);
    let mesh = build_root(&params, closed)
        .unwrap_or_else(|e| unreachable!("sampled parameters are valid by construction: {e}"));
    (params, mesh)
}

/// `count` shapes drawn with `seed`, built in parallel, in index order.
pub fn generate_roots(count: usize, seed: u64, closed: bool) -> Vec<(AorticRootParams, TriMesh)> {
    (0..count as u64)
        .into_par_iter()
        .map(|i| generate_root(seed, i, closed))
        .collect()
}
