//! Small dense linear algebra on row-major `Vec<Vec<f64>>` matrices: Cholesky
//! factorisation, solves, inverse and log-determinant through it, and the symmetric
//! eigen-decomposition by cyclic Jacobi rotations. Sized for covariance matrices of a
//! handful of measurements and Gram matrices of up to a few hundred shapes, where O(n³)
//! with a tiny constant beats pulling in a linear-algebra crate.

use super::StatsError;

/// A square matrix stored by rows.
pub type Matrix = Vec<Vec<f64>>;

/// The lower-triangular L with L Lᵀ = `a` for a symmetric positive definite `a`; a pivot
/// below 1e-12 × the largest diagonal entry counts as singular.
pub fn cholesky(a: &[Vec<f64>], what: &'static str) -> Result<Matrix, StatsError> {
    let n = a.len();
    if a.iter().any(|row| row.len() != n) {
        return Err(StatsError::Dimension {
            what,
            detail: format!("the matrix is not square ({n} rows)"),
        });
    }
    let scale = (0..n).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    let mut l = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in 0..=i {
            let dot: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                let pivot = a[i][i] - dot;
                if pivot.is_nan() || pivot <= 1e-12 * scale {
                    return Err(StatsError::Singular { what });
                }
                l[i][i] = pivot.sqrt();
            } else {
                l[i][j] = (a[i][j] - dot) / l[j][j];
            }
        }
    }
    Ok(l)
}

/// Solves L y = b by forward substitution.
pub fn solve_lower(l: &[Vec<f64>], b: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; b.len()];
    for i in 0..b.len() {
        let dot: f64 = (0..i).map(|k| l[i][k] * y[k]).sum();
        y[i] = (b[i] - dot) / l[i][i];
    }
    y
}

/// vᵀ (L Lᵀ)⁻¹ v = |L⁻¹ v|².
pub fn inverse_quadratic_form(l: &[Vec<f64>], v: &[f64]) -> f64 {
    solve_lower(l, v).iter().map(|y| y * y).sum()
}

/// ln det(L Lᵀ) = 2 Σ ln Lᵢᵢ.
pub fn log_det(l: &[Vec<f64>]) -> f64 {
    2.0 * (0..l.len()).map(|i| l[i][i].ln()).sum::<f64>()
}

/// (L Lᵀ)⁻¹, column by column from the two triangular solves.
pub fn cholesky_inverse(l: &[Vec<f64>]) -> Matrix {
    let n = l.len();
    let mut inverse = vec![vec![0.0; n]; n];
    for j in 0..n {
        let mut e = vec![0.0; n];
        e[j] = 1.0;
        let y = solve_lower(l, &e);
        // back substitution with Lᵀ
        let mut x = vec![0.0; n];
        for i in (0..n).rev() {
            let dot: f64 = (i + 1..n).map(|k| l[k][i] * x[k]).sum();
            x[i] = (y[i] - dot) / l[i][i];
        }
        for i in 0..n {
            inverse[i][j] = x[i];
        }
    }
    inverse
}

/// Eigenvalues (descending) and unit eigenvectors (`vectors[k]` belongs to `values[k]`)
/// of a symmetric matrix, by cyclic Jacobi rotations until the off-diagonal mass is below
/// 1e-15 of the total (Golub & Van Loan §8.5).
pub fn symmetric_eigen(a: &[Vec<f64>]) -> (Vec<f64>, Matrix) {
    let n = a.len();
    let mut m: Matrix = a.to_vec();
    let mut v: Matrix = (0..n)
        .map(|i| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
        .collect();
    let total: f64 = m.iter().flatten().map(|x| x * x).sum();
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |j| *j != i).map(move |j| (i, j)))
            .map(|(i, j)| m[i][j] * m[i][j])
            .sum();
        if off <= 1e-30 * total || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                rotate(&mut m, &mut v, p, q);
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| m[j][j].total_cmp(&m[i][i]));
    let values = order.iter().map(|&k| m[k][k]).collect();
    let vectors = order
        .iter()
        .map(|&k| (0..n).map(|r| v[r][k]).collect())
        .collect();
    (values, vectors)
}

