//! `anchors.json`: latents fitted to new shapes after training, kept beside a model.
//!
//! An anchor is a fitted latent ([`crate::sdf::training::fit`]) with its unit-ball transform and its
//! reconstruction Chamfer distance. Anchors live in their own file so the manifest and its
//! weights hash (the model's identity) never change; the file records the weights hash it
//! belongs to and is rejected for any other model ([`super::sidecar`]).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::sidecar::{Sidecar, SidecarError};
use crate::geometry::normalize::UnitBallTransform;
use crate::sdf::store::manifest::ModelManifest;

/// File name inside a model directory.
pub const ANCHORS_FILE: &str = "anchors.json";
/// Value of the `format` field.
pub const ANCHORS_FORMAT: &str = "aortagen-anchors";
/// The layout this build reads and writes.
pub const ANCHORS_VERSION: u32 = 1;

const ANCHORS: Sidecar = Sidecar {
    file: ANCHORS_FILE,
    format: ANCHORS_FORMAT,
    version: ANCHORS_VERSION,
    kind: "anchors",
};

/// One fitted shape.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Anchor {
    /// Unique within the file.
    pub name: String,
    /// The fitted latent (the model's latent dimension).
    pub latent: Vec<f32>,
    /// Mesh units ↔ unit ball of the fitted mesh.
    pub transform: UnitBallTransform,
    /// Reconstruction Chamfer distance (unit-ball coordinates).
    pub chamfer: f64,
    /// File the shape was read from.
    pub source: String,
    /// Adam steps of the fit.
    pub iterations: usize,
    /// Seed of the fit.
    pub seed: u64,
    /// When it was fitted, seconds since the Unix epoch.
    pub created_unix: u64,
}

impl Anchor {
    /// Checks the latent's length and values and the transform: the rules every fitted
    /// latent kept beside a model obeys (the reason when one is broken).
    pub fn check(&self, latent_dim: usize) -> Result<(), String> {
        if self.latent.len() != latent_dim {
            return Err(format!(
                "the latent has {} values, the model's latent dimension is {latent_dim}",
                self.latent.len()
            ));
        }
        if self.latent.iter().any(|v| !v.is_finite()) || !self.chamfer.is_finite() {
            return Err("the latent or its Chamfer distance is not finite".into());
        }
        let t = &self.transform;
        if !(t.radius.is_finite() && t.radius > 0.0 && t.centre.iter().all(|c| c.is_finite())) {
            return Err("the transform needs a finite centre and radius > 0".into());
        }
        Ok(())
    }
}

/// The whole file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnchorSet {
    /// Always [`ANCHORS_FORMAT`].
    pub format: String,
    /// [`ANCHORS_VERSION`].
    pub format_version: u32,
    /// SHA-256 of the weights the latents were fitted for.
    pub weights_sha256: String,
    /// The anchors, in the order they were added.
    pub anchors: Vec<Anchor>,
}

/// Why an anchors file or a new anchor is refused.
#[derive(Debug, thiserror::Error)]
pub enum AnchorError {
    /// The file cannot be read, written or used.
    #[error(transparent)]
    File(#[from] SidecarError),
    /// A new anchor breaks a rule.
    #[error("anchor {name:?}: {reason}")]
    Rejected {
        /// The anchor's name.
        name: String,
        /// The broken rule.
        reason: String,
    },
}

impl AnchorSet {
    /// An empty set for `manifest`'s weights.
    pub fn empty(manifest: &ModelManifest) -> Self {
        Self {
            format: ANCHORS_FORMAT.into(),
            format_version: ANCHORS_VERSION,
            weights_sha256: manifest.weights.sha256.clone(),
            anchors: Vec::new(),
        }
    }

    /// The anchors of the model in `dir` (empty when it has no file), checked against
    /// `manifest`.
    pub fn load(dir: &Path, manifest: &ModelManifest) -> Result<Self, AnchorError> {
        let Some(set) = ANCHORS.read::<Self>(dir, &manifest.weights.sha256)? else {
            return Ok(Self::empty(manifest));
        };
        let mut checked = Self::empty(manifest);
        for anchor in set.anchors {
            checked
                .add(anchor, manifest.architecture.latent_dim)
                .map_err(|e| ANCHORS.invalid(dir, e.to_string()))?;
        }
        Ok(checked)
    }

    /// Adds `anchor` after checking its name, latent length and values.
    pub fn add(&mut self, anchor: Anchor, latent_dim: usize) -> Result<(), AnchorError> {
        let reject = |reason: String| AnchorError::Rejected {
            name: anchor.name.clone(),
            reason,
        };
        if anchor.name.trim().is_empty() {
            return Err(reject("the name is empty".into()));
        }
        if self.anchors.iter().any(|a| a.name == anchor.name) {
            return Err(reject(
                "the model already has an anchor of this name".into(),
            ));
        }
        anchor.check(latent_dim).map_err(reject)?;
        self.anchors.push(anchor);
        Ok(())
    }

