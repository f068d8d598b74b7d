//! Gaussian kernel density estimates with R's defaults, the densities SIMCor's bootstrap
//! test compares.
//!
//! [`bw_nrd0`] is R's default bandwidth (Silverman's rule of thumb,
//! 0.9 · min(sd, IQR/1.34) · n^(−1/5), with R's fallbacks when that is zero), and
//! [`density`] evaluates the estimate on R's default grid: 512 equally spaced points from
//! min − 3h to max + 3h. R's `density()` approximates the kernel sum by binning the data
//! onto a grid and convolving by FFT; this module sums the kernels exactly, which differs
//! from R by about 1e-3 of the peak density (the tests bound it against R's own output).

use serde::{Deserialize, Serialize};

use super::descriptive::{quantile_sorted, sample_sd};
use super::{StatsError, check_sample, sorted};

/// Grid size of R's `density()`.
pub const GRID_POINTS: usize = 512;
/// How many bandwidths R's grid extends beyond the data (`cut = 3`).
pub const GRID_CUT: f64 = 3.0;

/// R's `bw.nrd0`: 0.9 · min(sd, IQR/1.34) · n^(−1/5) for at least two finite values. When
/// that spread is zero R falls back to the sd, then to |x₁|, then to 1 — kept here, so a
/// constant sample still gets a bandwidth.
pub fn bw_nrd0(values: &[f64]) -> Result<f64, StatsError> {
    check_sample("bandwidth", values, 2)?;
    let s = sorted(values);
    let sd = sample_sd(&s)?;
    let iqr = quantile_sorted(&s, 0.75)? - quantile_sorted(&s, 0.25)?;
    let mut spread = sd.min(iqr / 1.34);
    for fallback in [sd, values[0].abs(), 1.0] {
        if spread > 0.0 {
            break;
        }
        spread = fallback;
    }
    Ok(0.9 * spread * (values.len() as f64).powf(-0.2))
}

/// `points` equally spaced values from `lo` to `hi` inclusive (points ≥ 2).
pub fn linear_grid(lo: f64, hi: f64, points: usize) -> Vec<f64> {
    let step = (hi - lo) / (points.max(2) - 1) as f64;
    (0..points.max(2)).map(|i| lo + step * i as f64).collect()
}

/// The Gaussian kernel estimate (1/(n h)) Σ φ((g − xᵢ)/h) of `values` at every grid point.
pub fn gaussian_kde(values: &[f64], bandwidth: f64, grid: &[f64]) -> Result<Vec<f64>, StatsError> {
    check_sample("kernel density", values, 1)?;
    if !(bandwidth > 0.0 && bandwidth.is_finite()) {
        return Err(StatsError::Domain {
            what: "kernel bandwidth",
            detail: format!("needs a finite bandwidth > 0, got {bandwidth}"),
        });
    }
    Ok(kde_unchecked(values, bandwidth, grid))
}

/// The kernel sum without argument checks (values finite, bandwidth > 0).
pub(crate) fn kde_unchecked(values: &[f64], bandwidth: f64, grid: &[f64]) -> Vec<f64> {
    let scale = 1.0 / (values.len() as f64 * bandwidth * (2.0 * std::f64::consts::PI).sqrt());
    let inv_h = 1.0 / bandwidth;
    grid.iter()
        .map(|g| {
            let sum: f64 = values
                .iter()
                .map(|x| {
                    let u = (g - x) * inv_h;
                    (-0.5 * u * u).exp()
                })
                .sum();
            sum * scale
        })
        .collect()
}

/// A density estimate on its grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Density {
    /// Grid points, ascending.
    pub grid: Vec<f64>,
    /// Estimated density at each grid point.
    pub density: Vec<f64>,
    /// Kernel bandwidth (standard deviation of the Gaussian kernel).
    pub bandwidth: f64,
}

