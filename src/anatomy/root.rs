//! Aortic-root landmarks detected on the diameter profile alone.
//!
//! Along the centreline from the inlet the equivalent diameter D(σ) of a root is flat in the
//! outflow tract, rises smoothly into the sinus bulge, falls to a smooth minimum (or a
//! shoulder, when the ascending aorta is narrower) at the sinotubular junction and then
//! settles to the ascending diameter. The landmarks are:
//! - sinus: the interior maximum of D with the largest prominence; the inlet (annulus) end is
//!   the centreline end nearer to it;
//! - STJ: the first point after the steepest descent past the sinus where D′ reaches zero
//!   (a minimum) or stops rising (a shoulder);
//! - annulus: where the rise into the sinus starts. The rise is quadratic (C¹ onset), so
//!   √(D − D₀) is linear in σ; a straight-line fit over the early rise gives the onset σₐ.
//!   Without a flat inlet segment the annulus is the inlet section itself.

use super::centreline::Centreline;
use super::surface::Surface;
use super::{MeasureError, MeasureOptions, RootMeasurements, VesselMeasurements, measure_prepared};
use crate::geometry::TriMesh;
use crate::geometry::mesh::{norm, normalized, sub};

/// Spacing of the dense profiles around the annulus and the STJ, mm.
const DENSE_STEP: f64 = 0.25;
/// Gaussian smoothing of the dense profile before differentiation, mm.
const DENSE_SMOOTHING: f64 = 0.75;
/// Smallest sinus prominence (mm of equivalent diameter) accepted as a root bulge.
const MIN_PROMINENCE: f64 = 0.25;
/// Smallest sinus prominence relative to the sinus's equivalent diameter. Sinuses of
/// Valsalva stand 5–10 % above both sides in equivalent diameter (the parametric roots:
/// 5.2–9.1 %); a vessel without a root shows bumps of a few tenths of a millimetre where
/// the surface is coarse.
const MIN_RELATIVE_PROMINENCE: f64 = 0.03;
/// Farthest a sinus lies from the vessel's end, in sinus diameters: the sinus sits right
/// above the annulus (the parametric roots: 0.5–0.75 diameters with their outflow tract).
/// Farther along, a widening is the arch where the branches leave, not a root.
const SINUS_REACH_DIAMETERS: f64 = 1.0;
/// How far on either side of a sinus its prominence is measured, in sinus diameters: past
/// the annulus and the sinotubular junction (the parametric roots: within 0.8 diameters).
const PROMINENCE_REACH_DIAMETERS: f64 = 1.5;

/// The centreline seen from the annulus end: σ = distance from that end.
struct RootLine<'a> {
    surface: &'a Surface,
    line: &'a Centreline,
    forward: bool,
}

/// A section normal to the centreline at σ: equivalent diameter and its loop.
struct Sample {
    sigma: f64,
    diameter: f64,
    section: super::surface::SectionLoop,
}

impl RootLine<'_> {
    fn length(&self) -> f64 {
        self.line.length()
    }

    fn sample(&self, sigma: f64) -> Option<Sample> {
        let s = if self.forward {
            sigma
        } else {
            self.length() - sigma
        };
        let (p, t) = self.line.frame_at(s);
        let section = self.surface.wall_section_at(p, t)?;
        let diameter = (4.0 * section.area / std::f64::consts::PI).sqrt();
        Some(Sample {
            sigma,
            diameter,
            section,
        })
    }

    /// Samples every [`DENSE_STEP`] over [lo, hi] (clamped inside the vessel).
    fn dense(&self, lo: f64, hi: f64) -> Vec<Sample> {
        let (lo, hi) = (lo.max(DENSE_STEP), hi.min(self.length() - DENSE_STEP));
        let n = ((hi - lo) / DENSE_STEP).floor().max(0.0) as usize;
        (0..=n)
            .filter_map(|k| self.sample(lo + k as f64 * DENSE_STEP))
            .collect()
    }
}

