//! Dense marching cubes against analytic surfaces: accuracy, topology and watertightness on
//! fields chosen to hit the ambiguous and degenerate cases.

use aortagen::extract::analytic::Shape;
use aortagen::geometry::TriMesh;
use aortagen::geometry::marching_cubes::{Grid, GridError, marching_cubes, try_marching_cubes};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

fn sample(grid: &Grid, shape: &Shape) -> Vec<f32> {
    grid.points()
        .map(|p| shape.value_and_gradient(p).0)
        .collect()
}

fn assert_closed_manifold(mesh: &TriMesh, what: &str) {
    let report = mesh.edge_report();
    assert!(report.is_closed_and_oriented(), "{what}: {report:?}");
    mesh.validate().unwrap_or_else(|e| panic!("{what}: {e}"));
}

#[test]
fn sphere_at_128_is_accurate_closed_and_has_genus_zero() {
    let grid = Grid::new(128);
    let r = 0.5;
    let mesh = marching_cubes(
        &grid,
        &sample(
            &grid,
            &Shape::Sphere {
                centre: [0.0; 3],
                radius: r,
            },
        ),
        0.0,
    );
    assert_closed_manifold(&mesh, "sphere");
    assert_eq!(mesh.euler_characteristic(), 2);
    for p in &mesh.positions {
        let d = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        assert!(
            (d - 0.5).abs() < 1e-3,
            "vertex {p:?} is {d} from the centre"
        );
    }
    let r = f64::from(r);
    let (area, volume) = (4.0 * PI * r * r, 4.0 / 3.0 * PI * r.powi(3));
    assert!(
        (mesh.area() / area - 1.0).abs() < 0.005,
        "area {} vs {area}",
        mesh.area()
    );
    assert!(
        (mesh.signed_volume() / volume - 1.0).abs() < 0.005,
        "volume {} vs {volume}",
        mesh.signed_volume()
    );
}

#[test]
fn sphere_normals_follow_the_analytic_normal() {
    let grid = Grid::new(64);
    let centre = [0.1, -0.05, 0.02];
    let mesh = marching_cubes(
        &grid,
        &sample(
            &grid,
            &Shape::Sphere {
                centre,
                radius: 0.6,
            },
        ),
        0.0,
    );
    let normals = mesh.normals.as_ref().expect("normals are computed");
    let worst = mesh
        .positions
        .iter()
        .zip(normals)
        .map(|(p, n)| {
            let q = [p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]];
            let l = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
            let cos = (q[0] * n[0] + q[1] * n[1] + q[2] * n[2]) / l;
            f64::from(cos.min(1.0)).acos().to_degrees()
        })
        .fold(0.0, f64::max);
    assert!(worst < 2.0, "worst normal deviation {worst}°");
}

#[test]
fn torus_is_closed_with_euler_characteristic_zero() {
    let grid = Grid::new(72);
    let torus = Shape::Torus {
        centre: [0.03, 0.0, -0.02],
        major: 0.55,
        minor: 0.2,
    };
    let mesh = marching_cubes(&grid, &sample(&grid, &torus), 0.0);
    assert_closed_manifold(&mesh, "torus");
    assert_eq!(mesh.euler_characteristic(), 0);
    let volume = 2.0 * PI * PI * 0.55 * 0.2 * 0.2;
    assert!((mesh.signed_volume() / volume - 1.0).abs() < 0.01);
}

#[test]
fn random_noise_with_every_ambiguous_case_stays_closed_and_oriented() {
    // Independent random corner values hit every case and every face decision; the border
    // is kept outside so the surface must close inside the grid.
    for seed in 0..6 {
        let grid = Grid::new(20);
        let r = grid.resolution;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let values: Vec<f32> = (0..grid.sample_count())
            .map(|n| {
                let (i, j, k) = (n % r, n / r % r, n / (r * r));
                let border = [i, j, k].iter().any(|&x| x == 0 || x == r - 1);
                if border {
                    1.0
                } else {
                    rng.random_range(-1.0..1.0)
                }
            })
            .collect();
        let mesh = marching_cubes(&grid, &values, 0.0);
        assert!(mesh.triangle_count() > 1000);
        assert_closed_manifold(&mesh, &format!("noise seed {seed}"));
    }
}