    /// The anchors named by `names`, in that order, for a cohort of `arity`: each name once,
    /// at most `arity` of them; an unknown name is an error that lists the known ones.
    pub fn pick(&self, names: &[String], arity: usize) -> Result<Vec<Anchor>, AnchorError> {
        let rejected = |name: &str, reason: String| AnchorError::Rejected {
            name: name.to_string(),
            reason,
        };
        if names.len() > arity {
            return Err(rejected(
                &names[arity],
                format!(
                    "at most arity = {arity} anchors fit a shape, got {}",
                    names.len()
                ),
            ));
        }
        names
            .iter()
            .enumerate()
            .map(|(i, name)| {
                if names[..i].contains(name) {
                    return Err(rejected(name, "it is listed twice".into()));
                }
                self.anchors
                    .iter()
                    .find(|a| &a.name == name)
                    .cloned()
                    .ok_or_else(|| {
                        let known: Vec<&str> =
                            self.anchors.iter().map(|a| a.name.as_str()).collect();
                        let known = match known.is_empty() {
                            true => "the model has no anchors; `aortagen fit` adds them".into(),
                            false => format!("the model's anchors are {}", known.join(", ")),
                        };
                        rejected(name, format!("no such anchor ({known})"))
                    })
            })
            .collect()
    }

    /// Writes the set to `dir/anchors.json` (temporary file, then rename).
    pub fn save(&self, dir: &Path) -> Result<(), AnchorError> {
        Ok(ANCHORS.write(dir, self)?)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::sdf::store::manifest::FileRecord;

    fn anchor(name: &str, dim: usize) -> Anchor {
        Anchor {
            name: name.into(),
            latent: vec![0.5; dim],
            transform: UnitBallTransform {
                centre: [1.0, 2.0, 3.0],
                radius: 40.0,
            },
            chamfer: 1e-3,
            source: format!("{name}.stl"),
            iterations: 10,
            seed: 1,
            created_unix: 0,
        }
    }

    pub(crate) fn manifest(sha: &str) -> ModelManifest {
        let setup = crate::sdf::training::config::Preset::Cpu.setup(0);
        ModelManifest {
            format: String::new(),
            format_version: 1,
            software_version: String::new(),
            backend: String::new(),
            sign_convention: String::new(),
            architecture: setup.network.with_latent_dim(4),
            training: setup.training,
            data: crate::sdf::store::manifest::DataRecord {
                source: crate::sdf::data::DataSource::Synth { count: 1, seed: 0 },
                sampling: setup.sampling,
                dataset_key: String::new(),
                holdout: None,
            },
            shapes: Vec::new(),
            progress: Default::default(),
            loss_history: Vec::new(),
            weights: FileRecord {
                file: "weights.bpk".into(),
                sha256: sha.into(),
                bytes: 0,
            },
            optimizer: None,
        }
    }

    #[test]
    fn anchors_round_trip_and_are_refused_for_other_weights() {
        let dir = tempfile::tempdir().unwrap();
        let m = manifest("aa");
        assert!(AnchorSet::load(dir.path(), &m).unwrap().anchors.is_empty());
        let mut set = AnchorSet::empty(&m);
        set.add(anchor("p1", 4), 4).unwrap();
        set.save(dir.path()).unwrap();
        assert_eq!(AnchorSet::load(dir.path(), &m).unwrap(), set);
        let err = AnchorSet::load(dir.path(), &manifest("bb")).unwrap_err();
        assert!(err.to_string().contains("other weights"), "{err}");
    }

    #[test]
    fn anchors_are_picked_by_name_in_the_given_order() {
        let m = manifest("aa");
        let mut set = AnchorSet::empty(&m);
        for name in ["p1", "p2", "p3"] {
            set.add(anchor(name, 4), 4).unwrap();
        }
        let names = |list: &[&str]| list.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let picked = set.pick(&names(&["p3", "p1"]), 2).unwrap();
        let picked: Vec<&str> = picked.iter().map(|a| a.name.as_str()).collect();
        assert_eq!(picked, ["p3", "p1"]);
        let cases = [
            (
                names(&["p9"]),
                2,
                "no such anchor (the model's anchors are p1, p2, p3)",
            ),
            (names(&["p1", "p1"]), 2, "listed twice"),
            (names(&["p1", "p2", "p3"]), 2, "at most arity = 2"),
        ];
        for (list, arity, rule) in cases {
            let err = set.pick(&list, arity).unwrap_err().to_string();
            assert!(err.contains(rule), "{err}");
        }
        let err = AnchorSet::empty(&m).pick(&names(&["p1"]), 2).unwrap_err();
        assert!(
            err.to_string().contains("`aortagen fit` adds them"),
            "{err}"
        );
    }

    #[test]
    fn a_bad_anchor_is_refused_naming_the_rule() {
        let m = manifest("aa");
        let mut set = AnchorSet::empty(&m);
        set.add(anchor("p1", 4), 4).unwrap();
        let cases = [
            (anchor("p1", 4), "already has"),
            (anchor(" ", 4), "empty"),
            (anchor("p2", 3), "latent dimension is 4"),
            (
                Anchor {
                    latent: vec![f32::NAN; 4],
                    ..anchor("p3", 4)
                },
                "not finite",
            ),
        ];
        for (bad, rule) in cases {
            let err = set.add(bad, 4).unwrap_err().to_string();
            assert!(err.contains(rule), "{err}");
        }
        assert_eq!(set.anchors.len(), 1);
    }
}