/// Gaussian smoothing of uniformly spaced values, `sigma` in samples.
fn smooth(values: &[f64], sigma: f64) -> Vec<f64> {
    let reach = (3.0 * sigma).ceil() as isize;
    let n = values.len() as isize;
    (0..n)
        .map(|i| {
            let (mut acc, mut total) = (0.0, 0.0);
            for j in (i - reach).max(0)..=(i + reach).min(n - 1) {
                let w = (-0.5 * ((j - i) as f64 / sigma).powi(2)).exp();
                acc += w * values[j as usize];
                total += w;
            }
            acc / total
        })
        .collect()
}

/// Central-difference derivative of uniformly spaced values.
fn derivative(values: &[f64], step: f64) -> Vec<f64> {
    let n = values.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            if a == b {
                0.0
            } else {
                (values[b] - values[a]) / ((b - a) as f64 * step)
            }
        })
        .collect()
}

/// Index of the interior local maximum with the largest prominence among those `accept`
/// takes (given the index and the prominence), and that prominence. The prominence is the
/// height above the lower of the two minima within `reach(i)` samples on either side: a
/// sinus stands above the annulus and the junction next to it, and the far end of the
/// vessel (a rounded cap narrowing to nothing) does not make a bump prominent.
fn most_prominent_peak(
    d: &[f64],
    reach: impl Fn(usize) -> usize,
    accept: impl Fn(usize, f64) -> bool,
) -> Option<(usize, f64)> {
    let lowest = |values: &[f64]| values.iter().copied().fold(f64::INFINITY, f64::min);
    (1..d.len().saturating_sub(1))
        .filter(|&i| d[i] >= d[i - 1] && d[i] > d[i + 1])
        .map(|i| {
            let r = reach(i).max(1);
            let left = lowest(&d[i.saturating_sub(r)..i]);
            let right = lowest(&d[i + 1..(i + 1 + r).min(d.len())]);
            (i, (d[i] - left).min(d[i] - right))
        })
        .filter(|&(i, prominence)| accept(i, prominence))
        .max_by(|a, b| a.1.total_cmp(&b.1))
}

/// σ of the sinotubular junction on a dense profile starting at the sinus peak: a first
/// estimate where the smoothed slope reaches zero or stops rising, refined by
/// [`fit_waist`] (smoothing alone would bias it, the two sides curving differently).
fn find_stj(samples: &[Sample]) -> Option<f64> {
    let sigma = DENSE_SMOOTHING / DENSE_STEP;
    let raw: Vec<f64> = samples.iter().map(|s| s.diameter).collect();
    let slope = derivative(&smooth(&raw, sigma), DENSE_STEP);
    let n = slope.len();
    // Steepest descent past the sinus.
    let mut q = 0;
    while q + 1 < n && slope[q + 1] <= slope[q] {
        q += 1;
    }
    let mut rough = None;
    for k in q + 1..n {
        if slope[k] >= 0.0 || (k + 1 < n && slope[k + 1] < slope[k]) {
            rough = Some(samples[k].sigma);
            break;
        }
    }
    let rough = rough?;
    let sigmas: Vec<f64> = samples.iter().map(|s| s.sigma).collect();
    Some(fit_waist(&sigmas, &raw, rough - WAIST_SEARCH, rough + WAIST_SEARCH).unwrap_or(rough))
}

/// Half-range of the waist search around the first estimate, mm.
const WAIST_SEARCH: f64 = 3.0;
/// Half-width of the samples fitted on each side of a candidate waist, mm.
const WAIST_HALF_WIDTH: f64 = 4.0;

