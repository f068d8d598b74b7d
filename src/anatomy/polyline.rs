//! Polylines parametrised by arc length, smoothed by local quadratic fits.

use crate::geometry::mesh::{norm, normalized, sub};

/// A polyline with cumulative arc length.
#[derive(Debug, Clone, PartialEq)]
pub struct Polyline {
    points: Vec<[f64; 3]>,
    cumulative: Vec<f64>,
}

impl Polyline {
    /// The polyline through `points` (consecutive duplicates dropped).
    pub fn new(mut points: Vec<[f64; 3]>) -> Self {
        points.dedup_by(|a, b| norm(sub(*a, *b)) < 1e-12);
        let mut cumulative = Vec::with_capacity(points.len());
        let mut s = 0.0;
        for i in 0..points.len() {
            if i > 0 {
                s += norm(sub(points[i], points[i - 1]));
            }
            cumulative.push(s);
        }
        Self { points, cumulative }
    }

    /// Vertices.
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points
    }

    /// Arc length at each vertex.
    pub fn arc_lengths(&self) -> &[f64] {
        &self.cumulative
    }

    /// Total arc length.
    pub fn length(&self) -> f64 {
        self.cumulative.last().copied().unwrap_or(0.0)
    }

    /// Position and unit tangent at arc length `s`, smoothed by the local fit of
    /// [`Polyline::local_fit`].
    pub fn frame_at(&self, s: f64, half_window: f64) -> ([f64; 3], [f64; 3]) {
        match self.local_fit(s, half_window) {
            Some(q) if norm(q.coeffs[1]) > 0.0 => (q.coeffs[0], normalized(q.coeffs[1])),
            _ => {
                let (a, b) = (self.points[0], self.points[self.points.len() - 1]);
                (self.point_at(s), normalized(sub(b, a)))
            }
        }
    }

    /// Weighted least-squares quadratic through the vertices within `half_window` of `s`
    /// (widened to hold at least four vertices, two on each side of `s` where the line has
    /// them), in the offset u = (arc length − s) / window. A quadratic reproduces straight
    /// lines exactly and circular arcs to third order, so the smoothing does not shorten
    /// bends noticeably. The two-sided window matters where centre points are missing (a
    /// run of sections through branch ostia): a fit to a cluster on one side of a gap would
    /// extrapolate across it and can swing tens of millimetres off the vessel.
    #[allow(clippy::needless_range_loop)] // index loops mirror the normal equations
    pub fn local_fit(&self, s: f64, half_window: f64) -> Option<LocalQuadratic> {
        let n = self.points.len();
        let before_s = self.cumulative.partition_point(|&c| c < s);
        let wanted_before = 2.min(before_s);
        let wanted_after = 2.min(n - before_s);
        let mut w = half_window.max(1e-9);
        let mut idx: Vec<usize>;
        loop {
            idx = (0..n)
                .filter(|&i| (self.cumulative[i] - s).abs() <= w)
                .collect();
            let before = idx.iter().filter(|&&i| i < before_s).count();
            if idx.len() >= 4.min(n)
                && before >= wanted_before
                && idx.len() - before >= wanted_after
            {
                break;
            }
            w *= 1.5;
        }
        // Normal equations of weights × [1, u, u²] for each coordinate.
        let mut m = [[0.0; 3]; 3];
        let mut rhs = [[0.0; 3]; 3];
        for &i in &idx {
            let u = (self.cumulative[i] - s) / w;
            let weight = (1.0 - u * u).max(0.0).powi(2) + 1e-6;
            let basis = [1.0, u, u * u];
            for r in 0..3 {
                for c in 0..3 {
                    m[r][c] += weight * basis[r] * basis[c];
                }
                for k in 0..3 {
                    rhs[r][k] += weight * basis[r] * self.points[i][k];
                }
            }
        }
        let coeffs = solve3(m, rhs).or_else(|| {
            // Too few distinct abscissae for a quadratic: fall back to a straight line.
            let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
            (det.abs() > 1e-12).then(|| {
                let mut out = [[0.0; 3]; 3];
                for k in 0..3 {
                    out[0][k] = (rhs[0][k] * m[1][1] - m[0][1] * rhs[1][k]) / det;
                    out[1][k] = (m[0][0] * rhs[1][k] - m[1][0] * rhs[0][k]) / det;
                }
                out
            })
        })?;
        Some(LocalQuadratic { coeffs, window: w })
    }

    /// Linearly interpolated point at arc length `s` (clamped to the ends).
    pub fn point_at(&self, s: f64) -> [f64; 3] {
        let i = self
            .cumulative
            .partition_point(|&c| c < s)
            .clamp(1, self.points.len() - 1);
        let (s0, s1) = (self.cumulative[i - 1], self.cumulative[i]);
        let t = if s1 > s0 {
            ((s - s0) / (s1 - s0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (a, b) = (self.points[i - 1], self.points[i]);
        std::array::from_fn(|k| a[k] + t * (b[k] - a[k]))
    }
}

/// x(u) = c₀ + c₁·u + c₂·u² with u = (arc length − s) / window, around some arc length s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalQuadratic {
    /// c₀, c₁, c₂.
    pub coeffs: [[f64; 3]; 3],
    /// Arc length per unit of u.
    pub window: f64,
}

impl LocalQuadratic {
    /// The point at arc-length offset `ds` from the fit's centre.
    pub fn at(&self, ds: f64) -> [f64; 3] {
        let u = ds / self.window;
        let c = &self.coeffs;
        std::array::from_fn(|k| c[0][k] + u * c[1][k] + u * u * c[2][k])
    }

    /// Unit tangent at arc-length offset `ds` (zero if the fit is degenerate there).
    pub fn tangent(&self, ds: f64) -> [f64; 3] {
        let u = ds / self.window;
        let c = &self.coeffs;
        normalized(std::array::from_fn(|k| c[1][k] + 2.0 * u * c[2][k]))
    }
}

/// Solves the 3×3 system m·x = rhs for three right-hand sides (Gaussian elimination with
/// partial pivoting); `None` when m is singular.
#[allow(clippy::needless_range_loop)] // index loops mirror the elimination formulas
pub fn solve3(mut m: [[f64; 3]; 3], mut rhs: [[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let scale = m.iter().flatten().fold(0.0f64, |a, &b| a.max(b.abs()));
    for col in 0..3 {
        let pivot = (col..3).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[pivot][col].abs() <= 1e-10 * scale {
            return None;
        }
        m.swap(col, pivot);
        rhs.swap(col, pivot);
        for r in col + 1..3 {
            let f = m[r][col] / m[col][col];
            for c in col..3 {
                m[r][c] -= f * m[col][c];
            }
            for k in 0..3 {
                rhs[r][k] -= f * rhs[col][k];
            }
        }
    }
    let mut x = [[0.0; 3]; 3];
    for r in (0..3).rev() {
        for k in 0..3 {
            let tail: f64 = (r + 1..3).map(|c| m[r][c] * x[c][k]).sum();
            x[r][k] = (rhs[r][k] - tail) / m[r][r];
        }
    }
    Some(x)
}
