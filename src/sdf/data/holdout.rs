//! Held-out evaluation: a stated number of the source shapes is kept out of training, chosen
//! deterministically from a seed, so the trained model can be tested on shapes it has never
//! seen (DeepSDF's test protocol: fit their latents with the network frozen, report their
//! reconstruction beside the training shapes') and its cohorts compared with new patients.
//!
//! The choice is a ChaCha8 shuffle of the source indices seeded with the holdout seed: the
//! first `count` are held out. Both sets keep the source order (file-name order for a
//! directory), and the manifest records the held-out shapes by name and source index so a
//! resumed run, an evaluation or a validation finds the same split again.

use anyhow::{bail, ensure};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{DataSource, load_source_meshes};
use crate::geometry::TriMesh;

/// Stream tag mixed into the holdout seed, so the split does not share a stream with the
/// training batches drawn from the same seed.
const HOLDOUT_STREAM: u64 = 0x484f_4c44_4f55_5421;

/// How many shapes to hold out, and the seed that picks them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct HoldoutSpec {
    /// Shapes held out (≥ 1, leaving at least two to train on).
    pub count: usize,
    /// Seed of the choice.
    pub seed: u64,
}

/// One held-out shape, as the manifest records it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct HeldOutShape {
    /// Its name (file stem or generated name).
    pub name: String,
    /// Its position among the source shapes (file-name order).
    pub source_index: usize,
}

/// The held-out part of a model's data.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Holdout {
    /// How the shapes were chosen.
    pub spec: HoldoutSpec,
    /// The held-out shapes, in source order.
    pub shapes: Vec<HeldOutShape>,
}

/// Source shapes split into the training set and the held-out set, both in source order.
#[derive(Debug, Clone)]
pub struct SplitShapes {
    /// Shapes the model trains on.
    pub training: Vec<(String, TriMesh)>,
    /// Shapes kept out (empty without a holdout).
    pub heldout: Vec<(String, TriMesh)>,
    /// The record of the split (none without a holdout).
    pub holdout: Option<Holdout>,
}

/// The source indices held out of `n` shapes by `spec`, ascending.
pub fn heldout_indices(n: usize, spec: &HoldoutSpec) -> anyhow::Result<Vec<usize>> {
    ensure!(
        spec.count >= 1,
        "--holdout must hold out at least one shape"
    );
    ensure!(
        spec.count + 2 <= n,
        "--holdout {} leaves {} of the {n} shapes to train on; at least 2 are needed",
        spec.count,
        n.saturating_sub(spec.count)
    );
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(spec.seed ^ HOLDOUT_STREAM));
    let mut chosen = order[..spec.count].to_vec();
    chosen.sort_unstable();
    Ok(chosen)
}

/// Splits `meshes` (source order) by `spec`; without a spec everything trains.
pub fn split(
    meshes: Vec<(String, TriMesh)>,
    spec: Option<&HoldoutSpec>,
) -> anyhow::Result<SplitShapes> {
    let Some(spec) = spec else {
        return Ok(SplitShapes {
            training: meshes,
            heldout: Vec::new(),
            holdout: None,
        });
    };
    let chosen = heldout_indices(meshes.len(), spec)?;
    let mut split = SplitShapes {
        training: Vec::new(),
        heldout: Vec::new(),
        holdout: Some(Holdout {
            spec: *spec,
            shapes: Vec::new(),
        }),
    };
    for (index, (name, mesh)) in meshes.into_iter().enumerate() {
        if chosen.binary_search(&index).is_ok() {
            if let Some(h) = split.holdout.as_mut() {
                h.shapes.push(HeldOutShape {
                    name: name.clone(),
                    source_index: index,
                });
            }
            split.heldout.push((name, mesh));
        } else {
            split.training.push((name, mesh));
        }
    }
    Ok(split)
}

/// Reads `source` and splits it again as `holdout` records, checking that the held-out
/// shapes still carry their recorded names (the data has not changed under the model).
pub fn load_split(source: &DataSource, holdout: Option<&Holdout>) -> anyhow::Result<SplitShapes> {
    let meshes = load_source_meshes(source)?;
    let split = split(meshes, holdout.map(|h| &h.spec))?;
    if let (Some(recorded), Some(found)) = (holdout, &split.holdout)
        && recorded.shapes != found.shapes
    {
        bail!(
            "the training data changed: the model held out {:?}, the data now gives {:?}",
            names(&recorded.shapes),
            names(&found.shapes)
        );
    }
    Ok(split)
}

fn names(shapes: &[HeldOutShape]) -> Vec<&str> {
    shapes.iter().map(|s| s.name.as_str()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn named(n: usize) -> Vec<(String, TriMesh)> {
        (0..n)
            .map(|i| (format!("shape_{i:02}"), TriMesh::default()))
            .collect()
    }

    #[test]
    fn the_split_is_a_partition_fixed_by_the_seed() {
        let spec = HoldoutSpec { count: 5, seed: 3 };
        let s = split(named(20), Some(&spec)).unwrap();
        assert_eq!((s.training.len(), s.heldout.len()), (15, 5));
        let mut all: Vec<&str> = s
            .training
            .iter()
            .chain(&s.heldout)
            .map(|(n, _)| n.as_str())
            .collect();
        all.sort_unstable();
        all.dedup();
        assert_eq!(all.len(), 20, "every shape exactly once");
        let h = s.holdout.unwrap();
        let again = split(named(20), Some(&spec)).unwrap().holdout.unwrap();
        assert_eq!(h, again);
        assert!(
            h.shapes
                .windows(2)
                .all(|w| w[0].source_index < w[1].source_index)
        );
        for shape in &h.shapes {
            assert_eq!(shape.name, format!("shape_{:02}", shape.source_index));
        }
        let other = split(named(20), Some(&HoldoutSpec { count: 5, seed: 4 }))
            .unwrap()
            .holdout
            .unwrap();
        assert_ne!(h.shapes, other.shapes);
    }

    #[test]
    fn every_shape_is_held_out_about_equally_often_over_seeds() {
        // 400 seeds × 3 of 12: each index expects 100 picks (sd ≈ 9.6 binomially).
        let mut picks = [0usize; 12];
        for seed in 0..400 {
            for i in heldout_indices(12, &HoldoutSpec { count: 3, seed }).unwrap() {
                picks[i] += 1;
            }
        }
        assert!(picks.iter().all(|&p| (60..=140).contains(&p)), "{picks:?}");
    }

    #[test]
    fn too_large_or_empty_holdouts_are_refused() {
        assert!(heldout_indices(10, &HoldoutSpec { count: 0, seed: 0 }).is_err());
        assert!(heldout_indices(10, &HoldoutSpec { count: 8, seed: 0 }).is_ok());
        let err = heldout_indices(10, &HoldoutSpec { count: 9, seed: 0 }).unwrap_err();
        assert!(err.to_string().contains("at least 2"), "{err}");
    }

    #[test]
    fn no_spec_trains_on_everything() {
        let s = split(named(4), None).unwrap();
        assert_eq!((s.training.len(), s.heldout.len()), (4, 0));
        assert!(s.holdout.is_none());
    }
}
