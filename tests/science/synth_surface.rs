//! Geometry of the generated surfaces: topology, orientation, volume, measured diameters.

use std::collections::HashMap;
use std::f64::consts::TAU;

use aortagen::geometry::TriMesh;
use aortagen::synth::surface::RadiusProfile;
use aortagen::synth::{
    AorticRootParams, SurfaceResolution, build_root, build_root_with, generate_root, generate_roots,
};

use crate::synth_intersect::self_intersections;

/// Points where the mesh crosses the plane z = z0.
fn slice_z(mesh: &TriMesh, z0: f64) -> Vec<[f64; 3]> {
    let mut pts = Vec::new();
    for t in 0..mesh.triangle_count() {
        let c = mesh.corners(t);
        for k in 0..3 {
            let (a, b) = (c[k], c[(k + 1) % 3]);
            let (da, db) = (a[2] - z0, b[2] - z0);
            if da == 0.0 {
                pts.push(a);
            } else if da * db < 0.0 {
                let w = da / (da - db);
                pts.push(std::array::from_fn(|i| a[i] + w * (b[i] - a[i])));
            }
        }
    }
    pts
}

fn axial_radius(p: [f64; 3]) -> f64 {
    p[0].hypot(p[1])
}

/// Number of closed loops formed by the boundary edges.
fn boundary_loops(mesh: &TriMesh) -> usize {
    let mut directed = HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            directed.insert((t[k], t[(k + 1) % 3]), ());
        }
    }
    let mut next: HashMap<u32, u32> = directed
        .keys()
        .filter(|(a, b)| !directed.contains_key(&(*b, *a)))
        .map(|&(a, b)| (a, b))
        .collect();
    let mut loops = 0;
    while let Some(&start) = next.keys().next() {
        let mut v = start;
        while let Some(w) = next.remove(&v) {
            v = w;
        }
        assert_eq!(v, start, "boundary edges do not close into a loop");
        loops += 1;
    }
    loops
}

/// ∫ A(s) ds with A(s) = ½∫ r(s, θ)² dθ: the exact volume of the swept solid, because the
/// cross-sections are planar and, on the curved part, circles centred on the centreline.
fn swept_volume(p: &AorticRootParams) -> f64 {
    let profile = RadiusProfile::new(p);
    let (a, b) = (-p.lvot_length_mm, p.sinus_height_mm + p.ascending_length_mm);
    let (ns, nt) = (3000, 720);
    let area = |s: f64| {
        (0..nt)
            .map(|j| profile.radius(s, TAU * j as f64 / nt as f64).powi(2))
            .sum::<f64>()
            * 0.5
            * TAU
            / nt as f64
    };
    let h = (b - a) / ns as f64;
    (0..ns).map(|i| area(a + (i as f64 + 0.5) * h)).sum::<f64>() * h
}

#[test]
fn closed_roots_are_watertight_outward_genus_zero_with_the_swept_volume() {
    for i in 0..3 {
        let (p, mesh) = generate_root(21, i, true);
        mesh.validate().unwrap();
        let report = mesh.edge_report();
        assert!(report.is_closed_and_oriented(), "shape {i}: {report:?}");
        assert_eq!(mesh.euler_characteristic(), 2);
        assert!(mesh.triangle_count() >= 20_000);
        let (v, exact) = (mesh.signed_volume(), swept_volume(&p));
        assert!(v > 0.0);
        assert!(
            (v - exact).abs() < 0.005 * exact,
            "shape {i}: mesh {v} vs swept {exact}"
        );
    }
}

#[test]
fn open_roots_have_exactly_two_boundary_loops() {
    let (_, mesh) = generate_root(21, 0, false);
    let report = mesh.edge_report();
    assert_eq!(
        report.boundary_edges,
        2 * SurfaceResolution::default().segments
    );
    assert_eq!(
        report.non_manifold_edges + report.inconsistently_oriented_edges,
        0
    );
    assert_eq!(boundary_loops(&mesh), 2);
    assert!(mesh.triangle_count() >= 20_000);
}