/// The junction c of the least-squares piecewise polynomial D = D₀ + a·(c − σ)² + a₃·(c − σ)³
/// before c and D₀ + b·(σ − c)² after it (slope zero at c, curvatures free on each side,
/// a > 0 for the sinus side, a cubic term for the sinus descent, which is not symmetric),
/// over candidates c in [lo, hi] every 0.05 mm. This is the shape of a smooth
/// waist whether the profile rises after it (a minimum) or keeps falling gently (a shoulder).
fn fit_waist(sigma: &[f64], d: &[f64], lo: f64, hi: f64) -> Option<f64> {
    let mut best: Option<(f64, f64)> = None;
    let count = ((hi - lo) / 0.05).round() as usize;
    for i in 0..=count {
        let c = lo + i as f64 * 0.05;
        let rows: Vec<([f64; 4], f64)> = sigma
            .iter()
            .zip(d)
            .filter(|(s, _)| (**s - c).abs() <= WAIST_HALF_WIDTH)
            .map(|(&s, &y)| {
                let (before, after) = ((c - s).max(0.0), (s - c).max(0.0));
                ([1.0, before.powi(2), before.powi(3), after.powi(2)], y)
            })
            .collect();
        if rows.len() < 8 {
            continue;
        }
        let Some(x) = least_squares(&rows) else {
            continue;
        };
        if x[1] <= 0.0 {
            continue;
        }
        let ssr: f64 = rows
            .iter()
            .map(|(r, y)| (r.iter().zip(&x).map(|(a, b)| a * b).sum::<f64>() - y).powi(2))
            .sum::<f64>()
            / rows.len() as f64;
        if best.is_none_or(|(_, b)| ssr < b) {
            best = Some((c, ssr));
        }
    }
    best.map(|(c, _)| c)
}

/// Least-squares solution of rows · x ≈ y (normal equations, Gaussian elimination with
/// partial pivoting); `None` when the columns are dependent.
#[allow(clippy::needless_range_loop)] // index loops mirror the elimination formulas
fn least_squares<const N: usize>(rows: &[([f64; N], f64)]) -> Option<[f64; N]> {
    let mut m = [[0.0; N]; N];
    let mut rhs = [0.0; N];
    for (r, y) in rows {
        for i in 0..N {
            for j in 0..N {
                m[i][j] += r[i] * r[j];
            }
            rhs[i] += r[i] * y;
        }
    }
    let scale = m.iter().flatten().fold(0.0f64, |a, &b| a.max(b.abs()));
    for col in 0..N {
        let pivot = (col..N).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[pivot][col].abs() <= 1e-12 * scale {
            return None;
        }
        m.swap(col, pivot);
        rhs.swap(col, pivot);
        for r in col + 1..N {
            let f = m[r][col] / m[col][col];
            for c in col..N {
                m[r][c] -= f * m[col][c];
            }
            rhs[r] -= f * rhs[col];
        }
    }
    let mut x = [0.0; N];
    for r in (0..N).rev() {
        let tail: f64 = (r + 1..N).map(|c| m[r][c] * x[c]).sum();
        x[r] = (rhs[r] - tail) / m[r][r];
    }
    Some(x)
}

/// σ of the annulus plane on a dense profile from the inlet to the sinus peak.
fn find_annulus(samples: &[Sample], peak_diameter: f64) -> f64 {
    let first = samples[0].sigma;
    let raw: Vec<f64> = samples.iter().map(|s| s.diameter).collect();
    let slope = derivative(&smooth(&raw, DENSE_SMOOTHING / DENSE_STEP), DENSE_STEP);
    let Some(steepest) = (0..slope.len()).max_by(|&a, &b| slope[a].total_cmp(&slope[b])) else {
        return first;
    };
    // The flat inlet segment: back from the steepest ascent to where the slope vanishes.
    let flat = 0.02 * slope[steepest];
    let Some(plateau_end) = (0..steepest).rev().find(|&k| slope[k] <= flat) else {
        return first;
    };
    let mut plateau = raw[..=plateau_end].to_vec();
    plateau.sort_by(f64::total_cmp);
    let d0 = plateau[plateau.len() / 2];
    let rise = peak_diameter - d0;
    let (lo, hi) = (0.01 * rise, 0.15 * rise);
    let points: Vec<(f64, f64)> = (plateau_end..steepest)
        .filter(|&k| (lo..=hi).contains(&(raw[k] - d0)))
        .map(|k| (samples[k].sigma, (raw[k] - d0).sqrt()))
        .collect();
    if points.len() < 3 {
        return samples[plateau_end].sigma;
    }
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let (sxy, sxx) = points.iter().fold((0.0, 0.0), |(a, b), p| {
        (a + (p.0 - mx) * (p.1 - my), b + (p.0 - mx).powi(2))
    });
    let slope_fit = sxy / sxx;
    if slope_fit.is_nan() || slope_fit <= 0.0 {
        return samples[plateau_end].sigma;
    }
    (mx - my / slope_fit).clamp(first, samples[steepest].sigma)
}

