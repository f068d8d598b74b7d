//! The sparse coarse-to-fine extraction against the dense reference on analytic fields.

use aortagen::extract::analytic::Shape;
use aortagen::extract::{
    ExtractError, ExtractOptions, Parallelism, ScalarField, extract_dense, extract_surface,
    remove_small_components,
};
use aortagen::geometry::TriMesh;

fn assert_same_surface(sparse: &TriMesh, dense: &TriMesh, what: &str) {
    assert_eq!(
        sparse.triangle_count(),
        dense.triangle_count(),
        "{what}: triangle count"
    );
    assert_eq!(
        sparse.vertex_count(),
        dense.vertex_count(),
        "{what}: vertex count"
    );
    let worst = sparse.max_surface_difference(dense).unwrap();
    assert!(worst <= 1e-5, "{what}: vertices differ by {worst}");
}

fn scenes() -> Vec<(&'static str, Shape)> {
    vec![
        (
            "sphere",
            Shape::Sphere {
                centre: [0.02, -0.03, 0.01],
                radius: 0.55,
            },
        ),
        (
            "torus",
            Shape::Torus {
                centre: [0.0, 0.05, 0.0],
                major: 0.5,
                minor: 0.18,
            },
        ),
        (
            // Thinner than one finest block (and far thinner than the coarse ones).
            "thin plate",
            Shape::Intersection(vec![
                Shape::Plate {
                    normal: [0.0, 0.6, 0.8],
                    offset: 0.03,
                    half_thickness: 0.045,
                },
                Shape::Sphere {
                    centre: [0.0; 3],
                    radius: 0.7,
                },
            ]),
        ),
        (
            "small spheres",
            Shape::Union(
                (0..6)
                    .map(|n| {
                        let a = n as f32 * 1.047;
                        Shape::Sphere {
                            centre: [0.5 * a.cos(), 0.5 * a.sin(), 0.1 * n as f32 - 0.25],
                            radius: 0.13,
                        }
                    })
                    .collect(),
            ),
        ),
    ]
}

#[test]
fn sparse_extraction_equals_the_dense_path_on_analytic_fields() {
    let options = ExtractOptions::default();
    for resolution in [33, 64, 65] {
        for (name, shape) in scenes() {
            let what = format!("{name} at R = {resolution}");
            let sparse = extract_surface(&shape, resolution, &options).unwrap();
            let dense = extract_dense(&shape, resolution, &options).unwrap();
            assert!(sparse.mesh.triangle_count() > 100, "{what}: surface found");
            assert_same_surface(&sparse.mesh, &dense.mesh, &what);
            assert!(sparse.mesh.edge_report().is_closed_and_oriented(), "{what}");
            assert!(
                sparse.evaluations.samples < dense.evaluations.samples,
                "{what}: fewer samples"
            );
        }
    }
}

#[test]
fn odd_block_sizes_and_batches_give_the_same_surface() {
    let shape = &scenes()[1].1;
    let dense = extract_dense(shape, 37, &ExtractOptions::default()).unwrap();
    for (block_cells, batch_size, parallelism) in [
        (5, 1000, Parallelism::AcrossBatches),
        (3, 77, Parallelism::InsideField),
        (16, 1 << 16, Parallelism::AcrossBatches),
    ] {
        let options = ExtractOptions {
            block_cells,
            batch_size,
            parallelism,
            ..Default::default()
        };
        let sparse = extract_surface(shape, 37, &options).unwrap();
        assert_same_surface(
            &sparse.mesh,
            &dense.mesh,
            &format!("block {block_cells}, batch {batch_size}"),
        );
    }
}

/// Records every point evaluated without gradients.
struct Recording {
    shape: Shape,
    points: std::sync::Mutex<Vec<[f32; 3]>>,
}

impl ScalarField for Recording {
    fn eval_batch(&self, points: &[[f32; 3]], values: &mut [f32], g: Option<&mut [[f32; 3]]>) {
        if g.is_none() {
            self.points.lock().unwrap().extend_from_slice(points);
        }
        self.shape.eval_batch(points, values, g);
    }
    fn lipschitz_bound(&self) -> f32 {
        1.0
    }
}

