//! A small software renderer so the project draws its own pictures (README figures,
//! the worst reconstruction of an evaluation): orthographic, z-buffered, Lambert-shaded
//! (smooth with the mesh's vertex normals, flat without),
//! several meshes side by side at one common scale, written as PNG.

mod labelled;
mod png_out;
mod raster;

use crate::geometry::TriMesh;
use crate::geometry::mesh::{cross, dot, normalized};
pub use labelled::{face_colour, render_labelled};
pub use png_out::encode_png;
use raster::{Canvas, Material, ScreenTriangle, face_normal};

/// Largest accepted image side, in pixels.
pub const MAX_SIDE: u32 = 8192;

/// An 8-bit RGB image, rows top to bottom, `3 · width · height` bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Interleaved RGB bytes.
    pub pixels: Vec<u8>,
}

impl RgbImage {
    /// The colour of pixel (x, y).
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let k = 3 * (y as usize * self.width as usize + x as usize);
        [self.pixels[k], self.pixels[k + 1], self.pixels[k + 2]]
    }
}

/// Where the camera looks from and how the picture is styled.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Camera direction around the up axis, degrees (0 = looking from +x).
    pub azimuth_deg: f64,
    /// Camera height above the horizontal plane, degrees.
    pub elevation_deg: f64,
    /// World axis shown pointing up in the picture.
    pub up: [f64; 3],
    /// Background colour.
    pub background: [u8; 3],
    /// Colour of outward-facing surfaces.
    pub colour: [u8; 3],
    /// Colour of inward-facing surfaces seen through open ends.
    pub inside_colour: [u8; 3],
    /// Samples per pixel along each axis (anti-aliasing), 1–4.
    pub supersample: u32,
    /// Meshes per row; `None` picks the grid that draws them largest.
    pub columns: Option<usize>,
}

impl Default for View {
    /// A three-quarter view from slightly above, +z up, aortic red on white.
    fn default() -> Self {
        Self {
            azimuth_deg: -60.0,
            elevation_deg: 15.0,
            up: [0.0, 0.0, 1.0],
            background: [255, 255, 255],
            colour: [205, 92, 80],
            inside_colour: [120, 60, 55],
            supersample: 3,
            columns: None,
        }
    }
}

/// Why a picture could not be rendered.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RenderError {
    /// Nothing to draw.
    #[error("no meshes to render")]
    NoMeshes,
    /// Mesh `index` fails validation.
    #[error("mesh {index} cannot be rendered: {source}")]
    BadMesh {
        /// Position in the input list.
        index: usize,
        /// What is wrong with it.
        source: crate::geometry::MeshError,
    },
    /// Image size or view setting out of range.
    #[error("invalid view: {0}")]
    BadView(String),
    /// PNG encoding failed.
    #[error("PNG encoding failed: {0}")]
    Png(String),
}

/// Camera basis: `right`, `up`, and `toward` (from the scene to the eye).
struct Camera {
    right: [f64; 3],
    up: [f64; 3],
    toward: [f64; 3],
}

