//! Cohort generation, in one place for the command line and the service (DESIGN §4).
//!
//! A request is parsed once into a [`CohortRequest`] ([`request`]); with the model's facts
//! it becomes a [`CohortPlan`] ([`plan`]) that derives every draw of every shape from the
//! cohort seed ([`seeds`], [`selection`], [`weights`]). The [`CohortGenerator`]
//! ([`generator`]) meshes draws with the [`Engine`](crate::engine::Engine), redraws shapes
//! closer to a training shape than the minimum novelty, searches candidates for anatomical
//! [`targets`], and returns each finished [`CohortShape`] with its provenance ([`record`]).
//!
//! Nothing here knows SQL, HTTP or async: the command line writes the shapes to files, the
//! cohort job commits them to the database, both through [`CohortGenerator::run`].

pub mod generator;
pub mod plan;
pub mod record;
pub mod request;
pub mod sampler;
pub mod seeds;
pub mod selection;
pub mod targets;
pub mod weights;

use std::ops::RangeInclusive;

pub use generator::{CohortGenerator, CohortSetup, EngineHandle};
pub use plan::{CohortPlan, ModelLatents};
pub use record::{AnchorShare, CohortShape, ShapeProvenance, ShapeRecord};
pub use request::{CohortFields, CohortRequest, RequestError, RequestLimits, TargetSearch};
pub use sampler::{CovarianceEstimate, LatentSource, SamplerChoice, SamplerFields, SamplerKind};
pub use selection::Selection;
pub use targets::Targets;
pub use targets::feasibility::Infeasible;
pub use weights::{WeightChoice, Weighting};

use crate::geometry::marching_cubes::MAX_RESOLUTION;

/// Marching-cubes resolution of a cohort whose request names none (the paper's 256³).
pub const DEFAULT_RESOLUTION: usize = 256;
/// Resolutions a cohort may ask for.
pub const RESOLUTION_RANGE: RangeInclusive<usize> = 32..=MAX_RESOLUTION;
/// Most redraws of a shape that is closer than the requested novelty to a training shape.
pub const MAX_REDRAWS: u32 = 10;

/// Why a cohort (or one of its shapes) could not be generated.
#[derive(Debug, thiserror::Error)]
pub enum CohortError {
    /// The cancel flag was raised.
    #[error("cancelled")]
    Cancelled,
    /// The training surfaces to measure novelty against could not be built.
    #[error("training surfaces: {0:#}")]
    Reference(anyhow::Error),
    /// The training shapes could not be measured for the targets.
    #[error("targets: {0:#}")]
    Training(anyhow::Error),
    /// A target the model's training shapes cannot reach.
    #[error("targets: {0}")]
    Infeasible(Infeasible),
    /// The density sampler cannot be fitted to the model's training latents.
    #[error("sampler: cannot be fitted to the training latents: {0}")]
    Sampler(crate::latent_models::LatentModelError),
    /// One shape could not be generated.
    #[error("shape {index}: {error:#}")]
    Shape {
        /// Its index.
        index: u64,
        /// The engine's error chain.
        error: anyhow::Error,
    },
}

impl From<Infeasible> for CohortError {
    fn from(e: Infeasible) -> Self {
        Self::Infeasible(e)
    }
}
