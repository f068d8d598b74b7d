//! The root surface: a tube swept along the centreline whose cross-section radius r(s, θ)
//! is elliptic at the annulus, three-lobed in the sinuses, circular from the sinotubular
//! junction on, then tapers to the ascending diameter.

use std::f64::consts::{FRAC_PI_3, PI, TAU};

use super::centreline::Centreline;
use super::params::{AorticRootParams, ParamsError};
use crate::geometry::TriMesh;

/// Fraction of the ascending segment over which the STJ diameter blends to the ascending one.
pub const TAPER_FRACTION: f64 = 0.4;

/// How finely the surface is tessellated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SurfaceResolution {
    /// Cross-section loops along the centreline (at least 8).
    pub rings: usize,
    /// Vertices per loop (at least 12, a multiple of 4 keeps the annulus axes on vertices).
    pub segments: usize,
}

impl Default for SurfaceResolution {
    /// 200 × 128: 51 200 triangles, smooth at rendering and sampling scales.
    fn default() -> Self {
        Self {
            rings: 200,
            segments: 128,
        }
    }
}

/// Cubic smoothstep on [0, 1] (zero slope at both ends).
fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The radius function r(s, θ) of one parameter set.
#[derive(Debug, Clone)]
pub struct RadiusProfile {
    annulus_semi_axes: (f64, f64),
    stj: f64,
    sinus: f64,
    ascending: f64,
    height: f64,
    taper: f64,
    lobe_centres: [f64; 3],
    lobe_scales: [f64; 3],
}

impl RadiusProfile {
    /// The profile of `p` (assumed valid).
    pub fn new(p: &AorticRootParams) -> Self {
        let (major, minor) = p.annulus_axes_mm();
        let rot = p.lobe_rotation_deg.to_radians();
        Self {
            annulus_semi_axes: (0.5 * major, 0.5 * minor),
            stj: 0.5 * p.stj_diameter_mm,
            sinus: 0.5 * p.sinus_diameter_mm,
            ascending: 0.5 * p.ascending_diameter_mm,
            height: p.sinus_height_mm,
            taper: TAPER_FRACTION * p.ascending_length_mm,
            lobe_centres: std::array::from_fn(|k| rot + k as f64 * TAU / 3.0),
            lobe_scales: p.lobe_scales,
        }
    }

    /// Radius of the annulus ellipse in direction θ (major axis along θ = 0).
    fn ellipse(&self, theta: f64) -> f64 {
        let (a, b) = self.annulus_semi_axes;
        let (s, c) = theta.sin_cos();
        a * b / ((b * c).powi(2) + (a * s).powi(2)).sqrt()
    }

    /// Radius of the sinus cross-section at mid-height: each lobe rises from the STJ radius
    /// at the commissures (±60° from its centre) to its peak with a cos² profile, which is
    /// C¹ across the commissures whatever the lobe sizes.
    fn lobes(&self, theta: f64) -> f64 {
        for (centre, scale) in self.lobe_centres.iter().zip(self.lobe_scales) {
            let delta = (theta - centre + PI).rem_euclid(TAU) - PI;
            if delta.abs() < FRAC_PI_3 {
                let peak = self.stj + scale * (self.sinus - self.stj);
                return self.stj + (peak - self.stj) * (1.5 * delta).cos().powi(2);
            }
        }
        self.stj
    }

    /// r(s, θ) with s the centreline arc length from the annulus plane.
    ///
    /// In the root the radius is `(1 − β)·base + β·lobes` with β = sin²(πs/h) and `base`
    /// blending ellipse → STJ circle: at s = h/2 it equals the lobe profile exactly, and since
    /// both terms stay below the sinus radius the widest point is the largest lobe's peak.
    pub fn radius(&self, s: f64, theta: f64) -> f64 {
        if s <= 0.0 {
            return self.ellipse(theta);
        }
        if s <= self.height {
            let t = s / self.height;
            let w = smoothstep(t);
            let base = (1.0 - w) * self.ellipse(theta) + w * self.stj;
            let beta = (PI * t).sin().powi(2);
            return (1.0 - beta) * base + beta * self.lobes(theta);
        }
        let w = smoothstep((s - self.height) / self.taper);
        (1.0 - w) * self.stj + w * self.ascending
    }
}