#[test]
fn same_seed_builds_identical_meshes_and_different_seeds_do_not() {
    let a = generate_roots(2, 9, true);
    let b = generate_roots(2, 9, true);
    assert_eq!(a, b);
    let c = generate_roots(2, 10, true);
    assert_ne!(a[0].1.positions, c[0].1.positions);
}

#[test]
fn no_two_non_adjacent_triangles_intersect() {
    for i in 0..3 {
        let (_, closed) = generate_root(33, i, true);
        assert_eq!(self_intersections(&closed, 5), vec![], "shape {i}");
    }
}

#[test]
fn measured_diameters_match_the_parameters() {
    for i in 0..4 {
        let (p, mesh) = generate_root(44, i, true);
        let annulus = slice_z(&mesh, 0.0);
        let extent = |k: usize| {
            annulus
                .iter()
                .map(|q| q[k])
                .fold(f64::NEG_INFINITY, f64::max)
                - annulus.iter().map(|q| q[k]).fold(f64::INFINITY, f64::min)
        };
        let (major, minor) = p.annulus_axes_mm();
        assert!(
            (extent(0) - major).abs() < 0.2,
            "shape {i}: major {} vs {major}",
            extent(0)
        );
        assert!(
            (extent(1) - minor).abs() < 0.2,
            "shape {i}: minor {} vs {minor}",
            extent(1)
        );
        assert!((0.5 * (extent(0) + extent(1)) - p.annulus_diameter_mm).abs() < 0.2);

        let stj = slice_z(&mesh, p.sinus_height_mm);
        assert!(!stj.is_empty());
        for q in &stj {
            assert!(
                (2.0 * axial_radius(*q) - p.stj_diameter_mm).abs() < 0.2,
                "shape {i}: STJ point {q:?}"
            );
        }

        let sinus = slice_z(&mesh, 0.5 * p.sinus_height_mm);
        let widest = sinus.iter().map(|q| axial_radius(*q)).fold(0.0, f64::max);
        assert!(
            (2.0 * widest - p.sinus_diameter_mm).abs() < 0.2,
            "shape {i}: sinus {}",
            2.0 * widest
        );
        assert_eq!(count_lobes(&sinus), 3, "shape {i}");

        let end = mesh.positions.len() - 1; // centre of the distal cap
        let rim = &mesh.positions[end - 1 - 128..end - 1];
        let c = mesh.positions[end].map(f64::from);
        for q in rim {
            let r = (0..3)
                .map(|k| (f64::from(q[k]) - c[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(
                (2.0 * r - p.ascending_diameter_mm).abs() < 0.2,
                "shape {i}: ascending {}",
                2.0 * r
            );
        }
    }
}

/// Local maxima of radius versus angle around the axis, in 72 angular bins.
fn count_lobes(points: &[[f64; 3]]) -> usize {
    let bins = 72;
    let mut r = vec![0.0f64; bins];
    for q in points {
        let b = ((q[1].atan2(q[0]).rem_euclid(TAU) / TAU * bins as f64) as usize).min(bins - 1);
        r[b] = r[b].max(axial_radius(*q));
    }
    (0..bins)
        .filter(|&b| r[b] > r[(b + bins - 1) % bins] && r[b] >= r[(b + 1) % bins])
        .count()
}

#[test]
fn coarser_resolutions_keep_the_topology_and_bad_ones_are_refused() {
    let (p, _) = generate_root(1, 1, true);
    let coarse = build_root_with(
        &p,
        true,
        SurfaceResolution {
            rings: 40,
            segments: 24,
        },
    )
    .unwrap();
    assert_eq!(coarse.triangle_count(), 2 * 24 * 39 + 2 * 24);
    assert!(coarse.edge_report().is_closed_and_oriented());
    let err = build_root_with(
        &p,
        true,
        SurfaceResolution {
            rings: 3,
            segments: 24,
        },
    )
    .unwrap_err();
    assert!(err.to_string().contains("rings"), "{err}");
    assert_eq!(build_root(&p, false).unwrap(), generate_root(1, 1, false).1);
}
