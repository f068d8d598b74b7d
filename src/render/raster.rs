//! Z-buffered triangle rasterisation with Lambert shading (plus a faint highlight) into an
//! RGB buffer.

use crate::geometry::mesh::{cross, dot, normalized, sub};

/// A triangle already projected to pixel space with its camera-space shading normals.
pub(crate) struct ScreenTriangle {
    /// Pixel x, pixel y (down), depth (larger is farther) of each corner.
    pub corners: [[f64; 3]; 3],
    /// Camera-space unit normals at the corners (z towards the viewer).
    pub normals: [[f64; 3]; 3],
    /// Camera-space face normal (z towards the viewer), used to tell front from back.
    pub face_normal: [f64; 3],
}

/// Colour and lighting of one draw.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Material {
    pub outside: [f64; 3],
    pub inside: [f64; 3],
    pub light: [f64; 3],
    pub ambient: f64,
    /// Strength and exponent of a white Blinn–Phong highlight (viewer along +z).
    pub specular: f64,
    pub shininess: i32,
}

/// Colour and depth buffers of a frame.
pub(crate) struct Canvas {
    pub width: usize,
    pub height: usize,
    pub colour: Vec<[f64; 3]>,
    depth: Vec<f64>,
}

impl Canvas {
    pub fn new(width: usize, height: usize, background: [f64; 3]) -> Self {
        Self {
            width,
            height,
            colour: vec![background; width * height],
            depth: vec![f64::INFINITY; width * height],
        }
    }

    /// Fills the pixels whose centres the triangle covers, keeping the nearest surface.
    pub fn draw(&mut self, tri: &ScreenTriangle, material: &Material) {
        let [a, b, c] = tri.corners;
        let area = edge(a, b, c);
        if area.abs() < 1e-12 {
            return;
        }
        // Back faces (seen through an open end) get the inside colour, normals flipped.
        let front = tri.face_normal[2] >= 0.0;
        let (base, sign) = if front {
            (material.outside, 1.0)
        } else {
            (material.inside, -1.0)
        };
        let x0 = a[0].min(b[0]).min(c[0]).floor().max(0.0) as usize;
        let y0 = a[1].min(b[1]).min(c[1]).floor().max(0.0) as usize;
        let x1 = (a[0].max(b[0]).max(c[0]).ceil() as usize).min(self.width);
        let y1 = (a[1].max(b[1]).max(c[1]).ceil() as usize).min(self.height);
        for y in y0..y1 {
            for x in x0..x1 {
                let p = [x as f64 + 0.5, y as f64 + 0.5, 0.0];
                let w = [
                    edge(b, c, p) / area,
                    edge(c, a, p) / area,
                    edge(a, b, p) / area,
                ];
                if w.iter().any(|&wi| wi < 0.0) {
                    continue;
                }
                let z = w[0] * a[2] + w[1] * b[2] + w[2] * c[2];
                let k = y * self.width + x;
                if z >= self.depth[k] {
                    continue;
                }
                self.depth[k] = z;
                let n = normalized(std::array::from_fn(|i| {
                    sign * (w[0] * tri.normals[0][i]
                        + w[1] * tri.normals[1][i]
                        + w[2] * tri.normals[2][i])
                }));
                let lambert = dot(n, material.light).max(0.0);
                let shade = material.ambient + (1.0 - material.ambient) * lambert;
                let half = normalized([
                    material.light[0],
                    material.light[1],
                    material.light[2] + 1.0,
                ]);
                let highlight = material.specular * dot(n, half).max(0.0).powi(material.shininess);
                self.colour[k] = base.map(|ch| (ch * shade + highlight).min(1.0));
            }
        }
    }
}

/// Twice the signed area of (a, b, p) in the pixel plane.
fn edge(a: [f64; 3], b: [f64; 3], p: [f64; 3]) -> f64 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

/// Unit normal of the triangle (a, b, c) (zero when degenerate).
pub(crate) fn face_normal(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    normalized(cross(sub(b, a), sub(c, a)))
}
