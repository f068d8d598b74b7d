//! `refits.json`: the training shapes fitted once more after training, with the network
//! frozen, exactly as a new patient is fitted ([`crate::sdf::training::fit`]).
//!
//! Training optimises the latents jointly with the network, so they are tighter around the
//! mean than the latent a new patient's fit reaches; a density sampler fitted to them draws
//! too close to the training patients. Re-fitted latents come from the same process as a new
//! patient's, so a sampler fitted to them aims at the population the way real patients land
//! in latent space (`"latents": "refitted"` in a cohort's sampler).
//!
//! One record per training shape, in training-index order, named as in the manifest; the
//! file may hold a prefix while `aortagen refit` runs (it resumes from there), and only a
//! complete file is used for sampling. Like `anchors.json` it records the weights hash it
//! belongs to and is refused for any other model ([`super::sidecar`]).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::anchors::Anchor;
use super::sidecar::{Sidecar, SidecarError};
use crate::geometry::normalize::UnitBallTransform;
use crate::sdf::store::manifest::ModelManifest;

/// File name inside a model directory.
pub const REFITS_FILE: &str = "refits.json";
/// Value of the `format` field.
pub const REFITS_FORMAT: &str = "aortagen-refits";
/// The layout this build reads and writes.
pub const REFITS_VERSION: u32 = 1;

const REFITS: Sidecar = Sidecar {
    file: REFITS_FILE,
    format: REFITS_FORMAT,
    version: REFITS_VERSION,
    kind: "refits",
};

/// The whole file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefitSet {
    /// Always [`REFITS_FORMAT`].
    pub format: String,
    /// [`REFITS_VERSION`].
    pub format_version: u32,
    /// SHA-256 of the weights the latents were fitted for.
    pub weights_sha256: String,
    /// Training shapes 0, 1, … as fitted so far (each named as in the manifest).
    pub shapes: Vec<Anchor>,
}

/// Why a refits file or a new record is refused.
#[derive(Debug, thiserror::Error)]
pub enum RefitError {
    /// The file cannot be read, written or used.
    #[error(transparent)]
    File(#[from] SidecarError),
    /// A new record breaks a rule.
    #[error("re-fitted shape {name:?}: {reason}")]
    Rejected {
        /// The record's name.
        name: String,
        /// The broken rule.
        reason: String,
    },
}

/// Latents and transforms of every training shape, in index order.
pub type RefittedLatents = (Vec<Vec<f32>>, Vec<UnitBallTransform>);

impl RefitSet {
    /// An empty set for `manifest`'s weights.
    pub fn empty(manifest: &ModelManifest) -> Self {
        Self {
            format: REFITS_FORMAT.into(),
            format_version: REFITS_VERSION,
            weights_sha256: manifest.weights.sha256.clone(),
            shapes: Vec::new(),
        }
    }

    /// The re-fitted shapes of the model in `dir` (empty when it has no file), checked
    /// against `manifest`.
    pub fn load(dir: &Path, manifest: &ModelManifest) -> Result<Self, RefitError> {
        let Some(set) = REFITS.read::<Self>(dir, &manifest.weights.sha256)? else {
            return Ok(Self::empty(manifest));
        };
        let mut checked = Self::empty(manifest);
        for shape in set.shapes {
            checked
                .push(shape, manifest)
                .map_err(|e| REFITS.invalid(dir, e.to_string()))?;
        }
        Ok(checked)
    }

    /// Appends the next training shape's record after checking that it is that shape (its
    /// name) and that its latent and transform are usable.
    pub fn push(&mut self, shape: Anchor, manifest: &ModelManifest) -> Result<(), RefitError> {
        let reject = |reason: String| RefitError::Rejected {
            name: shape.name.clone(),
            reason,
        };
        let index = self.shapes.len();
        let Some(expected) = manifest.shapes.get(index) else {
            return Err(reject(format!(
                "the model has only {} training shapes",
                manifest.shapes.len()
            )));
        };
        if shape.name != expected.name {
            return Err(reject(format!(
                "training shape {index} is {:?}",
                expected.name
            )));
        }
        shape
            .check(manifest.architecture.latent_dim)
            .map_err(reject)?;
        self.shapes.push(shape);
        Ok(())
    }