#[test]
fn values_exactly_at_the_iso_level_do_not_break_the_surface() {
    // Integer noise in {-1, 0, 1}: a third of the samples lie exactly on the level.
    let grid = Grid::new(18);
    let r = grid.resolution;
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let values: Vec<f32> = (0..grid.sample_count())
        .map(|n| {
            let border = [n % r, n / r % r, n / (r * r)]
                .iter()
                .any(|&x| x == 0 || x == r - 1);
            if border {
                1.0
            } else {
                rng.random_range(-1i32..=1) as f32
            }
        })
        .collect();
    let mesh = marching_cubes(&grid, &values, 0.0);
    assert_closed_manifold(&mesh, "integer noise");
    // A box whose faces pass exactly through sample planes.
    let c = (r / 2) as f32;
    let cube: Vec<f32> = (0..grid.sample_count())
        .map(|n| {
            [n % r, n / r % r, n / (r * r)]
                .map(|x| (x as f32 - c).abs())
                .into_iter()
                .fold(0.0, f32::max)
                - 4.0
        })
        .collect();
    let mesh = marching_cubes(&grid, &cube, 0.0);
    assert_closed_manifold(&mesh, "grid-aligned box");
    assert_eq!(mesh.euler_characteristic(), 2);
}

#[test]
fn gyroid_inside_a_sphere_and_nearly_touching_spheres_are_closed() {
    let grid = Grid::new(64);
    let gyroid = Shape::Intersection(vec![
        Shape::Gyroid {
            frequency: 9.0,
            half_thickness: 0.02,
        },
        Shape::Sphere {
            centre: [0.0; 3],
            radius: 0.8,
        },
    ]);
    let mesh = marching_cubes(&grid, &sample(&grid, &gyroid), 0.0);
    assert!(mesh.triangle_count() > 20_000);
    assert_closed_manifold(&mesh, "gyroid");
    // Gap of a tenth of a cell between the spheres: ambiguous faces in the neck region.
    let h = grid.spacing();
    let r = 0.4;
    let x = r + 0.05 * h;
    let pair = Shape::Union(vec![
        Shape::Sphere {
            centre: [-x, 0.013, 0.0],
            radius: r,
        },
        Shape::Sphere {
            centre: [x, 0.013, 0.0],
            radius: r,
        },
    ]);
    let mesh = marching_cubes(&grid, &sample(&grid, &pair), 0.0);
    assert_closed_manifold(&mesh, "two spheres");
}

#[test]
fn a_surface_leaving_the_grid_is_open_only_on_the_border() {
    let grid = Grid::new(24);
    let plate = Shape::Plate {
        normal: [0.0, 0.6, 0.8],
        offset: 0.05,
        half_thickness: 0.3,
    };
    let mesh = marching_cubes(&grid, &sample(&grid, &plate), 0.0);
    let report = mesh.edge_report();
    assert!(report.boundary_edges > 0);
    assert_eq!(
        report.non_manifold_edges + report.inconsistently_oriented_edges,
        0
    );
    // Every vertex of a boundary edge lies on a face of the grid box.
    let mut uses = std::collections::HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
            *uses.entry((a, b)).or_insert(0) += 1;
        }
    }
    let on_border = |v: u32| mesh.positions[v as usize].iter().any(|c| c.abs() == 1.0);
    for ((a, b), n) in uses {
        if n == 1 {
            assert!(
                on_border(a) && on_border(b),
                "open edge {a}-{b} inside the grid"
            );
        }
    }
}

#[test]
fn bad_grids_and_values_are_reported_with_their_location() {
    let grid = Grid::new(4);
    assert_eq!(
        try_marching_cubes(&grid, &[0.0; 10], 0.0).unwrap_err(),
        GridError::Length {
            resolution: 4,
            expected: 64,
            found: 10
        }
    );
    let mut values = vec![1.0f32; 64];
    values[1 + 4 * (2 + 4 * 3)] = f32::NAN;
    assert!(matches!(
        try_marching_cubes(&grid, &values, 0.0),
        Err(GridError::NonFinite {
            i: 1,
            j: 2,
            k: 3,
            ..
        })
    ));
    assert_eq!(
        try_marching_cubes(&Grid::new(1), &[0.0], 0.0).unwrap_err(),
        GridError::Resolution(1)
    );
    let flipped = Grid {
        resolution: 4,
        min: 1.0,
        max: -1.0,
    };
    assert!(matches!(
        try_marching_cubes(&flipped, &values, 0.0),
        Err(GridError::Bounds { .. })
    ));
    // A field without a crossing gives an empty mesh, not an error.
    assert_eq!(
        try_marching_cubes(&grid, &[1.0; 64], 0.0)
            .unwrap()
            .triangle_count(),
        0
    );
}
