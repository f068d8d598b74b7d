//! The convex weights of a mixture: given by the request (checked once, on the way in),
//! equal, or drawn per shape from Dirichlet(1, …, 1) (DESIGN §4).

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Allowed deviation of explicit weights' sum from 1.
pub const WEIGHT_SUM_TOLERANCE: f64 = 1e-6;

/// How weights are chosen when the request gives none.
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    Eq,
    Serialize,
    Deserialize,
    utoipa::ToSchema,
    clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum Weighting {
    /// 1/k each.
    Equal,
    /// Dirichlet(1, …, 1), i.e. uniform on the simplex, drawn per shape from its seed.
    #[default]
    Dirichlet,
}

impl Weighting {
    /// The stored name.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Equal => "equal",
            Self::Dirichlet => "dirichlet",
        }
    }

    /// Parses a stored name.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "equal" => Some(Self::Equal),
            "dirichlet" => Some(Self::Dirichlet),
            _ => None,
        }
    }
}

/// Where each shape's weights come from, once the request's rules hold.
#[derive(Debug, Clone, PartialEq)]
pub enum WeightChoice {
    /// The same checked weights for every shape.
    Fixed(Vec<f64>),
    /// 1/k each.
    Equal,
    /// Drawn per shape from Dirichlet(1, …, 1).
    Dirichlet,
}

impl WeightChoice {
    /// The choice of a request that gives `weights` (checked against `arity`) or else
    /// `weighting`.
    pub fn new(
        weights: Option<Vec<f64>>,
        weighting: Weighting,
        arity: usize,
    ) -> Result<Self, WeightError> {
        match weights {
            Some(w) => {
                check_weights(&w, arity)?;
                Ok(Self::Fixed(w))
            }
            None => Ok(match weighting {
                Weighting::Equal => Self::Equal,
                Weighting::Dirichlet => Self::Dirichlet,
            }),
        }
    }

    /// The explicit weights, if the request gave them.
    pub fn fixed(&self) -> Option<&[f64]> {
        match self {
            Self::Fixed(w) => Some(w),
            _ => None,
        }
    }

    /// The strategy recorded with the cohort (`dirichlet` stands beside fixed weights, which
    /// override it, as the request's default).
    pub fn weighting(&self) -> Weighting {
        match self {
            Self::Equal => Weighting::Equal,
            Self::Fixed(_) | Self::Dirichlet => Weighting::Dirichlet,
        }
    }

    /// Whether the weights are drawn per shape (only drawn weights may be refined towards
    /// anatomical targets: weights the request fixes, explicitly or as `equal`, stay).
    pub fn is_drawn(&self) -> bool {
        matches!(self, Self::Dirichlet)
    }

    /// The `arity` weights of one shape, drawing from `rng` when they are drawn.
    pub fn draw(&self, rng: &mut ChaCha8Rng, arity: usize) -> Vec<f64> {
        match self {
            Self::Fixed(w) => w.clone(),
            Self::Equal => vec![1.0 / arity as f64; arity],
            Self::Dirichlet => dirichlet_ones(rng, arity),
        }
    }
}

/// A rule explicit weights break; the message names the rule (and the entry).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WeightError {
    /// Not one weight per mixed shape.
    #[error("must have arity = {arity} entries, got {found}")]
    Count {
        /// The request's arity.
        arity: usize,
        /// Weights given.
        found: usize,
    },
    /// NaN or infinite.
    #[error("entry {index} is not a finite number")]
    NonFinite {
        /// Zero-based position.
        index: usize,
    },
    /// Below zero.
    #[error("entry {index} is negative ({value}); weights must be ≥ 0")]
    Negative {
        /// Zero-based position.
        index: usize,
        /// The value.
        value: f64,
    },
    /// Off the simplex.
    #[error("must sum to 1 within {WEIGHT_SUM_TOLERANCE:e}, sum is {sum}")]
    Sum {
        /// Their sum.
        sum: f64,
    },
}

