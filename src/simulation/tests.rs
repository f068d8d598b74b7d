//! End-to-end checks of openings, cutting and capping against analytic truth: a straight
//! tube, a branched arch (marching cubes of a known signed-distance field) and the
//! parametric aortic roots.

use super::remesh::expected_triangles;
use super::request::failure_field;
use super::test_shapes::{BranchedArch, straight_tube};
use super::*;
use crate::anatomy::sections::PlaneFrame;
use crate::geometry::TriMesh;
use crate::geometry::mesh::{dot, norm, normalized, sub};

/// Largest distance of a cap's vertices from its opening's plane, mm.
fn cap_flatness(m: &LabelledMesh, opening: &Opening) -> f64 {
    let frame = PlaneFrame::new(opening.origin, opening.normal);
    let cap = m.submesh(opening.id);
    cap.positions
        .iter()
        .map(|p| frame.height(p.map(f64::from)).abs())
        .fold(0.0, f64::max)
}

fn size(mesh: &TriMesh) -> f64 {
    let b = mesh.bounding_box().unwrap();
    norm(sub(b.max, b.min))
}

/// The shared checks: planar caps, a watertight capped mesh of Euler characteristic 2 and
/// one boundary loop per opening in the open one.
fn check_topology(sim: &SimulationMesh, input: &TriMesh) {
    for o in &sim.openings {
        let flat = cap_flatness(&sim.capped, o);
        assert!(
            flat <= 1e-6 * size(input),
            "{}: {flat} mm off its plane",
            o.name
        );
    }
    let q = &sim.quality.manifold;
    assert!(q.watertight, "{q:?}");
    assert_eq!(q.euler_characteristic, 2);
    let open = quality_report(&sim.open().mesh);
    assert_eq!(open.manifold.boundary_loops, sim.openings.len());
    assert_eq!(sim.quality.self_intersections, 0);
}

fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    dot(normalized(a), normalized(b))
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

#[test]
fn a_tilted_tube_gets_two_perpendicular_round_caps() {
    let axis = normalized([0.3, -0.2, 1.0]);
    let start = [5.0, -3.0, 2.0];
    let mesh = straight_tube(10.0, 100.0, start, axis, 100, 72);
    let opts = SimulationOptions {
        kind: Some(ShapeKind::Tube),
        ..Default::default()
    };
    let sim = simulation_mesh(&mesh, &opts).unwrap();
    check_topology(&sim, &mesh);
    let faces = &sim.faces;
    assert_eq!(
        faces.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(),
        ["wall", "inlet", "outlet"]
    );
    // The 72-gon's area-equivalent diameter.
    let polygon =
        20.0 * ((72.0 / std::f64::consts::TAU) * (std::f64::consts::TAU / 72.0).sin()).sqrt();
    for (face, opening) in faces[1..].iter().zip(&sim.openings) {
        assert!(angle_deg(face.normal, axis).min(angle_deg(face.normal, axis.map(|c| -c))) < 1.0);
        assert!(
            (face.equivalent_diameter_mm / polygon - 1.0).abs() < 0.02,
            "{face:?}"
        );
        let along = dot(sub(face.centroid_mm, start), axis);
        let trim = opts.openings.end_trim_mm;
        assert!(
            (along - trim).abs() < 0.5 || (along - (100.0 - trim)).abs() < 0.5,
            "{along}"
        );
        assert!(dot(face.normal, opening.normal) > 0.9999);
    }
}

#[test]
fn a_branched_arch_gets_its_inlet_descending_outlet_and_ordered_branches() {
    let mesh = BranchedArch::mesh();
    let sim = simulation_mesh(&mesh, &SimulationOptions::default()).unwrap();
    assert_eq!(sim.kind, ShapeKind::Aorta);
    check_topology(&sim, &mesh);
    let names: Vec<&str> = sim.faces.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "wall",
            "inlet",
            "outlet_descending",
            "branch_1",
            "branch_2",
            "branch_3"
        ]
    );
    let ids: Vec<u32> = sim.faces.iter().map(|f| f.id).collect();
    assert_eq!(ids, [0, 1, 2, 3, 4, 5]);
    let r = BranchedArch::RADIUS;
    let opts = OpeningOptions::default();
    // Inlet on the ascending leg (x = −30, rounded end at z = −29), facing down.
    let inlet = &sim.faces[1];
    assert!(angle_deg(inlet.normal, [0.0, 0.0, -1.0]) < 1.0, "{inlet:?}");
    assert!(
        (inlet.centroid_mm[2] - (-20.0 - r + opts.end_trim_mm)).abs() < 0.5,
        "{inlet:?}"
    );
    assert!((inlet.centroid_mm[0] + BranchedArch::ARCH).abs() < 0.3);
    let outlet = &sim.faces[2];
    assert!(
        angle_deg(outlet.normal, [0.0, 0.0, -1.0]) < 1.0,
        "{outlet:?}"
    );
    assert!((outlet.centroid_mm[0] - BranchedArch::ARCH).abs() < 0.3);
    for face in &sim.faces[1..3] {
        assert!(
            (face.equivalent_diameter_mm / (2.0 * r) - 1.0).abs() < 0.02,
            "{face:?}"
        );
    }
    for k in 0..3 {
        let face = &sim.faces[3 + k];
        let (base, dir) = BranchedArch::branch(k);
        assert!(angle_deg(face.normal, dir) < 1.0, "{face:?}");
        // The centre lies on the branch axis, trimmed from the rounded tip.
        let along = dot(sub(face.centroid_mm, base), dir);
        let off_axis = norm(sub(sub(face.centroid_mm, base), dir.map(|c| c * along)));
        assert!(off_axis < 0.3, "{face:?}");
        let tip = 25.0 + BranchedArch::BRANCH_RADIUS;
        assert!((along - (tip - opts.branch_trim_mm)).abs() < 0.5, "{along}");
        let d = 2.0 * BranchedArch::BRANCH_RADIUS;
        assert!(
            (face.equivalent_diameter_mm / d - 1.0).abs() < 0.02,
            "{face:?}"
        );
    }
}

