//! Joint comparison of several measurements: mean vector and covariance of a sample
//! (observations as rows), and the Mahalanobis quadratic forms
//! q = (y − μ)ᵀ Σ⁻¹ (y − μ) of one sample's rows against another sample's mean and
//! covariance. For rows from the reference's own Gaussian, q follows χ²_p approximately
//! (exactly with known μ and Σ), so a QQ plot of q against χ²_p quantiles
//! ([`chi2_qq`]) shows whether a virtual cohort fills the real population's ellipsoid, is
//! too narrow (points below the line) or strays outside it (above).

use serde::{Deserialize, Serialize};

use super::distributions::chi2_quantile;
use super::linalg::{Matrix, cholesky, inverse_quadratic_form};
use super::{StatsError, check_finite, sorted};

fn check_rows(what: &'static str, rows: &[Vec<f64>], needed: usize) -> Result<usize, StatsError> {
    if rows.len() < needed {
        return Err(StatsError::TooFew {
            what,
            needed,
            got: rows.len(),
        });
    }
    let p = rows[0].len();
    if p == 0 {
        return Err(StatsError::Dimension {
            what,
            detail: "the rows have no columns".into(),
        });
    }
    for (i, row) in rows.iter().enumerate() {
        if row.len() != p {
            return Err(StatsError::Dimension {
                what,
                detail: format!("row {i} has {} values, row 0 has {p}", row.len()),
            });
        }
        check_finite(what, row)?;
    }
    Ok(p)
}

/// Column means of at least one row.
pub fn mean_vector(rows: &[Vec<f64>]) -> Result<Vec<f64>, StatsError> {
    let p = check_rows("mean vector", rows, 1)?;
    let n = rows.len() as f64;
    Ok((0..p)
        .map(|j| rows.iter().map(|r| r[j]).sum::<f64>() / n)
        .collect())
}

/// Sample covariance matrix (n − 1 denominator) of at least two rows.
pub fn covariance(rows: &[Vec<f64>]) -> Result<Matrix, StatsError> {
    let p = check_rows("covariance", rows, 2)?;
    let mu = mean_vector(rows)?;
    let n1 = (rows.len() - 1) as f64;
    Ok((0..p)
        .map(|i| {
            (0..p)
                .map(|j| {
                    rows.iter()
                        .map(|r| (r[i] - mu[i]) * (r[j] - mu[j]))
                        .sum::<f64>()
                        / n1
                })
                .collect()
        })
        .collect())
}

/// A reference sample's mean and the Cholesky factor of its covariance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MahalanobisReference {
    /// Mean vector μ.
    pub mean: Vec<f64>,
    /// Lower Cholesky factor of the covariance Σ.
    pub cholesky: Matrix,
}

impl MahalanobisReference {
    /// Fits μ and Σ to `rows`; needs more rows than columns, else Σ is singular.
    pub fn fit(rows: &[Vec<f64>]) -> Result<Self, StatsError> {
        let p = check_rows("Mahalanobis reference", rows, 2)?;
        if rows.len() <= p {
            return Err(StatsError::TooFew {
                what: "Mahalanobis reference (rows for a non-singular covariance)",
                needed: p + 1,
                got: rows.len(),
            });
        }
        let cholesky = cholesky(&covariance(rows)?, "Mahalanobis reference covariance")?;
        Ok(Self {
            mean: mean_vector(rows)?,
            cholesky,
        })
    }

    /// Number of measurements p.
    pub fn dimension(&self) -> usize {
        self.mean.len()
    }

    /// q = (y − μ)ᵀ Σ⁻¹ (y − μ) of every row of `rows`.
    pub fn quadratic_forms(&self, rows: &[Vec<f64>]) -> Result<Vec<f64>, StatsError> {
        let p = check_rows("Mahalanobis forms", rows, 1)?;
        if p != self.dimension() {
            return Err(StatsError::Dimension {
                what: "Mahalanobis forms",
                detail: format!("rows have {p} values, the reference {}", self.dimension()),
            });
        }
        Ok(rows
            .iter()
            .map(|r| {
                let centred: Vec<f64> = r.iter().zip(&self.mean).map(|(y, m)| y - m).collect();
                inverse_quadratic_form(&self.cholesky, &centred)
            })
            .collect())
    }
}

