//! Shape-level metrics of a generated cohort against a reference population, computed on
//! precomputed distance matrices (Chamfer distances on a common scale, DESIGN §8), so the
//! expensive geometry stays in `geometry::chamfer` and these functions stay pure:
//!
//! * [`coverage`]: MMD (fidelity) and COV (coverage), as in PointFlow's
//!   `lgan_mmd_cov` (stevenygd/PointFlow, `metrics/evaluation_metrics.py`);
//! * [`nna`]: the leave-one-out 1-nearest-neighbour accuracy of telling the two sets apart
//!   (PointFlow's `knn` with k = 1), on equal-size subsets with an interval over subsets;
//! * [`dcr`]: distance to the closest training shape, beside the same figure for held-out
//!   real shapes (the privacy check).

pub mod coverage;
pub mod dcr;
pub mod nna;

use serde::{Deserialize, Serialize};

/// Why a shape metric cannot be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShapeMetricsError {
    /// A set has fewer shapes than the metric needs.
    #[error("{what} needs at least {needed} shapes, got {got}")]
    TooFew {
        /// The set or metric.
        what: &'static str,
        /// The minimum.
        needed: usize,
        /// What was given.
        got: usize,
    },
    /// Matrices whose sizes do not fit together.
    #[error("{what}: {detail}")]
    Dimension {
        /// The matrix or metric.
        what: &'static str,
        /// Which sizes disagree.
        detail: String,
    },
    /// A distance that is negative, NaN or infinite.
    #[error("{what}: distance ({row}, {col}) is {value}, but distances must be finite and ≥ 0")]
    BadDistance {
        /// The matrix.
        what: &'static str,
        /// Its row.
        row: usize,
        /// Its column.
        col: usize,
        /// The value.
        value: f64,
    },
    /// A parameter out of range.
    #[error("{what}: {detail}")]
    Domain {
        /// The parameter.
        what: &'static str,
        /// Its allowed range and value.
        detail: String,
    },
}

/// A rows × cols matrix of distances, stored by rows; entry (i, j) is the distance from
/// shape i of the row set to shape j of the column set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DistanceMatrix {
    rows: usize,
    cols: usize,
    values: Vec<f64>,
}

impl DistanceMatrix {
    /// Checks that `values` has rows × cols finite, non-negative entries.
    pub fn new(
        what: &'static str,
        rows: usize,
        cols: usize,
        values: Vec<f64>,
    ) -> Result<Self, ShapeMetricsError> {
        if values.len() != rows * cols {
            return Err(ShapeMetricsError::Dimension {
                what,
                detail: format!("{} values for a {rows} × {cols} matrix", values.len()),
            });
        }
        if let Some(k) = values.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(ShapeMetricsError::BadDistance {
                what,
                row: k / cols,
                col: k % cols,
                value: values[k],
            });
        }
        Ok(Self { rows, cols, values })
    }

    /// Builds the matrix from `rows[i][j]`, every row as long as the first.
    pub fn from_rows(what: &'static str, rows: &[Vec<f64>]) -> Result<Self, ShapeMetricsError> {
        let cols = rows.first().map_or(0, Vec::len);
        if let Some(i) = rows.iter().position(|r| r.len() != cols) {
            return Err(ShapeMetricsError::Dimension {
                what,
                detail: format!("row {i} has {} entries, row 0 has {cols}", rows[i].len()),
            });
        }
        Self::new(what, rows.len(), cols, rows.concat())
    }

    /// The distances from every point of `a` to every point of `b` under `distance`.
    pub fn between<T>(a: &[T], b: &[T], distance: impl Fn(&T, &T) -> f64) -> Self {
        let values = a
            .iter()
            .flat_map(|x| b.iter().map(|y| distance(x, y)))
            .collect();
        Self {
            rows: a.len(),
            cols: b.len(),
            values,
        }
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Number of columns.
    pub fn cols(&self) -> usize {
        self.cols
    }

    /// Entry (i, j).
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.values[i * self.cols + j]
    }

    /// Row i.
    pub fn row(&self, i: usize) -> &[f64] {
        &self.values[i * self.cols..(i + 1) * self.cols]
    }

    /// The transposed matrix (columns become rows).
    pub fn transposed(&self) -> Self {
        let values = (0..self.cols)
            .flat_map(|j| (0..self.rows).map(move |i| (i, j)))
            .map(|(i, j)| self.get(i, j))
            .collect();
        Self {
            rows: self.cols,
            cols: self.rows,
            values,
        }
    }
}

/// `Err(Dimension)` unless `m` is `rows` × `cols`.
pub(crate) fn expect_shape(
    what: &'static str,
    m: &DistanceMatrix,
    rows: usize,
    cols: usize,
) -> Result<(), ShapeMetricsError> {
    if m.rows() == rows && m.cols() == cols {
        Ok(())
    } else {
        Err(ShapeMetricsError::Dimension {
            what,
            detail: format!("expected {rows} × {cols}, got {} × {}", m.rows(), m.cols()),
        })
    }
}

#[cfg(test)]
pub(crate) mod test_sets {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// `n` points of N(centre, I₃).
    pub fn gaussian_points(n: usize, centre: f64, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                std::array::from_fn(|_| {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    centre + z
                })
            })
            .collect::<Vec<[f64; 3]>>()
    }

    /// Squared Euclidean distance, the shape of a Chamfer distance.
    pub fn squared(a: &[f64; 3], b: &[f64; 3]) -> f64 {
        (0..3).map(|k| (a[k] - b[k]).powi(2)).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_matrices_are_refused_with_the_offending_entry() {
        assert!(matches!(
            DistanceMatrix::new("m", 2, 2, vec![0.0; 3]),
            Err(ShapeMetricsError::Dimension { .. })
        ));
        assert_eq!(
            DistanceMatrix::new("m", 2, 2, vec![0.0, 1.0, -1.0, 0.0]),
            Err(ShapeMetricsError::BadDistance {
                what: "m",
                row: 1,
                col: 0,
                value: -1.0
            })
        );
        assert!(DistanceMatrix::from_rows("m", &[vec![1.0], vec![1.0, 2.0]]).is_err());
    }

    #[test]
    fn transposition_swaps_indices() {
        let m =
            DistanceMatrix::from_rows("m", &[vec![1.0, 2.0, 3.0], vec![4.0, 5.0, 6.0]]).unwrap();
        let t = m.transposed();
        assert_eq!((t.rows(), t.cols()), (3, 2));
        assert_eq!(t.row(2), &[3.0, 6.0]);
    }
}
