//! Node transforms for the glTF reader: world matrices through the node hierarchy, and
//! how points and normals move under them.

use crate::geometry::mesh::{cross, dot};

/// A 4×4 transform, row-major.
pub(super) type Matrix = [[f64; 4]; 4];
/// The identity transform.
pub(super) const IDENTITY: Matrix = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

/// The node's local matrix premultiplied by its ancestors' (cycle-safe).
pub(super) fn world_matrix(
    nodes: &[gltf::Node<'_>],
    parents: &[Option<usize>],
    node: usize,
) -> Matrix {
    let mut world = local_matrix(&nodes[node]);
    let mut current = node;
    for _ in 0..nodes.len() {
        let Some(parent) = parents[current] else {
            break;
        };
        world = multiply(&local_matrix(&nodes[parent]), &world);
        current = parent;
    }
    world
}

/// Column-major local matrix as row-major f64.
fn local_matrix(node: &gltf::Node<'_>) -> Matrix {
    let cols = node.transform().matrix();
    std::array::from_fn(|r| std::array::from_fn(|c| f64::from(cols[c][r])))
}

fn multiply(a: &Matrix, b: &Matrix) -> Matrix {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..4).map(|k| a[r][k] * b[k][c]).sum()))
}

pub(super) fn transform_point(m: &Matrix, p: [f32; 3]) -> [f32; 3] {
    if *m == IDENTITY {
        return p; // bit-exact for the common case
    }
    let p = p.map(f64::from);
    std::array::from_fn(|r| (m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3]) as f32)
}

/// Normals transform by the inverse transpose of the linear part (the cofactor matrix,
/// scaled by the determinant's sign), then are renormalised.
pub(super) fn transform_normal(m: &Matrix, det: f64, n: [f32; 3]) -> [f32; 3] {
    if *m == IDENTITY {
        return n;
    }
    let row = |r: usize| [m[r][0], m[r][1], m[r][2]];
    let cofactor = [
        cross(row(1), row(2)),
        cross(row(2), row(0)),
        cross(row(0), row(1)),
    ];
    let n = n.map(f64::from);
    let v: [f64; 3] = std::array::from_fn(|i| dot(cofactor[i], n) * det.signum());
    let len = dot(v, v).sqrt();
    if len > 0.0 {
        v.map(|c| (c / len) as f32)
    } else {
        [0.0; 3]
    }
}

pub(super) fn determinant3(m: &Matrix) -> f64 {
    dot(
        [m[0][0], m[0][1], m[0][2]],
        cross([m[1][0], m[1][1], m[1][2]], [m[2][0], m[2][1], m[2][2]]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_stay_perpendicular_to_transformed_tangents() {
        // A shear, non-uniform scale and mirror together (det < 0), plus a translation.
        let m: Matrix = [
            [-1.5, 0.3, 0.2, 4.0],
            [0.1, 2.0, -0.4, -1.0],
            [0.0, 0.5, 0.7, 2.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let det = determinant3(&m);
        assert!(det < 0.0);
        let n = [0.0f32, 0.6, 0.8];
        let tangents = [[1.0f32, 0.0, 0.0], [0.0, 0.8, -0.6]];
        let moved_n = transform_normal(&m, det, n).map(f64::from);
        let origin = transform_point(&m, [0.0; 3]).map(f64::from);
        for t in tangents {
            let moved_t = transform_point(&m, t).map(f64::from);
            let dir = [0, 1, 2].map(|i| moved_t[i] - origin[i]);
            assert!(dot(moved_n, dir).abs() < 1e-6, "{moved_n:?} · {dir:?}");
        }
        assert!((dot(moved_n, moved_n) - 1.0).abs() < 1e-6);
        // The normal keeps pointing to the side the geometry's outside went to.
        let out = transform_point(&m, n).map(f64::from);
        let side = [0, 1, 2].map(|i| out[i] - origin[i]);
        assert!(dot(moved_n, side) > 0.0);
    }

    #[test]
    fn the_identity_leaves_points_bit_exact() {
        let p = [0.1f32, 1.0 / 3.0, -7.25];
        assert_eq!(transform_point(&IDENTITY, p), p);
    }
}
