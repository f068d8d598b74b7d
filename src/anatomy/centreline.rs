//! The centreline: a smoothed curve through section centroids, continued at each end until
//! it leaves the vessel, and the refinement that moves it onto the centroids of the sections
//! normal to it.

use super::polyline::{LocalQuadratic, Polyline};
use super::surface::Surface;
use super::{MeasureError, MeasureOptions};
use crate::geometry::mesh::{norm, normalized, sub};

/// Centre points (`inner`, smoothed by local quadratic fits) continued at both ends along
/// the fitted end tangents (`head`, `tail`) to where the vessel ends. Only `inner` is data: the continuation never feeds back into the
/// fits, which keeps the ends stable from one refinement to the next.
#[derive(Debug, Clone)]
pub struct Centreline {
    inner: Polyline,
    head: Option<LocalQuadratic>,
    tail: Option<LocalQuadratic>,
    head_length: f64,
    full: Polyline,
    smoothing: f64,
    starts_proximal: bool,
}

impl Centreline {
    /// Continues `inner` at both ends in steps of `step` for at most `reach` each.
    pub fn new(surface: &Surface, inner: Polyline, smoothing: f64, step: f64, reach: f64) -> Self {
        // Straight continuations along the fitted end tangents: extrapolating the curvature
        // of a one-sided fit would amplify any wobble of the last centre points.
        let straight = |s: f64, at: [f64; 3]| {
            inner.local_fit(s, smoothing).map(|mut fit| {
                fit.coeffs[0] = at;
                fit.coeffs[2] = [0.0; 3];
                fit
            })
        };
        let head = straight(0.0, inner.points()[0]);
        let tail = straight(inner.length(), inner.points()[inner.points().len() - 1]);
        let mut before = continuation(surface, &inner, head, 0.0, -1.0, step, reach);
        before.reverse();
        let after = continuation(surface, &inner, tail, inner.length(), 1.0, step, reach);
        let head_length = Polyline::new(
            before
                .iter()
                .copied()
                .chain(std::iter::once(inner.points()[0]))
                .collect(),
        )
        .length();
        let mut points = before;
        points.extend_from_slice(inner.points());
        points.extend(after);
        Self {
            full: Polyline::new(points),
            inner,
            head,
            tail,
            head_length,
            smoothing,
            starts_proximal: false,
        }
    }

    /// The same line, known to start at the vessel's proximal end (`true`: the ascending
    /// end of an aorta with branches) or not known to.
    pub fn starting_proximal(mut self, starts_proximal: bool) -> Self {
        self.starts_proximal = starts_proximal;
        self
    }

    /// Whether the line is known to start at the vessel's proximal end, where a root's
    /// inlet is.
    pub fn starts_proximal(&self) -> bool {
        self.starts_proximal
    }

    /// The centreline through a tracked path whose first and last points are the exits.
    pub fn from_path(surface: &Surface, path: Polyline, opts: &MeasureOptions) -> Self {
        let points = path.points();
        let inner = if points.len() > 4 {
            Polyline::new(points[1..points.len() - 1].to_vec())
        } else {
            path.clone()
        };
        Self::new(
            surface,
            inner,
            opts.smoothing_mm,
            opts.station_spacing_mm,
            opts.smoothing_mm + 5.0 * opts.station_spacing_mm,
        )
    }

    /// Arc length of the polyline through the centre points and continuations, which
    /// parametrises [`Centreline::frame_at`].
    pub fn length(&self) -> f64 {
        self.full.length()
    }

    /// Length of the smoothed centreline from where it enters to where it leaves the vessel:
    /// the smoothed curve sampled every `step` (the raw centre points carry millimetre-scale
    /// noise, which would lengthen the polyline through them).
    pub fn smoothed_length(&self, step: f64) -> f64 {
        let total = self.length();
        let n = ((total / step).ceil() as usize).max(1);
        let mut points: Vec<[f64; 3]> = vec![self.full.points()[0]];
        points.extend((1..n).map(|k| self.frame_at(total * k as f64 / n as f64).0));
        points.push(self.full.points()[self.full.points().len() - 1]);
        points.windows(2).map(|w| norm(sub(w[1], w[0]))).sum()
    }

