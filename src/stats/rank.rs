//! Rank correlation between measurements: average ranks (ties share the mean of the ranks
//! they span, as `scipy.stats.rankdata`'s default), Spearman's ρ as the Pearson
//! correlation of the ranks, the Spearman matrix of a sample (observations as rows), and
//! the difference of a virtual cohort's matrix from the real one's — whether the generator
//! keeps the dependence between measurements, not only their marginals.

use serde::{Deserialize, Serialize};

use super::linalg::Matrix;
use super::{StatsError, check_finite, check_sample};

/// 1-based ranks of `values`, ties given the average of the ranks they occupy.
pub fn average_ranks(values: &[f64]) -> Result<Vec<f64>, StatsError> {
    check_finite("ranks", values)?;
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&i, &j| values[i].total_cmp(&values[j]));
    let mut ranks = vec![0.0; values.len()];
    let mut start = 0;
    while start < order.len() {
        let mut end = start + 1;
        while end < order.len() && values[order[end]] == values[order[start]] {
            end += 1;
        }
        // positions start..end hold ranks start+1 ..= end; their mean is (start + end + 1)/2
        let rank = (start + end + 1) as f64 / 2.0;
        for &i in &order[start..end] {
            ranks[i] = rank;
        }
        start = end;
    }
    Ok(ranks)
}

/// Pearson correlation of two equally long samples (≥ 2 values, neither constant).
pub fn pearson(a: &[f64], b: &[f64]) -> Result<f64, StatsError> {
    check_sample("correlation", a, 2)?;
    check_sample("correlation", b, 2)?;
    if a.len() != b.len() {
        return Err(StatsError::Dimension {
            what: "correlation",
            detail: format!("samples of {} and {} values", a.len(), b.len()),
        });
    }
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa == 0.0 || sbb == 0.0 {
        return Err(StatsError::ZeroVariance {
            what: "correlation",
        });
    }
    Ok((sab / (saa * sbb).sqrt()).clamp(-1.0, 1.0))
}

/// Spearman's ρ of two equally long samples.
pub fn spearman(a: &[f64], b: &[f64]) -> Result<f64, StatsError> {
    pearson(&average_ranks(a)?, &average_ranks(b)?)
}

/// The p × p Spearman matrix of `rows` (n ≥ 2 observations of p measurements).
pub fn spearman_matrix(rows: &[Vec<f64>]) -> Result<Matrix, StatsError> {
    let p = rows.first().map_or(0, Vec::len);
    if let Some(i) = rows.iter().position(|r| r.len() != p) {
        return Err(StatsError::Dimension {
            what: "Spearman matrix",
            detail: format!("row {i} has {} values, row 0 has {p}", rows[i].len()),
        });
    }
    let ranked: Vec<Vec<f64>> = (0..p)
        .map(|j| average_ranks(&rows.iter().map(|r| r[j]).collect::<Vec<_>>()))
        .collect::<Result<_, _>>()?;
    let mut m = vec![vec![1.0; p]; p];
    for i in 0..p {
        for j in i + 1..p {
            let rho = pearson(&ranked[i], &ranked[j])?;
            (m[i][j], m[j][i]) = (rho, rho);
        }
    }
    Ok(m)
}

/// Spearman matrices of a virtual and a real sample and their difference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct CorrelationDifference {
    /// The virtual cohort's matrix.
    pub virtual_matrix: Matrix,
    /// The real sample's matrix.
    pub real_matrix: Matrix,
    /// virtual − real, entry by entry.
    pub difference: Matrix,
    /// Largest |difference| over the pairs of distinct measurements.
    pub max_abs_difference: f64,
}

impl CorrelationDifference {
    /// Compares the Spearman matrices of `virtual_rows` and `real_rows` (same p).
    pub fn new(virtual_rows: &[Vec<f64>], real_rows: &[Vec<f64>]) -> Result<Self, StatsError> {
        let virtual_matrix = spearman_matrix(virtual_rows)?;
        let real_matrix = spearman_matrix(real_rows)?;
        if virtual_matrix.len() != real_matrix.len() {
            return Err(StatsError::Dimension {
                what: "Spearman difference",
                detail: format!(
                    "{} virtual and {} real measurements",
                    virtual_matrix.len(),
                    real_matrix.len()
                ),
            });
        }
        let difference: Matrix = virtual_matrix
            .iter()
            .zip(&real_matrix)
            .map(|(v, r)| v.iter().zip(r).map(|(a, b)| a - b).collect())
            .collect();
        let max_abs_difference = difference
            .iter()
            .enumerate()
            .flat_map(|(i, row)| row.iter().enumerate().filter(move |(j, _)| *j != i))
            .map(|(_, d)| d.abs())
            .fold(0.0, f64::max);
        Ok(Self {
            virtual_matrix,
            real_matrix,
            difference,
            max_abs_difference,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::multivariate::tests::rows;

    // `python tests/reference/multivariate.py`: scipy.stats.rankdata of column 0 and
    // spearmanr of rows(30, 0) rounded to one decimal (so there are ties).
    const RANKS: [f64; 30] = [
        25.5, 23.5, 13.0, 2.0, 7.5, 17.5, 28.5, 20.5, 10.0, 2.0, 11.0, 20.5, 28.5, 17.5, 7.5, 4.5,
        14.0, 23.5, 25.5, 15.0, 4.5, 6.0, 16.0, 28.5, 22.0, 12.0, 2.0, 9.0, 19.0, 28.5,
    ];
    const SPEARMAN: [[f64; 3]; 3] = [
        [1.0, 0.2711032318970896, -0.06695978329411002],
        [0.2711032318970896, 1.0, -0.7444848346659534],
        [-0.06695978329411002, -0.7444848346659535, 1.0],
    ];

    fn tied_rows() -> Vec<Vec<f64>> {
        rows(30, 0.0)
            .into_iter()
            .map(|r| {
                r.iter()
                    .map(|v| (v * 10.0).round_ties_even() / 10.0)
                    .collect()
            })
            .collect()
    }

    #[test]
    fn ranks_and_spearman_matrix_match_scipy_with_ties() {
        let data = tied_rows();
        let column: Vec<f64> = data.iter().map(|r| r[0]).collect();
        assert_eq!(average_ranks(&column).unwrap(), RANKS.to_vec());
        let m = spearman_matrix(&data).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                assert!((m[i][j] - SPEARMAN[i][j]).abs() < 1e-14, "({i}, {j})");
            }
        }
    }

    #[test]
    fn monotone_transforms_keep_rho_and_the_difference_is_zero() {
        let data = rows(25, 0.0);
        let transformed: Vec<Vec<f64>> = data
            .iter()
            .map(|r| vec![r[0].exp(), r[1] * 3.0 - 1.0, r[2].powi(3)])
            .collect();
        let d = CorrelationDifference::new(&transformed, &data).unwrap();
        assert!(d.max_abs_difference < 1e-14, "{d:?}");
        let reversed: Vec<f64> = data.iter().map(|r| -r[0]).collect();
        let first: Vec<f64> = data.iter().map(|r| r[0]).collect();
        assert!((spearman(&first, &reversed).unwrap() + 1.0).abs() < 1e-14);
    }

    #[test]
    fn a_constant_measurement_has_no_correlation() {
        let data: Vec<Vec<f64>> = rows(10, 0.0).into_iter().map(|r| vec![r[0], 4.0]).collect();
        assert!(matches!(
            spearman_matrix(&data),
            Err(StatsError::ZeroVariance { .. })
        ));
    }
}