/// Finer finest blocks mean fewer evaluations, never a different mesh, and no point is
/// evaluated twice (block centres are reused as grid samples).
#[test]
fn the_block_hierarchy_evaluates_each_point_once_and_less_with_finer_blocks() {
    for (name, shape) in scenes() {
        let dense = extract_dense(&shape, 97, &ExtractOptions::default()).unwrap();
        let mut previous = u64::MAX;
        for block_cells in [16, 8, 4, 2] {
            let field = Recording {
                shape: shape.clone(),
                points: Default::default(),
            };
            let options = ExtractOptions {
                block_cells,
                ..Default::default()
            };
            let sparse = extract_surface(&field, 97, &options).unwrap();
            let what = format!("{name}, block {block_cells}");
            assert_same_surface(&sparse.mesh, &dense.mesh, &what);
            let mut points = field.points.into_inner().unwrap();
            let e = sparse.evaluations;
            assert_eq!(points.len() as u64, e.block_centres + e.samples, "{what}");
            points.sort_unstable_by_key(|p| p.map(f32::to_bits));
            let evaluated = points.len();
            points.dedup();
            assert_eq!(
                points.len(),
                evaluated,
                "{what}: a point was evaluated twice"
            );
            let cost = e.block_centres + e.samples;
            assert!(cost < previous, "{what}: {cost} evaluations vs {previous}");
            previous = cost;
        }
    }
}

#[test]
fn sparse_sampling_of_a_sphere_costs_a_fraction_of_the_dense_grid() {
    let sphere = Shape::Sphere {
        centre: [0.0; 3],
        radius: 0.5,
    };
    let out = extract_surface(&sphere, 129, &ExtractOptions::default()).unwrap();
    let dense = 129u64.pow(3);
    assert!(out.evaluations.samples * 4 < dense, "{:?}", out.evaluations);
    assert!(out.evaluations.total() * 3 < dense, "{:?}", out.evaluations);
    assert_eq!(out.evaluations.normals, out.mesh.vertex_count() as u64);
    assert!(out.kept_blocks > 0);
}

#[test]
fn vertex_normals_come_from_the_field_gradient() {
    let centre = [0.05, 0.0, -0.1];
    let sphere = Shape::Sphere {
        centre,
        radius: 0.6,
    };
    let out = extract_surface(&sphere, 40, &ExtractOptions::default()).unwrap();
    let normals = out.mesh.normals.as_ref().unwrap();
    for (p, n) in out.mesh.positions.iter().zip(normals) {
        let q: [f32; 3] = std::array::from_fn(|k| p[k] - centre[k]);
        let l = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
        let cos = (q[0] * n[0] + q[1] * n[1] + q[2] * n[2]) / l;
        assert!(cos > 1.0 - 1e-5, "normal {n:?} at {p:?}");
    }
}

/// A sphere that reports values only, like a field without a gradient pass.
struct ValuesOnly(Shape);

impl ScalarField for ValuesOnly {
    fn eval_batch(&self, points: &[[f32; 3]], values: &mut [f32], _: Option<&mut [[f32; 3]]>) {
        self.0.eval_batch(points, values, None);
    }
    fn lipschitz_bound(&self) -> f32 {
        1.0
    }
}

#[test]
fn a_field_without_gradients_gets_outward_face_normals() {
    let field = ValuesOnly(Shape::Sphere {
        centre: [0.0; 3],
        radius: 0.5,
    });
    let out = extract_surface(&field, 40, &ExtractOptions::default()).unwrap();
    let normals = out.mesh.normals.as_ref().unwrap();
    for (p, n) in out.mesh.positions.iter().zip(normals) {
        let cos = (p[0] * n[0] + p[1] * n[1] + p[2] * n[2]) / 0.5;
        assert!(cos > 0.98, "normal {n:?} at {p:?}");
    }
}

