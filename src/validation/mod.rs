//! Validation of a virtual cohort against a real population (DESIGN §8): is the cohort
//! representative of the patients a trial is about?
//!
//! * [`population`]: the compared sets — a generated cohort, a reference of real meshes or
//!   a measurements table ([`table`], SIMCor's column names accepted), the model's
//!   training and held-out shapes — each member with its surface (mm) and features;
//! * [`features`]: the compared measurements;
//! * [`shapes`]: the shape level — MMD, COV and 1-NNA on common-scale Chamfer distances
//!   (equal-size subsets with intervals), pairwise diversity, DCR beside new patients, and
//!   the same for the training shapes (the real-vs-real baseline);
//! * [`measures`]: the measurement level — summaries, histograms, KS, Wasserstein, ECDF
//!   area, SIMCor's bootstrap band test, TOST, and jointly Mahalanobis and Spearman;
//! * [`criteria`]: acceptance criteria → checks → pass, fail or inconclusive;
//! * [`report`]: the report with its credibility dossier, and [`report::validate`].
//!
//! Nothing here knows SQL or HTTP: the command line (`aortagen validate`) and the
//! service's validation job build the populations their way and call [`report::validate`].

pub mod criteria;
pub mod features;
pub mod measures;
pub mod population;
pub mod report;
pub mod shapes;
pub mod sources;
pub mod table;

pub use criteria::{AcceptanceCriteria, Criteria, Verdict};
pub use features::Feature;
pub use population::{Member, Population, StoredShape};
pub use report::{Dossier, Subject, ValidationInput, ValidationReport, validate};
pub use shapes::{Newcomers, Progress, ShapeInputs, ShapeSettings};

/// A broken rule of a validation's input (a request field, a table column or row); the
/// service answers it as 422 problem+json naming `field`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct InputError {
    /// The offending field (`criteria.nna_max`, `columns[D_an [cm]]`, `rows[3].D_an`).
    pub field: String,
    /// Short rule name.
    pub rule: &'static str,
    /// Human sentence.
    pub message: String,
}

impl InputError {
    /// A broken `rule` of `field`.
    pub fn new(field: impl Into<String>, rule: &'static str, message: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            rule,
            message: message.into(),
        }
    }
}