/// R's `density(values)` with its defaults: Gaussian kernel, `bw.nrd0`, 512 points from
/// min − 3h to max + 3h (kernel sums exact, see the module docs).
pub fn density(values: &[f64]) -> Result<Density, StatsError> {
    let bandwidth = bw_nrd0(values)?;
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let grid = linear_grid(
        lo - GRID_CUT * bandwidth,
        hi + GRID_CUT * bandwidth,
        GRID_POINTS,
    );
    let density = kde_unchecked(values, bandwidth, &grid);
    Ok(Density {
        grid,
        density,
        bandwidth,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::test_support::wave;

    // R 4.2.2, printed by `Rscript tests/reference/kde.R`: `bw.nrd0(x)`, and `density(x)$y`
    // at grid points 1, 100, 256, 400 and 512, with the grid's ends, for
    // x = 25 + 3 sin(0.31 i), i = 1..40.
    const R_BW: f64 = 0.9307462939854582;
    const R_GRID_ENDS: (f64, f64) = (19.213597801766987, 30.791590174524448);
    const R_DENSITY: [(usize, f64); 5] = [
        (1, 0.0006235665132668693),
        (100, 0.08040735372841405),
        (256, 0.10909055149326519),
        (400, 0.10389079639279193),
        (512, 0.0006129021996246306),
    ];
    // R's fallbacks: bw.nrd0 of (2, 2, 2) and of (0, 0, 0).
    const R_BW_CONSTANT: (f64, f64) = (1.4449348111684153, 0.7224674055842076);
    // `scipy.stats.gaussian_kde(x, bw_method=h / x.std(ddof=1))` at 25, 27.5 and 31, so its
    // kernel sd is exactly h = R_BW (printed by `python tests/reference/kde.py`).
    const SCIPY_KDE: [(f64, f64); 3] = [
        (25.0, 0.10893899969610824),
        (27.5, 0.14568568444677799),
        (31.0, 0.0002923724092512554),
    ];

    #[test]
    fn bandwidth_and_grid_match_r() {
        let x = wave(40, 0.31, 3.0, 25.0);
        assert!((bw_nrd0(&x).unwrap() - R_BW).abs() < 1e-12 * R_BW);
        let d = density(&x).unwrap();
        assert_eq!(d.grid.len(), GRID_POINTS);
        assert!((d.grid[0] - R_GRID_ENDS.0).abs() < 1e-10);
        assert!((d.grid[GRID_POINTS - 1] - R_GRID_ENDS.1).abs() < 1e-10);
        let (c2, c0) = R_BW_CONSTANT;
        assert!((bw_nrd0(&[2.0; 3]).unwrap() - c2).abs() < 1e-15);
        assert!((bw_nrd0(&[0.0; 3]).unwrap() - c0).abs() < 1e-15);
    }

    #[test]
    fn density_is_the_exact_kernel_sum_and_within_binning_error_of_r() {
        let x = wave(40, 0.31, 3.0, 25.0);
        let d = density(&x).unwrap();
        let peak = d.density.iter().copied().fold(0.0, f64::max);
        for (index, want) in R_DENSITY {
            let got = d.density[index - 1];
            assert!(
                (got - want).abs() < 2e-3 * peak,
                "point {index}: {got} vs R {want}"
            );
        }
        let grid: Vec<f64> = SCIPY_KDE.iter().map(|(g, _)| *g).collect();
        let exact = gaussian_kde(&x, R_BW, &grid).unwrap();
        for ((_, want), got) in SCIPY_KDE.iter().zip(exact) {
            assert!((got - want).abs() < 1e-13, "{got} vs scipy {want}");
        }
    }

    #[test]
    fn the_estimate_integrates_to_one() {
        let x = wave(25, 1.7, 4.0, 0.0);
        let d = density(&x).unwrap();
        let step = d.grid[1] - d.grid[0];
        // trapezoid rule; the 3h cut leaves out about 2·Φ(−3)/n of each kernel's mass
        let area: f64 = d
            .density
            .windows(2)
            .map(|w| 0.5 * (w[0] + w[1]) * step)
            .sum();
        assert!((area - 1.0).abs() < 3e-3, "area {area}");
    }

    #[test]
    fn bad_inputs_say_why() {
        assert!(matches!(bw_nrd0(&[1.0]), Err(StatsError::TooFew { .. })));
        assert!(gaussian_kde(&[1.0], 0.0, &[0.0]).is_err());
    }
}