/// The exact section area of a parametric root at arc length `s` (polar integral).
fn root_section_area(p: &crate::synth::AorticRootParams, s: f64) -> f64 {
    let profile = crate::synth::surface::RadiusProfile::new(p);
    let n = 4096;
    (0..n)
        .map(|k| {
            let theta = std::f64::consts::TAU * (k as f64 + 0.5) / n as f64;
            0.5 * profile.radius(s, theta).powi(2)
        })
        .sum::<f64>()
        * std::f64::consts::TAU
        / n as f64
}

#[test]
fn parametric_roots_open_at_the_annulus_and_above_the_junction_with_the_same_labels() {
    let opts = SimulationOptions::default();
    let mut tables = Vec::new();
    for seed in [3u64, 11, 2024] {
        let (params, mesh) = crate::synth::generate_root(seed, 0, true);
        let sim = simulation_mesh(&mesh, &opts).unwrap();
        assert_eq!(sim.kind, ShapeKind::Root);
        check_topology(&sim, &mesh);
        let line = crate::synth::centreline::Centreline::new(&params);
        let truth = [
            0.0 - opts.openings.inlet_below_annulus_mm,
            params.sinus_height_mm + opts.openings.outlet_above_stj_mm,
        ];
        for (face, (&s, sign)) in sim.faces[1..].iter().zip(truth.iter().zip([-1.0, 1.0])) {
            let frame = line.frame(s);
            let tangent = frame.t.map(|c| sign * c);
            assert!(
                angle_deg(face.normal, tangent) < 1.0,
                "seed {seed}: {face:?}"
            );
            // Measured landmarks are within a fraction of a millimetre of the truth.
            assert!(
                norm(sub(face.centroid_mm, frame.origin)) < 0.6,
                "seed {seed}: {face:?}"
            );
            let d = (4.0 * root_section_area(&params, s) / std::f64::consts::PI).sqrt();
            assert!(
                (face.equivalent_diameter_mm / d - 1.0).abs() < 0.02,
                "seed {seed}: {face:?} vs {d}"
            );
        }
        tables.push(
            sim.faces
                .iter()
                .map(|f| (f.id, f.name.clone()))
                .collect::<Vec<_>>(),
        );
    }
    assert!(tables.windows(2).all(|w| w[0] == w[1]), "{tables:?}");
    assert_eq!(
        tables[0],
        [
            (0, "wall".into()),
            (1, "inlet".into()),
            (2, "outlet".into())
        ]
    );
}

#[test]
fn openings_that_cannot_be_placed_say_why() {
    let (_, mesh) = crate::synth::generate_root(3, 0, true);
    let far = SimulationOptions {
        openings: OpeningOptions {
            inlet_below_annulus_mm: 30.0,
            ..Default::default()
        },
        ..Default::default()
    };
    let err = simulation_mesh(&mesh, &far).unwrap_err();
    assert!(
        matches!(&err, SimulationError::OutsideVessel { opening, .. } if opening == "inlet"),
        "{err}"
    );
    let bad = SimulationOptions {
        openings: OpeningOptions {
            end_trim_mm: f64::NAN,
            ..Default::default()
        },
        ..Default::default()
    };
    let err = simulation_mesh(&mesh, &bad).unwrap_err();
    assert!(
        matches!(
            err,
            SimulationError::BadOption {
                field: "end_trim_mm",
                ..
            }
        ),
        "{err}"
    );
    // A sphere has no ends to open.
    let sphere = crate::geometry::test_shapes::uv_sphere(10.0, [0.0; 3], 24, 32);
    let tube = SimulationOptions {
        kind: Some(ShapeKind::Tube),
        ..Default::default()
    };
    assert!(simulation_mesh(&sphere, &tube).is_err());
}

