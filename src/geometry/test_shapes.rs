//! Analytic meshes shared by the geometry tests.

use super::mesh::TriMesh;

/// A latitude–longitude sphere of radius `r` around `centre`, triangles counter-clockwise
/// from outside; triangles near the poles are much smaller than at the equator.
pub(crate) fn uv_sphere(r: f32, centre: [f32; 3], rings: u32, segments: u32) -> TriMesh {
    let mut positions = vec![[centre[0], centre[1], centre[2] + r]];
    for i in 1..rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segments {
            let phi = std::f32::consts::TAU * j as f32 / segments as f32;
            positions.push([
                centre[0] + r * theta.sin() * phi.cos(),
                centre[1] + r * theta.sin() * phi.sin(),
                centre[2] + r * theta.cos(),
            ]);
        }
    }
    let south = positions.len() as u32;
    positions.push([centre[0], centre[1], centre[2] - r]);
    let ring = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
    let mut triangles = Vec::new();
    for j in 0..segments {
        triangles.push([0, ring(1, j), ring(1, j + 1)]);
        triangles.push([south, ring(rings - 1, j + 1), ring(rings - 1, j)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segments {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            triangles.push([a, c, d]);
            triangles.push([a, d, b]);
        }
    }
    let normals = positions
        .iter()
        .map(|p| std::array::from_fn(|k| (p[k] - centre[k]) / r))
        .collect();
    TriMesh {
        positions,
        triangles,
        normals: Some(normals),
    }
}

#[test]
fn uv_sphere_is_closed_and_outward() {
    let m = uv_sphere(2.0, [1.0, 0.0, -1.0], 12, 20);
    m.validate().unwrap();
    assert!(m.edge_report().is_closed_and_oriented());
    assert_eq!(m.euler_characteristic(), 2);
    let v = m.signed_volume();
    let exact = 4.0 / 3.0 * std::f64::consts::PI * 8.0;
    assert!(v > 0.9 * exact && v < exact, "volume {v}");
}
