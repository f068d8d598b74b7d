//! The centreline of a parametric root: a straight axis through the outflow tract and the
//! root, then a circular arc for the ascending aorta, with a rotation-minimising frame.

use super::params::AorticRootParams;
use crate::geometry::mesh::{cross, dot};

/// A point of the centreline with its frame: `u`, `v` span the cross-section plane and
/// `(u, v, t)` is right-handed, so θ runs counter-clockwise seen from the distal end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Centreline point.
    pub origin: [f64; 3],
    /// Cross-section axis at θ = 0.
    pub u: [f64; 3],
    /// Cross-section axis at θ = 90°.
    pub v: [f64; 3],
    /// Unit tangent (downstream).
    pub t: [f64; 3],
}

impl Frame {
    /// The point at polar coordinates (r, θ) in this frame's cross-section plane.
    pub fn at(&self, r: f64, theta: f64) -> [f64; 3] {
        let (s, c) = theta.sin_cos();
        std::array::from_fn(|i| self.origin[i] + r * (c * self.u[i] + s * self.v[i]))
    }
}

/// Straight from s = −lvot to s = stj, then an arc of the given radius bending towards
/// `bend_dir` (a unit vector ⟂ z).
#[derive(Debug, Clone, Copy)]
pub struct Centreline {
    stj: f64,
    bend_radius: f64,
    bend_dir: [f64; 3],
}

impl Centreline {
    /// The centreline described by the parameters (arc length s = 0 at the annulus).
    pub fn new(p: &AorticRootParams) -> Self {
        let (sin, cos) = p.bending_plane_deg.to_radians().sin_cos();
        Self {
            stj: p.sinus_height_mm,
            bend_radius: p.bend_radius_mm,
            bend_dir: [cos, sin, 0.0],
        }
    }

    /// Frame at arc length `s`. On the arc the initial frame is rotated about the fixed
    /// binormal z × d by s/R: for a planar curve of constant curvature this is exactly the
    /// rotation-minimising (Bishop) frame, so the cross-sections never twist.
    pub fn frame(&self, s: f64) -> Frame {
        let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        if s <= self.stj {
            return Frame {
                origin: [0.0, 0.0, s],
                u: x,
                v: y,
                t: z,
            };
        }
        let a = (s - self.stj) / self.bend_radius;
        let (sa, ca) = a.sin_cos();
        let d = self.bend_dir;
        let r = self.bend_radius;
        let origin = std::array::from_fn(|i| z[i] * (self.stj + r * sa) + d[i] * r * (1.0 - ca));
        let k = cross(z, d);
        let rotate = |w: [f64; 3]| -> [f64; 3] {
            let kw = cross(k, w);
            let kd = dot(k, w);
            std::array::from_fn(|i| w[i] * ca + kw[i] * sa + k[i] * kd * (1.0 - ca))
        };
        Frame {
            origin,
            u: rotate(x),
            v: rotate(y),
            t: rotate(z),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::mesh::{norm, sub};

    fn line() -> Centreline {
        Centreline {
            stj: 20.0,
            bend_radius: 80.0,
            bend_dir: [0.6, 0.8, 0.0],
        }
    }

    #[test]
    fn frames_are_orthonormal_and_right_handed_along_the_arc() {
        let c = line();
        for i in 0..50 {
            let f = c.frame(-5.0 + i as f64 * 2.0);
            for (a, b) in [(f.u, f.v), (f.v, f.t), (f.t, f.u)] {
                assert!(dot(a, b).abs() < 1e-12);
            }
            for w in [f.u, f.v, f.t] {
                assert!((norm(w) - 1.0).abs() < 1e-12);
            }
            assert!(norm(sub(cross(f.u, f.v), f.t)) < 1e-12);
        }
    }

    #[test]
    fn tangent_matches_finite_difference_and_arc_is_unit_speed() {
        let c = line();
        let h = 1e-5;
        for s in [25.0, 40.0, 70.0] {
            let (a, b) = (c.frame(s - h).origin, c.frame(s + h).origin);
            let fd = sub(b, a).map(|x| x / (2.0 * h));
            assert!(norm(sub(fd, c.frame(s).t)) < 1e-8, "s = {s}");
        }
        // Points stay at distance R from the arc centre.
        let centre = [0.6 * 80.0, 0.8 * 80.0, 20.0];
        for s in [20.0, 50.0, 90.0] {
            assert!((norm(sub(c.frame(s).origin, centre)) - 80.0).abs() < 1e-9);
        }
    }

    #[test]
    fn frame_does_not_twist() {
        // Rotation-minimising: du/ds has no component along v (and dv/ds none along u).
        let c = line();
        let h = 1e-5;
        for s in [30.0, 60.0] {
            let du = sub(c.frame(s + h).u, c.frame(s - h).u).map(|x| x / (2.0 * h));
            assert!(dot(du, c.frame(s).v).abs() < 1e-9);
        }
    }
}