#[test]
fn flow_extensions_move_the_caps_two_diameters_out_and_stay_watertight() {
    let axis = [0.0, 0.0, 1.0];
    let mesh = straight_tube(10.0, 100.0, [0.0; 3], axis, 100, 72);
    let opts = SimulationOptions {
        kind: Some(ShapeKind::Tube),
        extension_diameters: 2.0,
        ..Default::default()
    };
    let plain = simulation_mesh(
        &mesh,
        &SimulationOptions {
            extension_diameters: 0.0,
            ..opts.clone()
        },
    )
    .unwrap();
    let sim = simulation_mesh(&mesh, &opts).unwrap();
    let q = &sim.quality.manifold;
    assert!(q.watertight && q.euler_characteristic == 2, "{q:?}");
    assert_eq!(sim.quality.self_intersections, 0);
    assert_eq!(quality_report(&sim.open().mesh).manifold.boundary_loops, 2);
    let names: Vec<&str> = sim.faces.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "wall",
            "inlet",
            "outlet",
            "inlet_extension",
            "outlet_extension"
        ]
    );
    for (cap, before) in sim.faces[1..3].iter().zip(&plain.faces[1..3]) {
        let d = before.equivalent_diameter_mm;
        let moved = dot(sub(cap.centroid_mm, before.centroid_mm), before.normal);
        assert!((moved - 2.0 * d).abs() < 1e-3 * d, "{moved} vs {d}");
        assert!(
            (cap.equivalent_diameter_mm / d - 1.0).abs() < 0.01,
            "{cap:?}"
        );
        assert!(dot(cap.normal, before.normal) > 0.99999);
        // The far cap lies in its plane.
        let frame = PlaneFrame::new(cap.centroid_mm, cap.normal);
        let flat = sim
            .capped
            .submesh(cap.id)
            .positions
            .iter()
            .map(|p| frame.height(p.map(f64::from)).abs())
            .fold(0.0, f64::max);
        assert!(flat < 1e-6 * 150.0, "{flat}");
    }
}

#[test]
fn remeshing_a_tube_keeps_it_on_the_cylinder_with_flat_caps_and_good_angles() {
    let axis = [0.0, 0.0, 1.0];
    let mesh = straight_tube(10.0, 100.0, [0.0; 3], axis, 100, 72);
    let opts = SimulationOptions {
        kind: Some(ShapeKind::Tube),
        remesh_mm: Some(1.0),
        ..Default::default()
    };
    let sim = simulation_mesh(&mesh, &opts).unwrap();
    check_topology(&sim, &mesh);
    let report = sim.remesh.as_ref().unwrap();
    assert!(
        sim.quality.share_min_angle_20 >= 0.99,
        "{:?}",
        sim.quality.min_angle_deg
    );
    assert!((report.median_edge_mm - 1.0).abs() < 0.2, "{report:?}");
    // Every wall point lies within the reported distance of the exact cylinder (the input
    // polygon's own chord error, 10·(1 − cos(π/72)) mm, included).
    let chord = 10.0 * (1.0 - (std::f64::consts::PI / 72.0).cos());
    assert!(report.max_distance_mm < chord + 0.05, "{report:?}");
    let wall = sim.capped.submesh(WALL_ID);
    for t in 0..wall.triangle_count() {
        let c = wall.corners(t);
        let centroid: [f64; 3] = std::array::from_fn(|i| (c[0][i] + c[1][i] + c[2][i]) / 3.0);
        let off = (centroid[0].hypot(centroid[1]) - 10.0).abs();
        assert!(off <= report.max_distance_mm + chord + 1e-6, "{off}");
    }
    for (face, opening) in sim.faces[1..].iter().zip(&sim.openings) {
        assert!(dot(face.normal, opening.normal) > 0.99985, "{face:?}");
        let polygon =
            20.0 * ((72.0 / std::f64::consts::TAU) * (std::f64::consts::TAU / 72.0).sin()).sqrt();
        assert!(
            (face.equivalent_diameter_mm / polygon - 1.0).abs() < 0.02,
            "{face:?}"
        );
    }
}