/// Arc-length positions of the rings: the outflow stub, the root (sampled twice as densely,
/// with rings exactly at the annulus, mid-sinus and the STJ) and the ascending arc.
fn ring_positions(p: &AorticRootParams, rings: usize) -> Vec<f64> {
    let (l, h, a) = (p.lvot_length_mm, p.sinus_height_mm, p.ascending_length_mm);
    let intervals = rings - 1;
    let weight = l + 2.0 * h + a;
    let n_l = ((intervals as f64 * l / weight).round() as usize).max(1);
    let n_h = (((intervals as f64 * 2.0 * h / weight) / 2.0).round() as usize * 2).max(2);
    let n_a = intervals.saturating_sub(n_l + n_h).max(1);
    let mut s = Vec::with_capacity(n_l + n_h + n_a + 1);
    s.extend((0..n_l).map(|i| -l + l * i as f64 / n_l as f64));
    s.extend((0..n_h).map(|i| h * i as f64 / n_h as f64));
    s.extend((0..=n_a).map(|i| h + a * i as f64 / n_a as f64));
    s
}

/// Builds the surface at the default resolution; see [`build_root_with`].
pub fn build_root(p: &AorticRootParams, closed: bool) -> Result<TriMesh, ParamsError> {
    build_root_with(p, closed, SurfaceResolution::default())
}

/// Builds the surface in millimetres. `closed` adds flat end caps (centre-vertex fans),
/// giving a watertight, outward-oriented, genus-0 mesh; otherwise both ends stay open.
/// Vertex normals are included.
pub fn build_root_with(
    p: &AorticRootParams,
    closed: bool,
    res: SurfaceResolution,
) -> Result<TriMesh, ParamsError> {
    p.validate()?;
    if res.rings < 8 || res.segments < 12 {
        return Err(ParamsError::Inconsistent(format!(
            "resolution {} rings × {} segments is below the minimum 8 × 12",
            res.rings, res.segments
        )));
    }
    let line = Centreline::new(p);
    let profile = RadiusProfile::new(p);
    let s_values = ring_positions(p, res.rings);
    let n = res.segments;
    let thetas: Vec<f64> = (0..n).map(|j| TAU * j as f64 / n as f64).collect();

    let mut positions = Vec::with_capacity(s_values.len() * n + 2);
    for &s in &s_values {
        let frame = line.frame(s);
        for &theta in &thetas {
            let q = frame.at(profile.radius(s, theta), theta);
            positions.push(q.map(|c| c as f32));
        }
    }
    let idx = |i: usize, j: usize| (i * n + j % n) as u32;
    let mut triangles = Vec::with_capacity(2 * n * s_values.len());
    for i in 0..s_values.len() - 1 {
        for j in 0..n {
            // (θ step) × (s step) points outward for a right-handed (u, v, t) frame.
            let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    if closed {
        let last = s_values.len() - 1;
        for (ring, s, outward_is_t) in [(0, s_values[0], false), (last, s_values[last], true)] {
            let centre = positions.len() as u32;
            positions.push(line.frame(s).origin.map(|c| c as f32));
            for j in 0..n {
                let (a, b) = (idx(ring, j), idx(ring, j + 1));
                triangles.push(if outward_is_t {
                    [centre, a, b]
                } else {
                    [centre, b, a]
                });
            }
        }
    }
    let mut mesh = TriMesh::new(positions, triangles);
    mesh.normals = Some(mesh.compute_vertex_normals());
    Ok(mesh)
}
