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
use super::{MeasureError, MeasureOptions, RootMeasurements, measure_prepared};
use crate::geometry::TriMesh;
use crate::geometry::mesh::{norm, normalized, sub};

/// Spacing of the dense profiles around the annulus and the STJ, mm.
const DENSE_STEP: f64 = 0.25;
/// Gaussian smoothing of the dense profile before differentiation, mm.
const DENSE_SMOOTHING: f64 = 0.75;
/// Smallest sinus prominence (mm of equivalent diameter) accepted as a root bulge.
const MIN_PROMINENCE: f64 = 0.25;

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
        let s = if self.forward { sigma } else { self.length() - sigma };
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
            if a == b { 0.0 } else { (values[b] - values[a]) / ((b - a) as f64 * step) }
        })
        .collect()
}

/// Index of the interior local maximum with the largest prominence, and that prominence.
fn most_prominent_peak(d: &[f64]) -> Option<(usize, f64)> {
    (1..d.len().saturating_sub(1))
        .filter(|&i| d[i] >= d[i - 1] && d[i] > d[i + 1])
        .map(|i| {
            let left = d[..i].iter().copied().fold(f64::INFINITY, f64::min);
            let right = d[i + 1..].iter().copied().fold(f64::INFINITY, f64::min);
            (i, (d[i] - left).min(d[i] - right))
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))
}

/// Vertex abscissa of the parabola through three equally spaced values, as an offset in
/// samples from the middle one (clamped to ±1).
fn parabola_vertex(y0: f64, y1: f64, y2: f64) -> f64 {
    let curvature = y0 - 2.0 * y1 + y2;
    if curvature.abs() < 1e-15 {
        0.0
    } else {
        (0.5 * (y0 - y2) / curvature).clamp(-1.0, 1.0)
    }
}

/// σ of the sinotubular junction on a dense profile starting at the sinus peak.
fn find_stj(samples: &[Sample]) -> Option<f64> {
    let sigma = DENSE_SMOOTHING / DENSE_STEP;
    let d = smooth(&samples.iter().map(|s| s.diameter).collect::<Vec<_>>(), sigma);
    let slope = derivative(&d, DENSE_STEP);
    let n = slope.len();
    // Steepest descent past the sinus.
    let mut q = 0;
    while q + 1 < n && slope[q + 1] <= slope[q] {
        q += 1;
    }
    for k in q + 1..n {
        if slope[k] >= 0.0 {
            let t = slope[k - 1] / (slope[k - 1] - slope[k]);
            return Some(samples[k - 1].sigma + t * DENSE_STEP);
        }
        if k + 1 < n && slope[k + 1] < slope[k] {
            let offset = parabola_vertex(slope[k - 1], slope[k], slope[k + 1]);
            return Some(samples[k].sigma + offset * DENSE_STEP);
        }
    }
    None
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
    if !(slope_fit > 0.0) {
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

/// Annulus, sinus, STJ and ascending diameters and the sinus height of an aortic-root
/// surface in millimetres, from its centreline profile (see the module docs).
pub fn measure_root(mesh: &TriMesh) -> Result<RootMeasurements, MeasureError> {
    let surface = Surface::new(mesh)?;
    let opts = MeasureOptions::default();
    let (line, vessel) = measure_prepared(&surface, &opts)?;
    let stations = &vessel.stations;
    let spacing = line.length() / stations.len().max(1) as f64;
    let profile = smooth(
        &stations
            .iter()
            .map(|s| s.equivalent_diameter_mm)
            .collect::<Vec<_>>(),
        2.0 / spacing,
    );
    let (peak, prominence) = most_prominent_peak(&profile)
        .filter(|&(_, p)| p >= MIN_PROMINENCE)
        .ok_or_else(|| {
            MeasureError::NotARoot(format!(
                "the diameter profile has no sinus bulge (an interior maximum at least \
                 {MIN_PROMINENCE} mm above both sides)"
            ))
        })?;
    tracing::debug!(prominence, "sinus bulge found");
    let length = line.length();
    let forward = stations[peak].s_mm <= 0.5 * length;
    let root = RootLine {
        surface: &surface,
        line: &line,
        forward,
    };
    let sigma_peak = if forward { stations[peak].s_mm } else { length - stations[peak].s_mm };

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
    let annulus = root.sample(sigma_annulus).ok_or_else(|| missing("annulus", sigma_annulus))?;
    let stj = root.sample(sigma_stj).ok_or_else(|| missing("STJ", sigma_stj))?;
    let (major, minor) = annulus.section.feret();
    let sinus = sinus_diameter(&surface, annulus.section.centroid, stj.section.centroid)
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
    Ok(RootMeasurements {
        annulus_major_mm: major,
        annulus_minor_mm: minor,
        annulus_mean_mm: 0.5 * (major + minor),
        sinus_diameter_mm: sinus,
        stj_diameter_mm: stj.diameter,
        sinus_height_mm: sigma_stj - sigma_annulus,
        ascending_diameter_mm: ascending[ascending.len() / 2],
    })
}
