//! Centrelines and root landmarks of branched vessels, against the analytic arch of the
//! simulation tests: the main vessel's centreline never turns into a branch, however long,
//! and a widening that is not a sinus of Valsalva is not taken for one.

use super::*;
use crate::geometry::mesh::{norm, sub};
use crate::simulation::test_shapes::{BranchedArch, mesh_of};

/// Where the arch's ascending and descending legs end (the centres of their rounded ends).
const ASCENDING_END: [f64; 3] = [-BranchedArch::ARCH, 0.0, -20.0];

#[test]
fn a_long_branch_does_not_take_the_centreline_out_of_the_aorta() {
    let mesh = BranchedArch::long_branches_mesh();
    let surface = Surface::new(&mesh).unwrap();
    // The shape does what it is for: the farthest-pair first guess runs into a branch.
    let farthest = geodesic::level_set_centres(&surface, 2.0).unwrap();
    let off_axis = farthest
        .points()
        .iter()
        .map(|&p| BranchedArch::main_axis_distance(p, BranchedArch::LONG_BRANCHES_DESCENDING))
        .fold(0.0, f64::max);
    assert!(off_axis > 20.0, "{off_axis}");

    let measured = measure_vessel(&mesh, &MeasureOptions::default()).unwrap();
    assert_on_the_main_axis(&measured, BranchedArch::LONG_BRANCHES_DESCENDING, 1.5);
    let stations = &measured.stations;
    // From one main end round the arch to the other, each reached to within its 9 mm
    // rounded cap.
    let descending_end = [
        BranchedArch::ARCH,
        0.0,
        -BranchedArch::LONG_BRANCHES_DESCENDING,
    ];
    let (first, last) = (stations[0].centre, stations[stations.len() - 1].centre);
    let near = |p: [f64; 3], q: [f64; 3]| norm(sub(p, q)) < 9.5;
    assert!(
        (near(first, ASCENDING_END) && near(last, descending_end))
            || (near(first, descending_end) && near(last, ASCENDING_END)),
        "{first:?} {last:?}"
    );
}

/// Every station outside the rounded end caps (where the centreline runs past the ends of
/// the axis) lies within `tolerance` mm of the arch's main axis, and the length is the
/// axis's: legs of 20 and `descending` mm and a half-circle arch of radius 30, plus up to a
/// radius into each cap (and 1 mm for the 1 mm marching-cubes surface). A line that
/// wiggled into the branches would be off the axis and longer.
fn assert_on_the_main_axis(measured: &VesselMeasurements, descending: f64, tolerance: f64) {
    let length = measured.centreline_length_mm;
    let cap = BranchedArch::RADIUS;
    for s in measured
        .stations
        .iter()
        .filter(|s| s.s_mm > cap && s.s_mm < length - cap)
    {
        let off = BranchedArch::main_axis_distance(s.centre, descending);
        assert!(
            off < tolerance,
            "station at {:.1} mm is {off:.2} mm off the axis",
            s.s_mm
        );
    }
    let axis = 20.0 + descending + std::f64::consts::PI * BranchedArch::ARCH;
    assert!(length > axis && length < axis + 2.0 * cap + 1.0, "{length}");
}

#[test]
fn the_maximum_diameter_leaves_the_branch_ostia_out() {
    // Branches reaching 25 mm above the arch: a plane within about 2 mm of a branch's axis
    // cuts it to its tip.
    let mesh = BranchedArch::mesh();
    let measured = measure_vessel(&mesh, &MeasureOptions::default()).unwrap();
    let diameter = 2.0 * BranchedArch::RADIUS;
    // The shape does what it is for: planes through the ostia cut up into the branches.
    let through_ostia = measured
        .stations
        .iter()
        .map(|s| s.equivalent_diameter_mm)
        .fold(0.0, f64::max);
    assert!(through_ostia > 1.2 * diameter, "{through_ostia}");
    // Without them the largest section is the tube's own (1 mm marching-cubes surface).
    let max = shape::measure_shape(&mesh).unwrap().max_diameter_mm;
    assert_eq!(max, measured.max_diameter_mm());
    assert!((max - diameter).abs() < 0.6, "{max} against {diameter}");
}