impl WeightError {
    /// The short rule name of API errors.
    pub fn rule(&self) -> &'static str {
        match self {
            Self::Count { .. } => "length",
            Self::NonFinite { .. } => "finite",
            Self::Negative { .. } => "non-negative",
            Self::Sum { .. } => "sum",
        }
    }
}

/// Checks explicit weights: one per mixed shape, finite, ≥ 0, summing to 1.
pub fn check_weights(weights: &[f64], arity: usize) -> Result<(), WeightError> {
    if weights.len() != arity {
        let found = weights.len();
        return Err(WeightError::Count { arity, found });
    }
    if let Some(index) = weights.iter().position(|w| !w.is_finite()) {
        return Err(WeightError::NonFinite { index });
    }
    if let Some(index) = weights.iter().position(|w| *w < 0.0) {
        let value = weights[index];
        return Err(WeightError::Negative { index, value });
    }
    let sum: f64 = weights.iter().sum();
    if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
        return Err(WeightError::Sum { sum });
    }
    Ok(())
}

/// A draw from Dirichlet(1, …, 1): normalised Exp(1) variables, −ln(1 − U).
pub fn dirichlet_ones(rng: &mut ChaCha8Rng, k: usize) -> Vec<f64> {
    let draws: Vec<f64> = (0..k).map(|_| -(1.0 - rng.random::<f64>()).ln()).collect();
    let sum: f64 = draws.iter().sum();
    draws.into_iter().map(|d| d / sum).collect()
}

/// Parses `"0.5,0.25,0.25"` (whitespace allowed) into weights, naming a bad entry.
pub fn parse_weights(text: &str) -> Result<Vec<f64>, String> {
    text.split(',')
        .enumerate()
        .map(|(i, s)| {
            s.trim()
                .parse::<f64>()
                .map_err(|e| format!("weight {i} ({:?}) is not a number: {e}", s.trim()))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn weight_rules_name_the_failed_rule() {
        assert!(check_weights(&[0.5, 0.5], 2).is_ok());
        assert!(check_weights(&[0.5, 0.5 + 0.9e-6], 2).is_ok());
        let message = |w: &[f64]| check_weights(w, 2).unwrap_err().to_string();
        assert!(message(&[0.5]).contains("arity = 2"));
        assert!(message(&[f64::NAN, 1.0]).contains("finite"));
        assert!(message(&[-0.5, 1.5]).contains("negative"));
        assert!(message(&[0.5, 0.6]).contains("sum to 1"));
        assert_eq!(check_weights(&[0.5, 0.6], 2).unwrap_err().rule(), "sum");
    }

    #[test]
    fn drawn_weights_lie_on_the_simplex_with_the_dirichlet_mean() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut first_mean = 0.0;
        for _ in 0..2000 {
            let w = WeightChoice::Dirichlet.draw(&mut rng, 4);
            assert!(check_weights(&w, 4).is_ok(), "{w:?}");
            first_mean += w[0] / 2000.0;
        }
        // Dirichlet(1,1,1,1) has E[w_0] = 1/4; the standard error over 2000 draws is ~0.004.
        assert!((first_mean - 0.25).abs() < 0.02, "{first_mean}");
        assert_eq!(WeightChoice::Equal.draw(&mut rng, 4), vec![0.25; 4]);
    }

    #[test]
    fn explicit_weights_are_checked_once_and_kept() {
        let fixed = WeightChoice::new(Some(vec![0.1, 0.9]), Weighting::Equal, 2).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        assert_eq!(fixed.draw(&mut rng, 2), vec![0.1, 0.9]);
        assert!(!fixed.is_drawn());
        let err = WeightChoice::new(Some(vec![0.1, 0.9]), Weighting::Equal, 3).unwrap_err();
        assert_eq!(err.rule(), "length");
    }

    #[test]
    fn weights_parse_from_text_naming_a_bad_entry() {
        assert_eq!(parse_weights("0.5, 0.25,0.25").unwrap(), [0.5, 0.25, 0.25]);
        assert!(parse_weights("0.5,x").unwrap_err().contains("weight 1"));
    }
}