    /// Whether every training shape of `manifest` has its record.
    pub fn is_complete(&self, manifest: &ModelManifest) -> bool {
        self.shapes.len() == manifest.shapes.len()
    }

    /// The latents and transforms for sampling; none until the set is complete.
    pub fn latents(&self, manifest: &ModelManifest) -> Option<RefittedLatents> {
        self.is_complete(manifest).then(|| {
            self.shapes
                .iter()
                .map(|s| (s.latent.clone(), s.transform))
                .unzip()
        })
    }

    /// Writes the set to `dir/refits.json` (temporary file, then rename).
    pub fn save(&self, dir: &Path) -> Result<(), RefitError> {
        Ok(REFITS.write(dir, self)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdf::store::manifest::ShapeRecord;

    fn record(name: &str, value: f32) -> Anchor {
        Anchor {
            name: name.into(),
            latent: vec![value; 4],
            transform: UnitBallTransform {
                centre: [1.0, 2.0, value as f64],
                radius: 40.0,
            },
            chamfer: 1e-4,
            source: format!("{name}.ply"),
            iterations: 10,
            seed: 2,
            created_unix: 0,
        }
    }

    fn manifest(sha: &str, names: &[&str]) -> ModelManifest {
        let mut m = crate::sdf::store::anchors::tests::manifest(sha);
        m.shapes = names
            .iter()
            .map(|n| ShapeRecord {
                name: (*n).into(),
                transform: record(n, 0.0).transform,
            })
            .collect();
        m
    }

    #[test]
    fn a_complete_set_round_trips_and_gives_the_latents_in_training_order() {
        let dir = tempfile::tempdir().unwrap();
        let m = manifest("aa", &["a", "b"]);
        let mut set = RefitSet::load(dir.path(), &m).unwrap();
        assert!(set.shapes.is_empty());
        set.push(record("a", 0.25), &m).unwrap();
        set.save(dir.path()).unwrap();
        let partial = RefitSet::load(dir.path(), &m).unwrap();
        assert_eq!(partial, set);
        assert_eq!(
            partial.latents(&m),
            None,
            "a prefix is not used for sampling"
        );
        set.push(record("b", 0.5), &m).unwrap();
        set.save(dir.path()).unwrap();
        let (latents, transforms) = RefitSet::load(dir.path(), &m).unwrap().latents(&m).unwrap();
        assert_eq!(latents, [vec![0.25; 4], vec![0.5; 4]]);
        assert_eq!(transforms[1].centre[2], 0.5);
        assert!(!dir.path().join(format!(".{REFITS_FILE}.tmp")).exists());
    }

    #[test]
    fn records_out_of_order_unusable_or_for_other_weights_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let m = manifest("aa", &["a", "b"]);
        let mut set = RefitSet::empty(&m);
        let err = set.push(record("b", 0.1), &m).unwrap_err();
        assert!(
            err.to_string().contains("training shape 0 is \"a\""),
            "{err}"
        );
        let mut nan = record("a", 0.1);
        nan.latent[2] = f32::NAN;
        assert!(
            set.push(nan, &m)
                .unwrap_err()
                .to_string()
                .contains("finite")
        );
        let mut short = record("a", 0.1);
        short.latent.pop();
        assert!(set.push(short, &m).is_err());
        set.push(record("a", 0.1), &m).unwrap();
        set.push(record("b", 0.1), &m).unwrap();
        let err = set.push(record("c", 0.1), &m).unwrap_err();
        assert!(err.to_string().contains("only 2 training shapes"), "{err}");
        set.save(dir.path()).unwrap();
        let err = RefitSet::load(dir.path(), &manifest("bb", &["a", "b"])).unwrap_err();
        assert!(err.to_string().contains("other weights"), "{err}");
        let err = RefitSet::load(dir.path(), &manifest("aa", &["a", "x"])).unwrap_err();
        assert!(
            err.to_string().contains("training shape 1 is \"x\""),
            "{err}"
        );
        std::fs::write(dir.path().join(REFITS_FILE), b"{\"format\": 1}").unwrap();
        assert!(
            RefitSet::load(dir.path(), &m)
                .unwrap_err()
                .to_string()
                .contains("not readable")
        );
    }
}