/// QQ pairs (χ²_p quantile, observed q) of the sorted `q`, at the plotting positions
/// (i − ½)/n (Hazen), i = 1..n.
pub fn chi2_qq(q: &[f64], p: usize) -> Result<Vec<(f64, f64)>, StatsError> {
    super::check_sample("χ² QQ", q, 1)?;
    let n = q.len() as f64;
    sorted(q)
        .into_iter()
        .enumerate()
        .map(|(i, observed)| Ok((chi2_quantile((i as f64 + 0.5) / n, p as f64)?, observed)))
        .collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Rows (sin(1.1 i), cos(0.7 i) + 0.3 sin(1.1 i), sin(0.37 i) ² ), i = 1..n — the sample
    /// of `tests/reference/multivariate.py`.
    pub(crate) fn rows(n: usize, shift: f64) -> Vec<Vec<f64>> {
        (1..=n)
            .map(|i| {
                let t = i as f64;
                let a = (1.1 * t).sin();
                vec![
                    a + shift,
                    (0.7 * t).cos() + 0.3 * a,
                    (0.37 * t).sin().powi(2),
                ]
            })
            .collect()
    }

    // `scipy.spatial.distance.mahalanobis(y, μ, inv(np.cov(ref.T)))²` for the rows of
    // rows(6, 0.5) against rows(30, 0), printed by `python tests/reference/multivariate.py`.
    const Q_REFERENCE: [f64; 6] = [
        4.2917318484516995,
        3.006706182523272,
        1.0986621718179188,
        2.89520150186834,
        2.557874136851262,
        2.2378369104507994,
    ];

    #[test]
    fn quadratic_forms_match_scipy() {
        let reference = MahalanobisReference::fit(&rows(30, 0.0)).unwrap();
        let q = reference.quadratic_forms(&rows(6, 0.5)).unwrap();
        assert_eq!(q.len(), Q_REFERENCE.len());
        for (got, want) in q.iter().zip(Q_REFERENCE) {
            assert!((got - want).abs() < 1e-10 * want, "{got} vs {want}");
        }
    }

    #[test]
    fn forms_of_the_reference_itself_average_p_times_n_minus_one_over_n() {
        // Σᵢ qᵢ = trace(Σ⁻¹ Σ (n − 1)) = p (n − 1) for the fitting sample itself.
        let data = rows(30, 0.0);
        let q = MahalanobisReference::fit(&data)
            .unwrap()
            .quadratic_forms(&data)
            .unwrap();
        let mean = q.iter().sum::<f64>() / 30.0;
        assert!((mean - 3.0 * 29.0 / 30.0).abs() < 1e-10, "mean q {mean}");
    }

    #[test]
    fn qq_pairs_use_hazen_positions() {
        let pairs = chi2_qq(&[3.0, 1.0], 2).unwrap();
        // χ²₂ quantile is −2 ln(1 − u): u = 1/4 and 3/4
        assert!((pairs[0].0 + 2.0 * 0.75f64.ln()).abs() < 1e-12 && pairs[0].1 == 1.0);
        assert!((pairs[1].0 + 2.0 * 0.25f64.ln()).abs() < 1e-12 && pairs[1].1 == 3.0);
    }

    #[test]
    fn too_few_rows_or_collinear_columns_say_why() {
        assert!(matches!(
            MahalanobisReference::fit(&rows(3, 0.0)),
            Err(StatsError::TooFew { needed: 4, .. })
        ));
        let collinear: Vec<Vec<f64>> = rows(10, 0.0)
            .into_iter()
            .map(|r| vec![r[0], 2.0 * r[0]])
            .collect();
        assert!(matches!(
            MahalanobisReference::fit(&collinear),
            Err(StatsError::Singular { .. })
        ));
        let ragged = vec![vec![1.0, 2.0], vec![1.0]];
        assert!(matches!(
            covariance(&ragged),
            Err(StatsError::Dimension { .. })
        ));
    }
}