/// Twice the largest distance from the axis `a → b` to the wall, over sections normal to it.
fn sinus_diameter(surface: &Surface, a: [f64; 3], b: [f64; 3]) -> Option<f64> {
    let axis = normalized(sub(b, a));
    let height = norm(sub(b, a));
    let radius_at = |z: f64| -> f64 {
        let p: [f64; 3] = std::array::from_fn(|i| a[i] + z * axis[i]);
        surface
            .section_at(p, axis)
            .map_or(0.0, |s| s.max_distance_from([0.0, 0.0]))
    };
    let coarse = 0.5;
    let n = (height / coarse).floor() as usize;
    let (best_z, _) = (0..=n)
        .map(|k| {
            let z = k as f64 * coarse;
            (z, radius_at(z))
        })
        .max_by(|x, y| x.1.total_cmp(&y.1))?;
    // Golden-section search around the coarse maximum.
    let (mut lo, mut hi) = ((best_z - coarse).max(0.0), (best_z + coarse).min(height));
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut f1, mut f2) = (radius_at(x1), radius_at(x2));
    for _ in 0..25 {
        if f1 < f2 {
            lo = x1;
            (x1, f1) = (x2, f2);
            x2 = lo + g * (hi - lo);
            f2 = radius_at(x2);
        } else {
            hi = x2;
            (x2, f2) = (x1, f1);
            x1 = hi - g * (hi - lo);
            f1 = radius_at(x1);
        }
    }
    let best = [f1, f2, radius_at(best_z)].into_iter().fold(0.0, f64::max);
    Some(2.0 * best)
}

/// Where the landmarks of a root lie along its centreline (arc lengths from the
/// centreline's start, as in [`super::Station::s_mm`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RootLandmarks {
    /// True when the centreline starts at the annulus end (the inlet).
    pub inlet_at_start: bool,
    /// Annulus plane.
    pub annulus_s_mm: f64,
    /// Sinotubular junction.
    pub stj_s_mm: f64,
}

/// Annulus, sinus, STJ and ascending diameters and the sinus height of an aortic-root
/// surface in millimetres, from its centreline profile (see the module docs).
pub fn measure_root(mesh: &TriMesh) -> Result<RootMeasurements, MeasureError> {
    measure_root_with_landmarks(mesh).map(|(m, _)| m)
}

/// [`measure_root`] together with where the landmarks were found.
pub fn measure_root_with_landmarks(
    mesh: &TriMesh,
) -> Result<(RootMeasurements, RootLandmarks), MeasureError> {
    measure_root_with_profile(mesh).map(|(m, l, _)| (m, l))
}

/// [`measure_root_with_landmarks`] together with the centreline profile it was read from.
pub fn measure_root_with_profile(
    mesh: &TriMesh,
) -> Result<(RootMeasurements, RootLandmarks, VesselMeasurements), MeasureError> {
    let surface = Surface::new(mesh)?;
    measure_prepared_root(&surface).map(|(m, l, v, _)| (m, l, v))
}

/// [`measure_root_with_profile`] of a prepared surface, also returning the centreline the
/// landmark arc lengths refer to (for planes placed relative to the landmarks).
pub(crate) fn measure_prepared_root(
    surface: &Surface,
) -> Result<
    (
        RootMeasurements,
        RootLandmarks,
        VesselMeasurements,
        Centreline,
    ),
    MeasureError,
