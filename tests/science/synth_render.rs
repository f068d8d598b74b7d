//! The software renderer against hand-computed pictures.

use aortagen::geometry::TriMesh;
use aortagen::render::{RenderError, RgbImage, View, encode_png, render_meshes};

/// The unit cube [0,1]³ with outward triangles.
fn cube() -> TriMesh {
    TriMesh::unit_cube()
}

fn front_view() -> View {
    View {
        azimuth_deg: 0.0,
        elevation_deg: 0.0,
        supersample: 1,
        ..View::default()
    }
}

/// Lambert shade of a face whose normal points at the viewer, as the renderer defines it.
fn facing_shade(colour: u8) -> u8 {
    let light = [-0.35f64, 0.55, 1.0];
    let lambert = 1.0 / light.iter().map(|c| c * c).sum::<f64>().sqrt();
    let shade = 0.22 + 0.78 * lambert;
    // Blinn–Phong highlight with the half vector of light and view (+z).
    let n = light.iter().map(|c| c * c).sum::<f64>().sqrt();
    let half = [light[0] / n, light[1] / n, light[2] / n + 1.0];
    let half_z = half[2] / half.iter().map(|c| c * c).sum::<f64>().sqrt();
    let highlight = 0.18 * half_z.powi(40);
    ((f64::from(colour) / 255.0 * shade + highlight).min(1.0) * 255.0).round() as u8
}

fn covered(img: &RgbImage, background: [u8; 3]) -> usize {
    img.pixels.chunks(3).filter(|p| *p != background).count()
}

#[test]
fn a_cube_seen_face_on_is_a_shaded_square_of_the_expected_size() {
    let view = front_view();
    let img = render_meshes(&[&cube()], 100, 100, &view).unwrap();
    // One mesh fills 92 % of its cell: a 92 × 92 square centred in the image.
    let n = covered(&img, view.background);
    assert!(
        (92 * 92 - 2 * 92..=92 * 92 + 2 * 92 + 1).contains(&n),
        "{n} pixels covered"
    );
    let expected = view.colour.map(facing_shade);
    assert_eq!(img.pixel(50, 50), expected);
    assert_eq!(img.pixel(1, 1), view.background);
}

#[test]
fn nearer_surfaces_hide_farther_ones_whatever_the_drawing_order() {
    // A square facing the viewer (+x) at x = 1 and a tilted square behind it at x = 0.
    let positions = vec![
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [1.0, 1.0, 1.0],
        [1.0, 0.0, 1.0],
        [0.5, -0.5, -0.5],
        [0.0, 1.5, -0.5],
        [0.0, 1.5, 1.5],
        [0.5, -0.5, 1.5],
    ];
    let front = [[0u32, 1, 2], [0, 2, 3]];
    let back = [[4u32, 5, 6], [4, 6, 7]];
    let view = front_view();
    let draw = |tris: Vec<[u32; 3]>| {
        render_meshes(&[&TriMesh::new(positions.clone(), tris)], 64, 64, &view).unwrap()
    };
    let a = draw([front, back].concat());
    let b = draw([back, front].concat());
    assert_eq!(a, b);
    assert_eq!(a.pixel(32, 32), view.colour.map(facing_shade));
}

#[test]
fn inner_walls_seen_through_an_opening_use_the_inside_colour() {
    let mut open = cube();
    open.triangles
        .retain(|t| *t != [1, 3, 5] && *t != [3, 7, 5]); // remove the +x face
    let view = front_view();
    let img = render_meshes(&[&open], 100, 100, &view).unwrap();
    // Through the hole we see the back of the x = 0 face, whose flipped normal faces us.
    assert_eq!(img.pixel(50, 50), view.inside_colour.map(facing_shade));
}

#[test]
fn meshes_share_one_scale_side_by_side() {
    let small = cube();
    let mut big = cube();
    big.scale_and_translate(2.0, [0.0; 3]);
    let view = front_view();
    let img = render_meshes(&[&small, &big], 200, 100, &view).unwrap();
    let left = (0..100)
        .filter(|&x| img.pixel(x, 50) != view.background)
        .count();
    let right = (100..200)
        .filter(|&x| img.pixel(x, 50) != view.background)
        .count();
    assert!(
        (2 * left).abs_diff(right) <= 2,
        "left {left}, right {right}"
    );
}

#[test]
fn png_round_trips_the_pixels() {
    let img = render_meshes(&[&cube()], 40, 30, &View::default()).unwrap();
    let bytes = encode_png(&img).unwrap();
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (40, 30));
    assert_eq!(&buf[..info.buffer_size()], &img.pixels[..]);
}

#[test]
fn bad_requests_are_refused_with_a_reason() {
    let c = cube();
    assert_eq!(
        render_meshes(&[], 10, 10, &View::default()),
        Err(RenderError::NoMeshes)
    );
    assert!(matches!(
        render_meshes(&[&c], 0, 10, &View::default()),
        Err(RenderError::BadView(_))
    ));
    let bad = TriMesh::new(vec![[0.0; 3]; 3], vec![[0, 1, 7]]);
    assert!(matches!(
        render_meshes(&[&c, &bad], 10, 10, &View::default()),
        Err(RenderError::BadMesh { index: 1, .. })
    ));
    let top = View {
        elevation_deg: 90.0,
        ..View::default()
    };
    assert!(matches!(
        render_meshes(&[&c], 10, 10, &top),
        Err(RenderError::BadView(_))
    ));
}
