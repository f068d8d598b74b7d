//! Analytic implicit shapes with exact gradients: references for tests and benchmarks of the
//! extraction, and a stand-in field wherever a trained model is not needed.

use super::ScalarField;
use rayon::prelude::*;

/// An analytic field, negative inside. Every variant is 1-Lipschitz except the gyroid.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// Exact distance to a sphere.
    Sphere {
        /// Centre.
        centre: [f32; 3],
        /// Radius.
        radius: f32,
    },
    /// Exact distance to a torus whose ring lies in the xz-plane (around the y axis).
    Torus {
        /// Centre.
        centre: [f32; 3],
        /// Ring radius.
        major: f32,
        /// Tube radius.
        minor: f32,
    },
    /// First-order ellipsoid distance `(|q / a| − 1) · min(a)`, q = p − centre.
    Ellipsoid {
        /// Centre.
        centre: [f32; 3],
        /// Semi-axes.
        axes: [f32; 3],
    },
    /// Infinite plate `|n · p − offset| − half_thickness` (n of unit length).
    Plate {
        /// Unit normal.
        normal: [f32; 3],
        /// Signed distance of the mid-plane from the origin.
        offset: f32,
        /// Half the plate's thickness.
        half_thickness: f32,
    },
    /// Thickened gyroid sheet `|g(ωp)| / ω − half_thickness` (√6-Lipschitz): a surface full of
    /// saddles, hence of ambiguous marching-cubes cells.
    Gyroid {
        /// Angular frequency ω.
        frequency: f32,
        /// Half the sheet's thickness.
        half_thickness: f32,
    },
    /// Union (minimum) of shapes.
    Union(Vec<Shape>),
    /// Intersection (maximum) of shapes.
    Intersection(Vec<Shape>),
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn length(a: [f32; 3]) -> f32 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn scaled(a: [f32; 3], s: f32) -> [f32; 3] {
    a.map(|c| c * s)
}

impl Shape {
    /// The scene of the reference marching-cubes benchmark (peers/bench_marching_cubes.py):
    /// union of a torus, two spheres and an ellipsoid.
    pub fn benchmark_scene() -> Self {
        Shape::Union(vec![
            Shape::Torus {
                centre: [0.0; 3],
                major: 0.5,
                minor: 0.15,
            },
            Shape::Sphere {
                centre: [0.55, 0.35, 0.1],
                radius: 0.3,
            },
            Shape::Sphere {
                centre: [-0.4, -0.45, -0.3],
                radius: 0.22,
            },
            Shape::Ellipsoid {
                centre: [0.0, 0.1, -0.05],
                axes: [0.25, 0.6, 0.2],
            },
        ])
    }

    /// Value and gradient at `p` (the gradient of the active part for unions/intersections).
    pub fn value_and_gradient(&self, p: [f32; 3]) -> (f32, [f32; 3]) {
        match self {
            Shape::Sphere { centre, radius } => {
                let q = sub(p, *centre);
                let l = length(q);
                (
                    l - radius,
                    if l > 0.0 {
                        scaled(q, 1.0 / l)
                    } else {
                        [0.0; 3]
                    },
                )
            }
            Shape::Torus {
                centre,
                major,
                minor,
            } => {
                let q = sub(p, *centre);
                let ring = (q[0] * q[0] + q[2] * q[2]).sqrt();
                let (dx, dy) = (ring - major, q[1]);
                let l = (dx * dx + dy * dy).sqrt();
                let (ux, uy) = if l > 0.0 {
                    (dx / l, dy / l)
                } else {
                    (0.0, 0.0)
                };
                let (cx, cz) = if ring > 0.0 {
                    (q[0] / ring, q[2] / ring)
                } else {
                    (0.0, 0.0)
                };
                (l - minor, [ux * cx, uy, ux * cz])
            }
            Shape::Ellipsoid { centre, axes } => {
                let q = sub(p, *centre);
                let e: [f32; 3] = std::array::from_fn(|k| q[k] / axes[k]);
                let k0 = length(e);
                let m = axes[0].min(axes[1]).min(axes[2]);
                let g = if k0 > 0.0 {
                    std::array::from_fn(|k| m * e[k] / (k0 * axes[k]))
                } else {
                    [0.0; 3]
                };
                ((k0 - 1.0) * m, g)
            }
            Shape::Plate {
                normal,
                offset,
                half_thickness,
            } => {
                let d = normal[0] * p[0] + normal[1] * p[1] + normal[2] * p[2] - offset;
                (d.abs() - half_thickness, scaled(*normal, d.signum()))
            }
            Shape::Gyroid {
                frequency: w,
                half_thickness,
            } => {
                let [x, y, z] = p.map(|c| c * w);
                let (sx, cx, sy, cy, sz, cz) =
                    (x.sin(), x.cos(), y.sin(), y.cos(), z.sin(), z.cos());
                let g = sx * cy + sy * cz + sz * cx;
                let grad = [cx * cy - sz * sx, cy * cz - sx * sy, cz * cx - sy * sz];
                (g.abs() / w - half_thickness, scaled(grad, g.signum()))
            }
            Shape::Union(parts) => extreme(parts, p, |a, b| a < b),
            Shape::Intersection(parts) => extreme(parts, p, |a, b| a > b),
        }
    }
}

/// The part whose value wins under `better`, with its gradient.
fn extreme(parts: &[Shape], p: [f32; 3], better: fn(f32, f32) -> bool) -> (f32, [f32; 3]) {
    parts
        .iter()
        .map(|s| s.value_and_gradient(p))
        .reduce(|a, b| if better(b.0, a.0) { b } else { a })
        .unwrap_or((f32::INFINITY, [0.0; 3]))
}

impl ScalarField for Shape {
    fn eval_batch(
        &self,
        points: &[[f32; 3]],
        values: &mut [f32],
        gradients: Option<&mut [[f32; 3]]>,
    ) {
        const CHUNK: usize = 2048;
        match gradients {
            Some(grads) => points
                .par_chunks(CHUNK)
                .zip(values.par_chunks_mut(CHUNK))
                .zip(grads.par_chunks_mut(CHUNK))
                .for_each(|((p, v), g)| {
                    for ((p, v), g) in p.iter().zip(v).zip(g) {
                        (*v, *g) = self.value_and_gradient(*p);
                    }
                }),
            None => points
                .par_chunks(CHUNK)
                .zip(values.par_chunks_mut(CHUNK))
                .for_each(|(p, v)| {
                    for (p, v) in p.iter().zip(v) {
                        *v = self.value_and_gradient(*p).0;
                    }
                }),
        }
    }

    fn lipschitz_bound(&self) -> f32 {
        match self {
            // Each partial derivative of g/ω has the form a·cos u − b·sin u with |a|, |b| ≤ 1.
            Shape::Gyroid { .. } => 6f32.sqrt(),
            Shape::Union(parts) | Shape::Intersection(parts) => parts
                .iter()
                .map(|s| s.lipschitz_bound())
                .fold(0.0, f32::max),
            _ => 1.0,
        }
    }
}