#[test]
fn remeshing_the_branched_arch_keeps_its_labels_and_raises_its_angles() {
    let mesh = BranchedArch::mesh();
    let plain = simulation_mesh(&mesh, &SimulationOptions::default()).unwrap();
    let opts = SimulationOptions {
        remesh_mm: Some(1.0),
        ..Default::default()
    };
    let sim = simulation_mesh(&mesh, &opts).unwrap();
    check_topology(&sim, &mesh);
    assert!(plain.quality.share_min_angle_20 < 0.9);
    assert!(
        sim.quality.share_min_angle_20 >= 0.99,
        "{:?}",
        sim.quality.min_angle_deg
    );
    let report = sim.remesh.as_ref().unwrap();
    assert!(report.max_distance_mm < 0.25, "{report:?}");
    for (a, b) in plain.faces.iter().zip(&sim.faces) {
        assert_eq!((a.id, &a.name), (b.id, &b.name));
        if a.id != WALL_ID {
            assert!(
                dot(a.normal, b.normal) > 0.99985 && norm(sub(a.centroid_mm, b.centroid_mm)) < 0.2,
                "{a:?} {b:?}"
            );
            assert!((a.area_mm2 / b.area_mm2 - 1.0).abs() < 0.02, "{a:?} {b:?}");
        }
    }
}

#[test]
fn a_remesh_size_out_of_range_names_the_field() {
    let mesh = straight_tube(10.0, 100.0, [0.0; 3], [0.0, 0.0, 1.0], 20, 24);
    let opts = SimulationOptions {
        remesh_mm: Some(0.0),
        ..Default::default()
    };
    let err = simulation_mesh(&mesh, &opts).unwrap_err();
    assert!(
        matches!(
            err,
            SimulationError::BadOption {
                field: "remesh_mm",
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn the_same_input_gives_the_same_remeshed_mesh() {
    let (_, mesh) = crate::synth::generate_root(7, 2, true);
    let opts = SimulationOptions {
        remesh_mm: Some(1.5),
        ..Default::default()
    };
    let (a, b) = (
        simulation_mesh(&mesh, &opts).unwrap(),
        simulation_mesh(&mesh, &opts).unwrap(),
    );
    assert_eq!(a.capped, b.capped);
    assert_eq!(a.faces, b.faces);
}

#[test]
fn a_remesh_makes_about_the_expected_number_of_triangles() {
    let mesh = straight_tube(10.0, 100.0, [0.0; 3], [0.0, 0.0, 1.0], 100, 72);
    let tube = SimulationOptions {
        kind: Some(ShapeKind::Tube),
        ..Default::default()
    };
    let capped = simulation_mesh(&mesh, &tube).unwrap().capped.mesh.area();
    for mm in [1.0, 2.0] {
        let opts = SimulationOptions {
            remesh_mm: Some(mm),
            ..tube.clone()
        };
        let made = simulation_mesh(&mesh, &opts).unwrap();
        let made = made.remesh.unwrap().triangles_after as f64;
        let expected = expected_triangles(capped, mm) as f64;
        assert!(
            (made / expected - 1.0).abs() < 0.2,
            "{mm} mm: {made} vs {expected}"
        );
    }
}

#[test]
fn a_remesh_over_the_budget_stops_before_it_starts_and_names_the_finest_edge() {
    let mesh = straight_tube(10.0, 100.0, [0.0; 3], [0.0, 0.0, 1.0], 100, 72);
    let opts = SimulationOptions {
        kind: Some(ShapeKind::Tube),
        remesh_mm: Some(0.5),
        ..Default::default()
    };
    let mut steps = Vec::new();
    let err =
        simulation_mesh_observed(&mesh, &opts, Some(5_000), &mut |s| steps.push(s)).unwrap_err();
    assert_eq!(failure_field(opts.kind, &err), "remesh_mm");
    let SimulationError::OverBudget {
        triangles,
        max_triangles,
        area_mm2,
        finest_mm,
    } = err
    else {
        panic!("{err}");
    };
    assert!(!steps.contains(&Step::Remesh), "{steps:?}");
    assert_eq!(max_triangles, 5_000);
    assert_eq!(triangles, expected_triangles(area_mm2, 0.5));
    assert!(expected_triangles(area_mm2, finest_mm) <= 5_000);
    assert!(expected_triangles(area_mm2, finest_mm - 0.01) > 5_000);

    // At the edge it names, the same budget admits the remesh.
    let within = SimulationOptions {
        remesh_mm: Some(finest_mm),
        ..opts.clone()
    };
    let sim = simulation_mesh_observed(&mesh, &within, Some(5_000), &mut |_| {}).unwrap();
    assert!(sim.remesh.is_some());

    // Flow extensions are counted: at an edge within the budget for the closed tube, the
    // capped tube with two 10-diameter extensions is over it.
    let closed_finest = super::remesh::finest_target_mm(mesh.area(), 5_000);
    let extended = SimulationOptions {
        extension_diameters: 10.0,
        remesh_mm: Some(closed_finest),
        ..opts
    };
    let err = simulation_mesh_observed(&mesh, &extended, Some(5_000), &mut |_| {}).unwrap_err();
    assert!(matches!(err, SimulationError::OverBudget { .. }), "{err}");
}