/// The centreline of an arch with supra-aortic branches stays on the main axis where the
/// sections cut the ostia, instead of being pulled towards a branch.
#[test]
fn the_centreline_runs_straight_past_the_branch_ostia() {
    let measured = measure_vessel(&BranchedArch::mesh(), &MeasureOptions::default()).unwrap();
    assert_on_the_main_axis(&measured, BranchedArch::DESCENDING, 0.5);
}

#[test]
fn an_elliptic_lumen_keeps_its_sections_in_the_maximum_diameter() {
    // Semi-axes 12 and 9 (aspect 1.33), flat ends, 100 mm long.
    let mesh = mesh_of(
        |p| ((p[0] / 12.0).hypot(p[1] / 9.0) - 1.0).max((p[2].abs() - 50.0) / 9.0),
        60.0,
        121,
    );
    let measured = measure_vessel(&mesh, &MeasureOptions::default()).unwrap();
    assert!(measured.stations.iter().all(Station::is_single_lumen));
    let equivalent = 2.0 * (12.0f64 * 9.0).sqrt();
    let max = measured.max_diameter_mm();
    assert!((max - equivalent).abs() < 0.5, "{max} against {equivalent}");
}

#[test]
fn an_aorta_without_a_sinus_is_not_a_root() {
    let err = measure_root(&BranchedArch::mesh()).unwrap_err();
    assert!(matches!(err, MeasureError::NotARoot(_)), "{err}");
}

/// A flat-ended cylinder of radius 12 and length 120 mm along z with a smooth
/// rotationally symmetric bulge of 2.5 mm centred `at` mm from one end.
fn tube_with_bulge(at: f64) -> crate::geometry::TriMesh {
    mesh_of(
        move |p| {
            let bulge = 2.5 * (-0.5 * ((p[2] + 60.0 - at) / 5.0).powi(2)).exp();
            (p[0].hypot(p[1]) - 12.0 - bulge).max(p[2].abs() - 60.0)
        },
        75.0,
        151,
    )
}

#[test]
fn a_widening_far_from_the_ends_is_not_a_sinus() {
    let err = measure_root(&tube_with_bulge(60.0)).unwrap_err();
    let MeasureError::NotARoot(why) = &err else {
        panic!("{err}");
    };
    assert!(why.contains("within 1 diameter of an end"), "{why}");
}

/// A straight line of centre points every 1 mm with a 22 mm run missing and, just after
/// it, four noisy points (±0.8 mm) bunched within 1.7 mm, as at a run of sections through
/// branch ostia.
fn line_with_a_gap_and_a_noisy_cluster() -> polyline::Polyline {
    let mut points: Vec<[f64; 3]> = (0..=40).map(|x| [x as f64, 0.0, 0.0]).collect();
    points.extend([
        [62.0, 0.0, 0.0],
        [62.7, 0.8, 0.0],
        [63.1, -0.6, 0.0],
        [63.7, 0.5, 0.0],
    ]);
    points.extend((70..=120).map(|x| [x as f64, 0.0, 0.0]));
    polyline::Polyline::new(points)
}

#[test]
fn the_smoothed_line_bridges_a_gap_instead_of_extrapolating_a_cluster() {
    let line = line_with_a_gap_and_a_noisy_cluster();
    let gap_start = line.arc_lengths()[40];
    let gap_end = line.arc_lengths()[41];
    let mut s = gap_start;
    while s <= gap_end {
        let (p, _) = line.frame_at(s, 10.0);
        assert!(
            p[1].abs() < 1.0 && p[2].abs() < 1e-9,
            "at s = {s:.1} the smoothed point {p:?} is off the line"
        );
        s += 0.25;
    }
}
