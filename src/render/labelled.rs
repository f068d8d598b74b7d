//! Pictures of face-labelled surfaces: each face id drawn in its own colour (wall, inlet,
//! outlets, extensions), with the same camera, shading and anti-aliasing as
//! [`super::render_meshes`].

use super::raster::{Canvas, Material, ScreenTriangle, face_normal};
use super::{Camera, RenderError, RgbImage, View, downsample, extent_2d};
use crate::geometry::TriMesh;
use crate::geometry::mesh::normalized;

/// Colour of face id `id`: the wall in the view's colour, then a fixed palette.
pub fn face_colour(id: u32, view: &View) -> [u8; 3] {
    const PALETTE: [[u8; 3]; 8] = [
        [52, 120, 200],
        [60, 170, 90],
        [240, 170, 40],
        [150, 90, 190],
        [40, 180, 190],
        [230, 110, 160],
        [120, 120, 120],
        [180, 150, 60],
    ];
    if id == 0 {
        view.colour
    } else {
        PALETTE[(id as usize - 1) % PALETTE.len()]
    }
}

/// Renders one mesh with a colour per face id (`face_ids` has one id per triangle).
pub fn render_labelled(
    mesh: &TriMesh,
    face_ids: &[u32],
    width: u32,
    height: u32,
    view: &View,
) -> Result<RgbImage, RenderError> {
    mesh.validate()
        .map_err(|source| RenderError::BadMesh { index: 0, source })?;
    if face_ids.len() != mesh.triangles.len() || !(1..=4).contains(&view.supersample) {
        return Err(RenderError::BadView(format!(
            "{} face ids for {} triangles, supersample {}",
            face_ids.len(),
            mesh.triangles.len(),
            view.supersample
        )));
    }
    let camera = Camera::new(view)?;
    let ss = view.supersample as usize;
    let (w, h) = (width as usize * ss, height as usize * ss);
    let verts: Vec<[f64; 3]> = mesh
        .positions
        .iter()
        .map(|p| camera.to_camera(p.map(f64::from)))
        .collect();
    let (lo, hi) = extent_2d(&verts);
    let scale =
        0.92 * (w as f64 / (hi[0] - lo[0]).max(1e-12)).min(h as f64 / (hi[1] - lo[1]).max(1e-12));
    let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    let to_pixel = |q: [f64; 3]| {
        [
            0.5 * w as f64 + scale * (q[0] - centre[0]),
            0.5 * h as f64 - scale * (q[1] - centre[1]),
            -q[2],
        ]
    };
    let to_f = |c: [u8; 3]| c.map(|x| f64::from(x) / 255.0);
    let mut canvas = Canvas::new(w, h, to_f(view.background));
    for (t, &id) in mesh.triangles.iter().zip(face_ids) {
        let colour = to_f(face_colour(id, view));
        let material = Material {
            outside: colour,
            inside: colour.map(|c| 0.6 * c),
            light: normalized([-0.35, 0.55, 1.0]),
            ambient: 0.22,
            specular: 0.18,
            shininess: 40,
        };
        let [a, b, c] = t.map(|k| verts[k as usize]);
        let face = face_normal(a, b, c);
        canvas.draw(
            &ScreenTriangle {
                corners: [to_pixel(a), to_pixel(b), to_pixel(c)],
                normals: [face; 3],
                face_normal: face,
            },
            &material,
        );
    }
    Ok(downsample(&canvas, ss, width, height))
}