    /// The whole centreline as a polyline.
    pub fn polyline(&self) -> &Polyline {
        &self.full
    }

    /// Smoothed position and unit tangent at arc length `s` from the start.
    pub fn frame_at(&self, s: f64) -> ([f64; 3], [f64; 3]) {
        let u = s - self.head_length;
        let inner_length = self.inner.length();
        let end_fit = if u < 0.0 {
            self.head.map(|f| (f, u))
        } else if u > inner_length {
            self.tail.map(|f| (f, u - inner_length))
        } else {
            None
        };
        match end_fit {
            Some((fit, ds)) if norm(fit.tangent(ds)) > 0.0 => (fit.at(ds), fit.tangent(ds)),
            _ => self
                .inner
                .frame_at(u.clamp(0.0, inner_length), self.smoothing),
        }
    }
}

/// Points of `fit` (centred at arc length `s` of `line`) beyond that end, every `step` in
/// direction `sign`, up to and including the exit point (or `reach` if none is found).
fn continuation(
    surface: &Surface,
    line: &Polyline,
    fit: Option<LocalQuadratic>,
    s: f64,
    sign: f64,
    step: f64,
    reach: f64,
) -> Vec<[f64; 3]> {
    let Some(fit) = fit else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut prev = line.point_at(s);
    let mut travelled = 0.0;
    while travelled < reach {
        travelled += step;
        let next = fit.at(sign * travelled);
        let (dir, len) = (normalized(sub(next, prev)), norm(sub(next, prev)));
        if let Some(d) = surface.first_exit(prev, dir, len) {
            out.push(std::array::from_fn(|k| prev[k] + d * dir[k]));
            return out;
        }
        out.push(next);
        prev = next;
    }
    out
}

/// Largest move of a centre point in one refinement pass, in section radii.
const MAX_SHIFT: f64 = 0.25;

/// Arc-length positions of `count` stations spaced evenly over (0, length): the stations sit
/// at the middles of `count` equal intervals, never on an end cap.
pub fn station_positions(length: f64, spacing: f64) -> Vec<f64> {
    let count = ((length / spacing).round() as usize).max(2);
    let step = length / count as f64;
    (0..count).map(|k| (k as f64 + 0.5) * step).collect()
}

/// Moves the centreline onto the area centroids of the sections normal to it, up to
/// `opts.iterations` times (stopping early once no centre moves by more than 1 µm).
pub fn refine(
    surface: &Surface,
    mut line: Centreline,
    opts: &MeasureOptions,
) -> Result<Centreline, MeasureError> {
    let starts_proximal = line.starts_proximal;
    for _ in 0..opts.iterations {
        // A plane near an end that is still tilted against a cap gives no wall section and
        // is skipped until the end has been re-extrapolated from the interior.
        let stations = station_positions(line.length(), opts.station_spacing_mm);
        let mut centres = Vec::with_capacity(stations.len());
        let mut moved = 0.0f64;
        for &s in &stations {
            let (p, t) = line.frame_at(s);
            if let Some(section) = surface.wall_section_at(p, t) {
                // A centroid far off the current point means the plane cuts a side branch or
                // the section is lopsided, and a section through a branch ostium has its
                // centroid pulled towards the branch: leave the station out rather than jump
                // (the smoothed line bridges the gap).
                let shift = norm(sub(section.centroid, p));
                let radius = (section.area / std::f64::consts::PI).sqrt();
                if shift <= MAX_SHIFT * radius && section.is_single_lumen() {
                    moved = moved.max(shift);
                    centres.push(section.centroid);
                }
            }
        }
        if centres.len() < 2 || centres.len() * 4 < stations.len() * 3 {
            return Err(MeasureError::NotTubular(format!(
                "only {} of {} planes normal to the centreline cut a closed loop around it",
                centres.len(),
                stations.len()
            )));
        }
        line = Centreline::new(
            surface,
            Polyline::new(centres),
            opts.smoothing_mm,
            opts.station_spacing_mm,
            opts.smoothing_mm + 5.0 * opts.station_spacing_mm,
        )
        .starting_proximal(starts_proximal);
        if moved < 1e-3 {
            break;
        }
    }
    Ok(line)
}