impl Camera {
    fn new(view: &View) -> Result<Self, RenderError> {
        let up = normalized(view.up);
        // Build a horizontal basis (h1, h2) ⟂ up, then place the eye by azimuth/elevation.
        let helper = if up[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        if dot(up, up) == 0.0 {
            return Err(RenderError::BadView("the up vector is zero".into()));
        }
        let h2 = normalized(cross(up, helper));
        let h1 = cross(h2, up);
        let (sa, ca) = view.azimuth_deg.to_radians().sin_cos();
        let (se, ce) = view.elevation_deg.to_radians().sin_cos();
        let toward: [f64; 3] = std::array::from_fn(|i| ce * (ca * h1[i] + sa * h2[i]) + se * up[i]);
        let side = cross(up, toward);
        if dot(side, side) < 1e-12 {
            return Err(RenderError::BadView(
                "an elevation of ±90° leaves no horizon".into(),
            ));
        }
        let right = normalized(side);
        Ok(Self {
            right,
            up: cross(toward, right),
            toward,
        })
    }

    fn to_camera(&self, p: [f64; 3]) -> [f64; 3] {
        [dot(p, self.right), dot(p, self.up), dot(p, self.toward)]
    }
}

/// Renders `meshes` in a grid of cells (row-major), each centred in its cell, all at one
/// scale so their relative sizes are true. Returns the image; see [`encode_png`].
pub fn render_meshes(
    meshes: &[&TriMesh],
    width: u32,
    height: u32,
    view: &View,
) -> Result<RgbImage, RenderError> {
    if meshes.is_empty() {
        return Err(RenderError::NoMeshes);
    }
    if !(1..=MAX_SIDE).contains(&width) || !(1..=MAX_SIDE).contains(&height) {
        return Err(RenderError::BadView(format!(
            "image size {width}×{height} must be within 1..={MAX_SIDE} on each side"
        )));
    }
    if !(1..=4).contains(&view.supersample) {
        return Err(RenderError::BadView(format!(
            "supersample {} must be 1–4",
            view.supersample
        )));
    }
    for (index, m) in meshes.iter().enumerate() {
        m.validate()
            .map_err(|source| RenderError::BadMesh { index, source })?;
    }
    let camera = Camera::new(view)?;
    let ss = view.supersample as usize;
    let (w, h) = (width as usize * ss, height as usize * ss);
    // Camera-space vertices and the projected extent of every mesh.
    let projected: Vec<Vec<[f64; 3]>> = meshes
        .iter()
        .map(|m| {
            m.positions
                .iter()
                .map(|p| camera.to_camera(p.map(f64::from)))
                .collect()
        })
        .collect();
    let extents: Vec<([f64; 2], [f64; 2])> = projected.iter().map(|v| extent_2d(v)).collect();
    let widest = extents
        .iter()
        .map(|(lo, hi)| hi[0] - lo[0])
        .fold(f64::MIN_POSITIVE, f64::max);
    let tallest = extents
        .iter()
        .map(|(lo, hi)| hi[1] - lo[1])
        .fold(f64::MIN_POSITIVE, f64::max);
    let fit = |columns: usize| {
        let rows = meshes.len().div_ceil(columns);
        let (cell_w, cell_h) = (w as f64 / columns as f64, h as f64 / rows as f64);
        (
            0.92 * (cell_w / widest).min(cell_h / tallest),
            cell_w,
            cell_h,
        )
    };
    let columns = match view.columns {
        Some(c) => c.clamp(1, meshes.len()),
        // The grid that draws the meshes largest.
        None => (1..=meshes.len())
            .max_by(|&a, &b| fit(a).0.total_cmp(&fit(b).0))
            .unwrap_or(1),
    };
    let (scale, cell_w, cell_h) = fit(columns);

    let to_f = |c: [u8; 3]| c.map(|x| f64::from(x) / 255.0);
    let light = normalized([-0.35, 0.55, 1.0]);
    let material = Material {
        outside: to_f(view.colour),
        inside: to_f(view.inside_colour),
        light,
        ambient: 0.22,
        specular: 0.18,
        shininess: 40,
    };
    let mut canvas = Canvas::new(w, h, to_f(view.background));
    for (i, (mesh, verts)) in meshes.iter().zip(&projected).enumerate() {
        let (lo, hi) = extents[i];
        let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        let cell = [(i % columns) as f64 + 0.5, (i / columns) as f64 + 0.5];
        let to_pixel = |q: [f64; 3]| {
            [
                cell[0] * cell_w + scale * (q[0] - centre[0]),
                cell[1] * cell_h - scale * (q[1] - centre[1]),
                -q[2],
            ]
        };
        // Smooth shading with the mesh's own normals; flat shading without them.
        let normals: Option<Vec<[f64; 3]>> = mesh.normals.as_ref().map(|n| {
            n.iter()
                .map(|v| camera.to_camera(v.map(f64::from)))
                .collect()
        });
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|k| verts[k as usize]);
            let face = face_normal(a, b, c);
            let tri = ScreenTriangle {
                corners: [to_pixel(a), to_pixel(b), to_pixel(c)],
                normals: match &normals {
                    Some(n) => t.map(|k| n[k as usize]),
                    None => [face; 3],
                },
                face_normal: face,
            };
            canvas.draw(&tri, &material);
        }
    }
    Ok(downsample(&canvas, ss, width, height))
}

fn extent_2d(v: &[[f64; 3]]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in v {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// Box-filters the supersampled canvas to the output size and quantises to 8 bits.
fn downsample(canvas: &Canvas, ss: usize, width: u32, height: u32) -> RgbImage {
    let (width_px, height_px) = (width as usize, height as usize);
    let mut pixels = Vec::with_capacity(3 * width_px * height_px);
    let norm = 1.0 / (ss * ss) as f64;
    for y in 0..height_px {
        for x in 0..width_px {
            let mut acc = [0.0; 3];
            for dy in 0..ss {
                for dx in 0..ss {
                    let c = canvas.colour[(y * ss + dy) * canvas.width + x * ss + dx];
                    for k in 0..3 {
                        acc[k] += c[k];
                    }
                }
            }
            pixels.extend(acc.map(|v| (v * norm * 255.0).round().clamp(0.0, 255.0) as u8));
        }
    }
    RgbImage {
        width,
        height,
        pixels,
    }
}
