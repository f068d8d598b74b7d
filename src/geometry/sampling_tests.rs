use super::*;
use crate::geometry::mesh::{dot, norm};
use crate::geometry::test_shapes::uv_sphere;

/// Four disjoint triangles whose areas are 1, 10, 100 and 1000 (× 0.5).
fn unequal_triangles() -> TriMesh {
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for (k, side) in [1.0f32, 10f32.sqrt(), 10.0, 1000f32.sqrt()]
        .into_iter()
        .enumerate()
    {
        let z = k as f32;
        let base = positions.len() as u32;
        positions.extend([[0.0, 0.0, z], [side, 0.0, z], [0.0, side, z]]);
        triangles.push([base, base + 1, base + 2]);
    }
    TriMesh::new(positions, triangles)
}

#[test]
fn the_same_seed_gives_identical_samples_and_another_seed_does_not() {
    let m = uv_sphere(1.0, [0.0; 3], 10, 16);
    let a = sample_surface(&m, 20_000, 7);
    let b = sample_surface(&m, 20_000, 7);
    let c = sample_surface(&m, 20_000, 8);
    assert_eq!(a, b);
    assert_eq!(a.points.len(), 20_000);
    let same = a
        .points
        .iter()
        .zip(&c.points)
        .filter(|(p, q)| p == q)
        .count();
    assert_eq!(same, 0);
}

#[test]
fn samples_do_not_depend_on_the_thread_count() {
    let m = uv_sphere(1.0, [0.0; 3], 10, 16);
    let parallel = sample_surface(&m, 3 * SAMPLING_CHUNK + 17, 3);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let serial = pool.install(|| sample_surface(&m, 3 * SAMPLING_CHUNK + 17, 3));
    assert_eq!(parallel, serial);
    // A prefix of a longer run is the shorter run: chunks are independent streams.
    let shorter = sample_surface(&m, SAMPLING_CHUNK + 5, 3);
    assert_eq!(shorter.points[..], parallel.points[..SAMPLING_CHUNK + 5]);
}

#[test]
fn sphere_samples_lie_on_their_triangles_with_unit_outward_normals() {
    let centre = [0.5f32, -1.0, 2.0];
    let m = uv_sphere(3.0, centre, 12, 24);
    let n = 20_000;
    let s = sample_surface(&m, n, 11);
    let locs = sample_locations(&m, n, 11).unwrap();
    for ((p, nrm), loc) in s.points.iter().zip(&s.normals).zip(&locs) {
        let t = loc.triangle as usize;
        let [a, b, c] = m.corners(t);
        let p = p.map(f64::from);
        // Barycentric coordinates of p recovered by projection onto the triangle's plane.
        let (e1, e2, d) = (sub(b, a), sub(c, a), sub(p, a));
        let face = m.face_normal(t);
        assert!(
            dot(d, face).abs() < 1e-5,
            "off the plane by {}",
            dot(d, face)
        );
        let (d11, d12, d22) = (dot(e1, e1), dot(e1, e2), dot(e2, e2));
        let det = d11 * d22 - d12 * d12;
        let w1 = (d22 * dot(d, e1) - d12 * dot(d, e2)) / det;
        let w2 = (d11 * dot(d, e2) - d12 * dot(d, e1)) / det;
        let eps = 1e-4;
        assert!(
            w1 > -eps && w2 > -eps && w1 + w2 < 1.0 + eps,
            "outside: {w1} {w2}"
        );
        let nrm = nrm.map(f64::from);
        assert!((norm(nrm) - 1.0).abs() < 1e-6);
        let radial = sub(p, centre.map(f64::from));
        assert!(dot(nrm, radial) > 0.95 * norm(radial), "normal not outward");
    }
}

#[test]
fn each_triangle_gets_its_share_of_the_area() {
    let m = unequal_triangles();
    let n = 400_000;
    let locs = sample_locations(&m, n, 5).unwrap();
    let mut counts = [0usize; 4];
    for l in &locs {
        counts[l.triangle as usize] += 1;
    }
    let total = m.area();
    let chi2: f64 = (0..4)
        .map(|t| {
            let expected = n as f64 * m.triangle_area(t) / total;
            (counts[t] as f64 - expected).powi(2) / expected
        })
        .sum();
    // 3 degrees of freedom: P(χ² > 25) ≈ 1.6e-5.
    assert!(chi2 < 25.0, "chi-square {chi2}, counts {counts:?}");
    assert!(counts[0] > 0, "the smallest triangle is never drawn");
}

#[test]
fn samples_are_uniform_inside_a_triangle() {
    let m = TriMesh::new(
        vec![[0.0; 3], [4.0, 0.0, 0.0], [1.0, 3.0, 0.0]],
        vec![[0, 1, 2]],
    );
    let n = 200_000;
    let locs = sample_locations(&m, n, 9).unwrap();
    let (mut mean, mut second) = ([0.0; 3], [0.0; 3]);
    for l in &locs {
        let [w1, w2] = l.weights;
        for (k, w) in [1.0 - w1 - w2, w1, w2].into_iter().enumerate() {
            assert!((-1e-12..=1.0 + 1e-12).contains(&w));
            mean[k] += w / n as f64;
            second[k] += w * w / n as f64;
        }
    }
    // Uniform on a triangle ⇔ barycentrics ~ Dirichlet(1,1,1): E[w] = 1/3, E[w²] = 1/6.
    for k in 0..3 {
        assert!((mean[k] - 1.0 / 3.0).abs() < 0.004, "mean {mean:?}");
        assert!(
            (second[k] - 1.0 / 6.0).abs() < 0.004,
            "second moment {second:?}"
        );
    }
}

#[test]
fn interpolated_vertex_normals_follow_the_sphere_more_closely_than_face_normals() {
    let m = uv_sphere(1.0, [0.0; 3], 8, 12);
    let err = |source| {
        let s = try_sample_surface(&m, 5000, 2, source).unwrap();
        s.points
            .iter()
            .zip(&s.normals)
            .map(|(p, n)| {
                let exact = normalized(p.map(f64::from));
                1.0 - dot(exact, n.map(f64::from))
            })
            .sum::<f64>()
    };
    let (face, vertex) = (err(NormalSource::Face), err(NormalSource::Vertex));
    assert!(vertex < 0.5 * face, "vertex {vertex} vs face {face}");
}

#[test]
fn unusable_meshes_are_reported() {
    let mut m = uv_sphere(1.0, [0.0; 3], 6, 8);
    m.normals = None;
    assert_eq!(
        try_sample_surface(&m, 10, 0, NormalSource::Vertex),
        Err(SamplingError::NoVertexNormals)
    );
    m.triangles[3][1] = 1000;
    assert!(matches!(
        try_sample_surface(&m, 10, 0, NormalSource::Face),
        Err(SamplingError::Mesh(MeshError::IndexOutOfRange {
            triangle: 3,
            ..
        }))
    ));
    assert!(sample_surface(&m, 10, 0).points.is_empty());
    let flat = TriMesh::new(vec![[0.0; 3]; 3], vec![[0, 1, 2]]);
    assert!(matches!(
        sample_locations(&flat, 10, 0),
        Err(SamplingError::Mesh(MeshError::AllDegenerate(1)))
    ));
}
