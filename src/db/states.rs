//! The closed sets of values some columns hold (each one has a CHECK constraint in the
//! schema), as enums read and written through sqlx, so no handler compares strings.

use serde::{Deserialize, Serialize};
use sqlx::any::{Any, AnyTypeInfo};
use sqlx::encode::IsNull;
use sqlx::error::BoxDynError;
use sqlx::{Database, Decode, Encode, Type};

use crate::cohort::{Selection, Weighting};

/// Implements sqlx's TEXT mapping for an enum with `as_str` and `parse`.
macro_rules! text_column {
    ($($t:ty),* $(,)?) => {$(
        impl Type<Any> for $t {
            fn type_info() -> AnyTypeInfo {
                <&str as Type<Any>>::type_info()
            }
            fn compatible(ty: &AnyTypeInfo) -> bool {
                <&str as Type<Any>>::compatible(ty)
            }
        }

        impl Encode<'_, Any> for $t {
            fn encode_by_ref(
                &self,
                buf: &mut <Any as Database>::ArgumentBuffer,
            ) -> Result<IsNull, BoxDynError> {
                <&str as Encode<'_, Any>>::encode(self.as_str(), buf)
            }
        }

        impl<'r> Decode<'r, Any> for $t {
            fn decode(value: <Any as Database>::ValueRef<'r>) -> Result<Self, BoxDynError> {
                let text = <&str as Decode<'r, Any>>::decode(value)?;
                <$t>::parse(text).ok_or_else(|| {
                    format!("{text:?} is not a valid {}", stringify!($t)).into()
                })
            }
        }
    )*};
}

/// Declares a column enum: serde and OpenAPI use the same lower-case names as the column.
macro_rules! column_enum {
    ($(#[$doc:meta])* $name:ident { $($(#[$vdoc:meta])* $variant:ident = $text:literal),* $(,)? }) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
        #[serde(rename_all = "lowercase")]
        pub enum $name {
            $($(#[$vdoc])* $variant),*
        }

        impl $name {
            /// Every value, in the schema's order.
            pub const ALL: &[Self] = &[$(Self::$variant),*];

            /// The column value.
            pub fn as_str(self) -> &'static str {
                match self {
                    $(Self::$variant => $text),*
                }
            }

            /// Parses a column value.
            pub fn parse(text: &str) -> Option<Self> {
                match text {
                    $($text => Some(Self::$variant),)*
                    _ => None,
                }
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.as_str())
            }
        }
    };
}

column_enum! {
    /// What a job does.
    JobKind {
        /// Generates a cohort's shapes and metrics.
        Cohort = "cohort",
        /// Trains a model from uploaded meshes.
        Training = "training",
        /// Fits a latent to a new mesh (an anchor).
        Fit = "fit",
        /// Validate a cohort against a reference population.
        Validation = "validation",
        /// Fits a model's training shapes again with the network frozen.
        Refit = "refit",
    }
}

column_enum! {
    /// Where a job stands.
    JobStatus {
        /// Waiting for a worker.
        Queued = "queued",
        /// Claimed by a worker.
        Running = "running",
        /// Done.
        Succeeded = "succeeded",
        /// Given up (see its error).
        Failed = "failed",
        /// Stopped on request.
        Cancelled = "cancelled",
    }
}

column_enum! {
    /// What a task (a unit of a job one worker runs under a lease) makes.
    TaskKind {
        /// One training shape reconstructed at a cohort's resolution (novelty reference).
        Surface = "surface",
        /// The model's training shapes measured (targeted cohorts).
        Anatomy = "anatomy",
        /// One generated shape of a cohort.
        Shape = "shape",
        /// A cohort's pairwise statistics, after its last shape.
        Metrics = "metrics",
        /// A whole training.
        Training = "training",
        /// A whole fit.
        Fit = "fit",
        /// A whole validation.
        Validation = "validation",
        /// One training shape re-fitted with the network frozen.
        Refit = "refit",
    }
}

column_enum! {
    /// Where a task stands.
    TaskStatus {
        /// Waiting for a worker.
        Queued = "queued",
        /// Held by a worker's lease.
        Running = "running",
        /// Its result is committed.
        Done = "done",
        /// Gave up; its job failed with it.
        Failed = "failed",
        /// Its job was cancelled or failed before it finished.
        Cancelled = "cancelled",
    }
}

column_enum! {
    /// Where a model stands.
    ModelStatus {
        /// Its training job runs.
        Training = "training",
        /// Cohorts may be drawn from it.
        Ready = "ready",
        /// Its training failed or was cancelled.
        Failed = "failed",
    }
}

column_enum! {
    /// Where a fitted anchor stands.
    AnchorStatus {
        /// Its fit job runs.
        Fitting = "fitting",
        /// Its latent is fitted.
        Ready = "ready",
        /// The fit failed or was cancelled.
        Failed = "failed",
    }
}

impl JobStatus {
    /// Whether the job still waits or runs (it counts against the queue bound).
    pub fn is_pending(self) -> bool {
        matches!(self, Self::Queued | Self::Running)
    }
}

text_column!(
    JobKind,
    JobStatus,
    TaskKind,
    TaskStatus,
    ModelStatus,
    AnchorStatus,
    Weighting,
    Selection
);