/// One Jacobi rotation zeroing m[p][q]; `v` accumulates the rotations by columns.
fn rotate(m: &mut Matrix, v: &mut Matrix, p: usize, q: usize) {
    let apq = m[p][q];
    if apq == 0.0 {
        return;
    }
    let theta = (m[q][q] - m[p][p]) / (2.0 * apq);
    let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
    let c = 1.0 / (t * t + 1.0).sqrt();
    let s = t * c;
    for row in m.iter_mut() {
        let (rp, rq) = (row[p], row[q]);
        row[p] = c * rp - s * rq;
        row[q] = s * rp + c * rq;
    }
    // rows p < q, borrowed apart
    let (top, bottom) = m.split_at_mut(q);
    for (a, b) in top[p].iter_mut().zip(bottom[0].iter_mut()) {
        let (x, y) = (*a, *b);
        *a = c * x - s * y;
        *b = s * x + c * y;
    }
    m[p][q] = 0.0;
    m[q][p] = 0.0;
    for row in v.iter_mut() {
        let (rp, rq) = (row[p], row[q]);
        row[p] = c * rp - s * rq;
        row[q] = s * rp + c * rq;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spd(n: usize) -> Matrix {
        // B Bᵀ + I for a fixed B with entries sin(i + 2j)
        let b: Matrix = (0..n)
            .map(|i| (0..n).map(|j| ((i + 2 * j) as f64).sin()).collect())
            .collect();
        (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| (0..n).map(|k| b[i][k] * b[j][k]).sum::<f64>() + (i == j) as u8 as f64)
                    .collect()
            })
            .collect()
    }

    fn product(a: &[Vec<f64>], b: &[Vec<f64>]) -> Matrix {
        let n = a.len();
        (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| (0..n).map(|k| a[i][k] * b[k][j]).sum())
                    .collect()
            })
            .collect()
    }

    #[test]
    fn cholesky_reconstructs_and_its_inverse_inverts() {
        let a = spd(6);
        let l = cholesky(&a, "test").unwrap();
        let lt: Matrix = (0..6).map(|i| (0..6).map(|j| l[j][i]).collect()).collect();
        let back = product(&l, &lt);
        let identity = product(&a, &cholesky_inverse(&l));
        for i in 0..6 {
            for j in 0..6 {
                assert!((back[i][j] - a[i][j]).abs() < 1e-12);
                assert!((identity[i][j] - (i == j) as u8 as f64).abs() < 1e-10);
            }
        }
        let v = [1.0, -2.0, 0.5, 0.0, 3.0, 1.0];
        let inv = cholesky_inverse(&l);
        let direct: f64 = (0..6)
            .flat_map(|i| (0..6).map(move |j| (i, j)))
            .map(|(i, j)| v[i] * inv[i][j] * v[j])
            .sum();
        assert!((inverse_quadratic_form(&l, &v) - direct).abs() < 1e-10 * direct);
    }

    #[test]
    fn log_det_of_a_diagonal_matrix_is_the_sum_of_logs() {
        let a = vec![
            vec![2.0, 0.0, 0.0],
            vec![0.0, 5.0, 0.0],
            vec![0.0, 0.0, 0.1],
        ];
        let l = cholesky(&a, "test").unwrap();
        assert!((log_det(&l) - (2.0f64 * 5.0 * 0.1).ln()).abs() < 1e-14);
    }

    #[test]
    fn a_singular_matrix_is_refused() {
        let a = vec![vec![1.0, 2.0], vec![2.0, 4.0]];
        assert!(matches!(
            cholesky(&a, "test"),
            Err(StatsError::Singular { .. })
        ));
    }

    #[test]
    fn jacobi_eigenpairs_satisfy_the_definition() {
        let a = spd(9);
        let (values, vectors) = symmetric_eigen(&a);
        assert!(values.windows(2).all(|w| w[0] >= w[1]));
        for (lambda, v) in values.iter().zip(&vectors) {
            for i in 0..9 {
                let av: f64 = (0..9).map(|k| a[i][k] * v[k]).sum();
                assert!((av - lambda * v[i]).abs() < 1e-10, "A v ≠ λ v");
            }
        }
        for (i, u) in vectors.iter().enumerate() {
            for (j, w) in vectors.iter().enumerate() {
                let dot: f64 = u.iter().zip(w).map(|(x, y)| x * y).sum();
                assert!((dot - (i == j) as u8 as f64).abs() < 1e-12);
            }
        }
        let trace: f64 = (0..9).map(|i| a[i][i]).sum();
        assert!((values.iter().sum::<f64>() - trace).abs() < 1e-10);
    }

    #[test]
    fn jacobi_finds_the_analytic_eigenvalues_of_a_2x2() {
        // [[2, 1], [1, 2]] has eigenvalues 3 and 1 with vectors (1, 1)/√2 and (1, −1)/√2
        let (values, vectors) = symmetric_eigen(&[vec![2.0, 1.0], vec![1.0, 2.0]]);
        assert!((values[0] - 3.0).abs() < 1e-15 && (values[1] - 1.0).abs() < 1e-15);
        assert!((vectors[0][0].abs() - 0.5f64.sqrt()).abs() < 1e-15);
        assert!((vectors[0][0] - vectors[0][1]).abs() < 1e-15);
    }
}