#[test]
fn floaters_below_the_threshold_are_removed_and_the_rest_stays_closed() {
    let scene = Shape::Union(vec![
        Shape::Sphere {
            centre: [-0.2, 0.0, 0.0],
            radius: 0.5,
        },
        Shape::Sphere {
            centre: [0.7, 0.6, 0.6],
            radius: 0.04,
        },
        // A floater of 4 % of the main surface, the size of a network's spurious blob.
        Shape::Sphere {
            centre: [0.6, -0.6, -0.6],
            radius: 0.1,
        },
    ]);
    let keep_all = ExtractOptions {
        min_component_fraction: 0.0,
        ..Default::default()
    };
    let all = extract_surface(&scene, 64, &keep_all).unwrap();
    assert_eq!(all.removed_components, 0);
    assert_eq!(all.mesh.euler_characteristic(), 6, "three spheres");
    let cleaned = extract_surface(&scene, 64, &ExtractOptions::default()).unwrap();
    assert_eq!(cleaned.removed_components, 2);
    assert_eq!(cleaned.mesh.euler_characteristic(), 2);
    assert!(cleaned.mesh.edge_report().is_closed_and_oriented());
    assert!(
        cleaned.mesh.positions.iter().all(|p| p[0] < 0.4),
        "the speck and the floater are gone"
    );
    assert_eq!(
        cleaned.mesh.normals.as_ref().unwrap().len(),
        cleaned.mesh.vertex_count()
    );
}

#[test]
fn component_removal_keeps_components_at_the_threshold() {
    // Two disjoint triangles of one triangle each and a pair sharing an edge.
    let mesh = TriMesh::new(
        vec![
            [0.0; 3],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
            [5.0, 0.0, 0.0],
            [6.0, 0.0, 0.0],
            [5.0, 1.0, 0.0],
        ],
        vec![[0, 1, 2], [1, 3, 2], [4, 5, 6]],
    );
    assert_eq!(
        remove_small_components(mesh.clone(), 0.5).1,
        0,
        "1 triangle ≥ 0.5 × 2"
    );
    let (kept, removed) = remove_small_components(mesh, 0.6);
    assert_eq!(removed, 1);
    assert_eq!(kept.triangles, vec![[0, 1, 2], [1, 3, 2]]);
    assert_eq!(kept.vertex_count(), 4);
}

/// Returns NaN in one octant.
struct Broken;

impl ScalarField for Broken {
    fn eval_batch(&self, points: &[[f32; 3]], values: &mut [f32], _: Option<&mut [[f32; 3]]>) {
        for (p, v) in points.iter().zip(values) {
            *v = if p.iter().all(|&c| c > 0.5) {
                f32::NAN
            } else {
                p[0]
            };
        }
    }
    fn lipschitz_bound(&self) -> f32 {
        1.0
    }
}

#[test]
fn bad_fields_and_options_are_named_in_the_error() {
    let sphere = Shape::Sphere {
        centre: [0.0; 3],
        radius: 0.5,
    };
    let err = extract_surface(&Broken, 16, &ExtractOptions::default()).unwrap_err();
    match err {
        ExtractError::NonFinite { point, value } => {
            assert!(
                value.is_nan() && point.iter().all(|&c| c > 0.5),
                "{point:?}"
            )
        }
        other => panic!("unexpected {other}"),
    }
    let bad = ExtractOptions {
        block_cells: 1,
        ..Default::default()
    };
    assert!(
        extract_surface(&sphere, 16, &bad)
            .unwrap_err()
            .to_string()
            .contains("block_cells")
    );
    let bad = ExtractOptions {
        min: 1.0,
        max: 1.0,
        ..Default::default()
    };
    assert!(matches!(
        extract_surface(&sphere, 16, &bad),
        Err(ExtractError::Grid(_))
    ));
    assert!(matches!(
        extract_surface(&sphere, 1, &ExtractOptions::default()),
        Err(ExtractError::Grid(_))
    ));
    struct Steep;
    impl ScalarField for Steep {
        fn eval_batch(&self, _: &[[f32; 3]], _: &mut [f32], _: Option<&mut [[f32; 3]]>) {}
        fn lipschitz_bound(&self) -> f32 {
            f32::INFINITY
        }
    }
    assert_eq!(
        extract_surface(&Steep, 16, &ExtractOptions::default()).unwrap_err(),
        ExtractError::Lipschitz(f32::INFINITY)
    );
}

#[test]
fn a_field_without_a_surface_in_the_box_gives_an_empty_mesh() {
    let far = Shape::Sphere {
        centre: [3.0, 0.0, 0.0],
        radius: 0.5,
    };
    let out = extract_surface(&far, 40, &ExtractOptions::default()).unwrap();
    assert_eq!((out.mesh.vertex_count(), out.mesh.triangle_count()), (0, 0));
    assert_eq!(out.kept_blocks, 0);
    assert_eq!(
        out.evaluations.samples, 0,
        "nothing sampled beyond the coarse centres"
    );
}
