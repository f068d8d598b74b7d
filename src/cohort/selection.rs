//! Which training latents a generated shape mixes: `k` distinct ones, uniformly or spread
//! out over the latent space.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// How the `k` training latents of a generated shape are picked.
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    Eq,
    Serialize,
    Deserialize,
    clap::ValueEnum,
    utoipa::ToSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Selection {
    /// k distinct training shapes, uniformly at random.
    #[default]
    Uniform,
    /// Variance-aware, k-means++ style: the first with probability ∝ its squared distance
    /// to the mean latent, each next ∝ its smallest squared distance to those already
    /// chosen, so mixtures combine dissimilar shapes and spread over the latent space.
    Spread,
}

impl Selection {
    /// The stored name.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Uniform => "uniform",
            Self::Spread => "spread",
        }
    }

    /// Parses a stored name.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "uniform" => Some(Self::Uniform),
            "spread" => Some(Self::Spread),
            _ => None,
        }
    }

    /// Whether picking needs the training latents themselves (not only their number).
    pub fn needs_latents(self) -> bool {
        self == Self::Spread
    }
}

/// `k` distinct indices of `0..n` in random order (partial Fisher–Yates).
pub fn choose_distinct(rng: &mut ChaCha8Rng, n: usize, k: usize) -> Vec<usize> {
    let mut pool: Vec<usize> = (0..n).collect();
    let k = k.min(n);
    for i in 0..k {
        let j = rng.random_range(i..n);
        pool.swap(i, j);
    }
    pool.truncate(k);
    pool
}

/// k-means++ style selection of `k` distinct latents (see [`Selection::Spread`]).
pub fn select_spread(rng: &mut ChaCha8Rng, latents: &[Vec<f32>], k: usize) -> Vec<usize> {
    let n = latents.len();
    let k = k.min(n);
    if k == 0 {
        return Vec::new();
    }
    let dim = latents[0].len();
    let mut mean = vec![0.0f64; dim];
    for z in latents {
        for (m, &v) in mean.iter_mut().zip(z) {
            *m += f64::from(v) / n as f64;
        }
    }
    let mut weights: Vec<f64> = latents.iter().map(|z| squared_distance(z, &mean)).collect();
    let mut eligible = vec![true; n];
    let mut chosen = Vec::with_capacity(k);
    while chosen.len() < k {
        let pick = draw_weighted(rng, &weights, &eligible);
        chosen.push(pick);
        eligible[pick] = false;
        let centre: Vec<f64> = latents[pick].iter().map(|&v| f64::from(v)).collect();
        for (i, w) in weights.iter_mut().enumerate() {
            *w = if eligible[i] {
                let d = squared_distance(&latents[i], &centre);
                if chosen.len() == 1 { d } else { w.min(d) }
            } else {
                0.0
            };
        }
    }
    chosen
}

fn squared_distance(a: &[f32], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| (f64::from(x) - y).powi(2))
        .sum()
}

/// Draws an index with probability ∝ `weights`; uniform over the `eligible` ones when every
/// weight is zero (all remaining latents coincide with chosen ones).
fn draw_weighted(rng: &mut ChaCha8Rng, weights: &[f64], eligible: &[bool]) -> usize {
    let total: f64 = weights.iter().sum();
    if total > 0.0 && total.is_finite() {
        let mut target = rng.random::<f64>() * total;
        let mut last = 0;
        for (i, &w) in weights.iter().enumerate() {
            if w > 0.0 {
                last = i;
                if target < w {
                    return i;
                }
                target -= w;
            }
        }
        return last;
    }
    let open: Vec<usize> = (0..eligible.len()).filter(|&i| eligible[i]).collect();
    open[rng.random_range(0..open.len())]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdf::inference::mixing::test_support::clustered_latents;
    use rand::SeedableRng;

    fn distance(a: &[f32], b: &[f32]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| f64::from(x - y).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    fn pick(selection: Selection, seed: u64, latents: &[Vec<f32>], k: usize) -> Vec<usize> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        match selection {
            Selection::Uniform => choose_distinct(&mut rng, latents.len(), k),
            Selection::Spread => select_spread(&mut rng, latents, k),
        }
    }

    #[test]
    fn spread_selection_picks_farther_apart_latents_than_uniform() {
        let latents = clustered_latents();
        let mean_pair_distance = |selection: Selection| {
            let (mut total, mut pairs) = (0.0, 0);
            for seed in 0..500 {
                let picked = pick(selection, seed, &latents, 3);
                let mut sorted = picked.clone();
                sorted.sort_unstable();
                sorted.dedup();
                assert_eq!(
                    sorted.len(),
                    3,
                    "{selection:?} repeated an index: {picked:?}"
                );
                for i in 0..3 {
                    for j in i + 1..3 {
                        total += distance(&latents[picked[i]], &latents[picked[j]]);
                        pairs += 1;
                    }
                }
            }
            total / f64::from(pairs)
        };
        let uniform = mean_pair_distance(Selection::Uniform);
        let spread = mean_pair_distance(Selection::Spread);
        assert!(
            spread > 1.5 * uniform,
            "spread {spread} vs uniform {uniform}"
        );
    }

    #[test]
    fn spread_selection_handles_coincident_latents() {
        let latents = vec![vec![1.0f32, 1.0]; 5];
        let mut picked = pick(Selection::Spread, 2, &latents, 4);
        picked.sort_unstable();
        picked.dedup();
        assert_eq!(picked.len(), 4);
    }

    #[test]
    fn distinct_choices_are_in_range_and_never_repeat() {
        for seed in 0..200 {
            let mut idx = pick(Selection::Uniform, seed, &clustered_latents(), 4);
            assert!(idx.iter().all(|&j| j < 20));
            idx.sort_unstable();
            idx.dedup();
            assert_eq!(idx.len(), 4, "seed {seed}");
        }
    }
}