> {
    let opts = MeasureOptions::default();
    let (line, vessel) = measure_prepared(surface, &opts)?;
    let stations = &vessel.stations;
    let spacing = line.length() / stations.len().max(1) as f64;
    let profile = smooth(
        &stations
            .iter()
            .map(|s| s.equivalent_diameter_mm)
            .collect::<Vec<_>>(),
        2.0 / spacing,
    );
    let length = line.length();
    // On an aorta with branches the root can only be at the proximal end.
    let is_sinus = |i: usize, prominence: f64| {
        let s = stations[i].s_mm;
        let from_end = if line.starts_proximal() {
            s
        } else {
            s.min(length - s)
        };
        from_end <= SINUS_REACH_DIAMETERS * profile[i]
            && prominence >= MIN_PROMINENCE.max(MIN_RELATIVE_PROMINENCE * profile[i])
    };
    let reach = |i: usize| (PROMINENCE_REACH_DIAMETERS * profile[i] / spacing).ceil() as usize;
    let (peak, prominence) = most_prominent_peak(&profile, reach, is_sinus).ok_or_else(|| {
        MeasureError::NotARoot(format!(
            "the diameter profile has no sinus bulge: no maximum within \
             {SINUS_REACH_DIAMETERS} diameter of an end standing at least \
             {:.0} % ({MIN_PROMINENCE} mm) above both sides",
            100.0 * MIN_RELATIVE_PROMINENCE
        ))
    })?;
    tracing::debug!(prominence, "sinus bulge found");
    let forward = stations[peak].s_mm <= 0.5 * length;
    let root = RootLine {
        surface,
        line: &line,
        forward,
    };
    let sigma_peak = if forward {
        stations[peak].s_mm
    } else {
        length - stations[peak].s_mm
    };

    let after = root.dense(sigma_peak, sigma_peak + 30.0);
    let sigma_stj = find_stj(&after)
        .ok_or_else(|| MeasureError::NotARoot("no sinotubular junction past the sinus".into()))?;
    let before = root.dense(0.0, sigma_peak);
    if before.len() < 4 {
        return Err(MeasureError::NotARoot(
            "the sinus bulge touches the inlet: no annulus below it".into(),
        ));
    }
    let peak_diameter = after.first().map_or(profile[peak], |s| s.diameter);
    let sigma_annulus = find_annulus(&before, peak_diameter);

    let missing = |what: &str, at: f64| {
        MeasureError::NotTubular(format!("no closed {what} section at {at:.2} mm"))
    };
    let annulus = root
        .sample(sigma_annulus)
        .ok_or_else(|| missing("annulus", sigma_annulus))?;
    let stj = root
        .sample(sigma_stj)
        .ok_or_else(|| missing("STJ", sigma_stj))?;
    let (major, minor) = annulus.section.feret();
    let sinus = sinus_diameter(surface, annulus.section.centroid, stj.section.centroid)
        .ok_or_else(|| missing("sinus", 0.5 * (sigma_annulus + sigma_stj)))?;

    let distal_start = sigma_stj + 0.5 * (length - sigma_stj);
    let mut ascending: Vec<f64> = stations
        .iter()
        .filter(|st| {
            let sigma = if forward { st.s_mm } else { length - st.s_mm };
            sigma >= distal_start && sigma <= length - 0.5 * st.equivalent_diameter_mm
        })
        .map(|st| st.equivalent_diameter_mm)
        .collect();
    if ascending.is_empty() {
        return Err(MeasureError::NotARoot(
            "no ascending segment beyond the sinotubular junction".into(),
        ));
    }
    ascending.sort_by(f64::total_cmp);
    let to_s = |sigma: f64| if forward { sigma } else { length - sigma };
    let measurements = RootMeasurements {
        annulus_major_mm: major,
        annulus_minor_mm: minor,
        annulus_mean_mm: 0.5 * (major + minor),
        sinus_diameter_mm: sinus,
        stj_diameter_mm: stj.diameter,
        sinus_height_mm: sigma_stj - sigma_annulus,
        ascending_diameter_mm: ascending[ascending.len() / 2],
    };
    let landmarks = RootLandmarks {
        inlet_at_start: forward,
        annulus_s_mm: to_s(sigma_annulus),
        stj_s_mm: to_s(sigma_stj),
    };
    Ok((measurements, landmarks, vessel, line))
}
