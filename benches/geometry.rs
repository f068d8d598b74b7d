//! Geometry-core benchmarks: Chamfer distance (single pair and the full pairwise sweep) and
//! area-weighted surface sampling, on the same inputs as the Python reference scripts
//! (`bench_chamfer.py`, `bench_surface_sampling.py`).
//!
//! Run: `cargo bench --bench geometry` (all cases), or name cases as arguments:
//! `cargo bench --bench geometry -- cd30k cd100k sampling pairwise data`
//! (`kiddo` additionally compares nearest-neighbour paths; it only runs when named).
//! `AORTAGEN_DATA=/work/shared/data/synthaorta/ref4` adds the SynthAorta surfaces
//! (pairwise CD on 30k samples per shape and the sampling floor), unit-ball coordinates.
//! `AORTAGEN_BENCH_PAIRWISE_REPS` sets the pairwise repetitions (default 5).

use std::path::Path;
use std::time::Instant;

use aortagen::geometry::TriMesh;
use aortagen::geometry::chamfer::{
    DEFAULT_CHAMFER_POINTS, chamfer_distance, index_sets, pairwise_chamfer_indexed, sampling_floor,
};
use aortagen::geometry::normalize::normalize_to_unit_ball;
use aortagen::geometry::sampling::sample_surface;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let wants = |case: &str| args.is_empty() || args.iter().any(|a| a == case);
    println!(
        "geometry bench: {} rayon threads (medians; reference figures: scipy cKDTree workers=2, trimesh)",
        rayon::current_num_threads()
    );
    if args.iter().any(|a| a == "kiddo") {
        kiddo_comparison();
    }
    if wants("cd30k") {
        single_chamfer(30_000, 3, 15, 0.129);
    }
    if wants("cd100k") {
        single_chamfer(100_000, 2, 8, f64::NAN);
    }
    if wants("sampling") {
        sampling(0.144);
    }
    if wants("pairwise") {
        pairwise(1022.0);
    }
    if wants("data") {
        match std::env::var("AORTAGEN_DATA") {
            Ok(dir) => synthaorta(Path::new(&dir)),
            Err(_) => println!("data: skipped (set AORTAGEN_DATA to the SynthAorta PLY folder)"),
        }
    }
}

/// Median, min and max of `reps` timed runs after `warmup` untimed ones.
fn time_it(reps: usize, warmup: usize, mut f: impl FnMut()) -> (f64, f64, f64) {
    for _ in 0..warmup {
        f();
    }
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], t[0], t[t.len() - 1])
}

fn report(label: &str, (median, min, max): (f64, f64, f64), reference: f64) {
    let ratio = if reference.is_finite() {
        format!(
            "; reference {reference:.3} s → {:.1}× faster",
            reference / median
        )
    } else {
        String::new()
    };
    println!("{label}: median {median:.4} s (min {min:.4}, max {max:.4}){ratio}");
}

/// A uniformly random rotation (QR of a Gaussian matrix, as the reference does).
fn random_rotation(rng: &mut ChaCha8Rng) -> [[f64; 3]; 3] {
    let mut cols: [[f64; 3]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| gaussian(rng)));
    for i in 0..3 {
        for j in 0..i {
            let d: f64 = (0..3).map(|k| cols[i][k] * cols[j][k]).sum();
            let basis = cols[j];
            for (c, b) in cols[i].iter_mut().zip(basis) {
                *c -= d * b;
            }
        }
        let n = cols[i].iter().map(|c| c * c).sum::<f64>().sqrt();
        cols[i] = cols[i].map(|c| c / n);
    }
    cols
}

fn uniform(rng: &mut ChaCha8Rng) -> f64 {
    (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let (u, v) = (1.0 - uniform(rng), uniform(rng));
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// `n` points on a randomly rotated ellipsoid (normalised Gaussian directions × axes).
fn sample_ellipsoid(n: usize, rng: &mut ChaCha8Rng, axes: [f64; 3]) -> Vec<[f32; 3]> {
    let r = random_rotation(rng);
    (0..n)
        .map(|_| {
            let u: [f64; 3] = std::array::from_fn(|_| gaussian(rng));
            let len = u.iter().map(|c| c * c).sum::<f64>().sqrt();
            let e: [f64; 3] = std::array::from_fn(|k| u[k] / len * axes[k]);
            std::array::from_fn(|k| (0..3).map(|j| r[j][k] * e[j]).sum::<f64>() as f32)
        })
        .collect()
}

fn single_chamfer(n: usize, warmup: usize, reps: usize, reference: f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let a = sample_ellipsoid(n, &mut rng, [0.6, 0.4, 0.3]);
    let b = sample_ellipsoid(n, &mut rng, [0.5, 0.5, 0.35]);
    let mut cd = 0.0;
    let t = time_it(reps, warmup, || cd = chamfer_distance(&a, &b));
    report(
        &format!("chamfer {n} vs {n} (build 2 trees + queries), CD={cd:.6}"),
        t,
        reference,
    );
}

fn pairwise(reference: f64) {
    let reps = std::env::var("AORTAGEN_BENCH_PAIRWISE_REPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    let mut rng = ChaCha8Rng::seed_from_u64(100);
    let sets: Vec<Vec<[f32; 3]>> = (0..100)
        .map(|_| {
            let axes = std::array::from_fn(|_| 0.3 + 0.6 * uniform(&mut rng));
            sample_ellipsoid(DEFAULT_CHAMFER_POINTS, &mut rng, axes)
        })
        .collect();
    let start = Instant::now();
    let indices = index_sets(&sets);
    println!(
        "pairwise: built 100 trees of 30k points in {:.3} s",
        start.elapsed().as_secs_f64()
    );
    let mut mean = 0.0;
    let t = time_it(reps, 0, || {
        let m = pairwise_chamfer_indexed(&indices);
        mean = m.iter().flatten().sum::<f64>() / (100.0 * 99.0);
    });
    report(
        &format!("pairwise CD, 100 sets × 30k, all 4950 pairs, mean CD={mean:.6}"),
        t,
        reference,
    );
}

/// A torus like `trimesh.creation.torus(0.6, 0.25, 400, 125)` scaled by (1, 0.7, 1.3):
/// 100 000 triangles whose areas differ between the inner and outer side.
fn torus(major: f64, minor: f64, nu: u32, nv: u32) -> TriMesh {
    let mut positions = Vec::with_capacity((nu * nv) as usize);
    for i in 0..nu {
        let u = std::f64::consts::TAU * f64::from(i) / f64::from(nu);
        for j in 0..nv {
            let v = std::f64::consts::TAU * f64::from(j) / f64::from(nv);
            let r = major + minor * v.cos();
            positions.push([
                (r * u.cos()) as f32,
                (0.7 * r * u.sin()) as f32,
                (1.3 * minor * v.sin()) as f32,
            ]);
        }
    }
    let id = |i: u32, j: u32| (i % nu) * nv + j % nv;
    let mut triangles = Vec::with_capacity((2 * nu * nv) as usize);
    for i in 0..nu {
        for j in 0..nv {
            triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh::new(positions, triangles)
}

fn sampling(reference: f64) {
    let mesh = torus(0.6, 0.25, 400, 125);
    let n = 500_000;
    let mut count = 0;
    let t = time_it(20, 3, || count = sample_surface(&mesh, n, 42).points.len());
    assert_eq!(count, n);
    report(
        &format!(
            "sampling {n} points + face normals from {} triangles (areas computed inside)",
            mesh.triangle_count()
        ),
        t,
        reference,
    );
}

fn synthaorta(dir: &Path) {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    files.retain(|p| p.extension().is_some_and(|e| e == "ply"));
    files.sort();
    let meshes: Vec<TriMesh> = files
        .iter()
        .filter_map(|p| match read_binary_ply(p) {
            Ok(m) => Some(normalize_to_unit_ball(&m).0),
            Err(e) => {
                println!("data: skipping {}: {e}", p.display());
                None
            }
        })
        .collect();
    if meshes.len() < 2 {
        println!(
            "data: fewer than two readable PLY surfaces in {}",
            dir.display()
        );
        return;
    }
    let n = DEFAULT_CHAMFER_POINTS;
    let start = Instant::now();
    let sets: Vec<Vec<[f32; 3]>> = meshes
        .iter()
        .enumerate()
        .map(|(i, m)| sample_surface(m, n, i as u64).points)
        .collect();
    let sample_s = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let matrix = pairwise_chamfer_indexed(&index_sets(&sets));
    let pair_s = start.elapsed().as_secs_f64();
    let mut off: Vec<f64> = (0..meshes.len())
        .flat_map(|i| (i + 1..meshes.len()).map(move |j| (i, j)))
        .map(|(i, j)| matrix[i][j])
        .collect();
    off.sort_by(f64::total_cmp);
    let mut floors: Vec<f64> = meshes.iter().map(|m| sampling_floor(m, n, 7)).collect();
    floors.sort_by(f64::total_cmp);
    println!(
        "data: {} SynthAorta surfaces (unit-ball coordinates): sampled {n} points each in {sample_s:.3} s; \
         pairwise CD over {} pairs in {pair_s:.3} s: min {:.3e}, median {:.3e}, max {:.3e}; \
         sampling floor median {:.3e} (min {:.3e}, max {:.3e})",
        meshes.len(),
        off.len(),
        off[0],
        off[off.len() / 2],
        off[off.len() - 1],
        floors[floors.len() / 2],
        floors[0],
        floors[floors.len() - 1]
    );
}

/// Minimal reader for the SynthAorta files: binary little-endian PLY whose vertices are
/// `float` properties starting with x y z and whose faces are `list uchar int`.
fn read_binary_ply(path: &Path) -> Result<TriMesh, String> {
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .ok_or("no end_header line")?;
    let header = std::str::from_utf8(&bytes[..end]).map_err(|e| e.to_string())?;
    if !header.contains("format binary_little_endian 1.0") {
        return Err("not binary little-endian".into());
    }
    let (mut nv, mut nf, mut vprops, mut element) = (0usize, 0usize, 0usize, "");
    for line in header.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["element", name, count] => {
                element = if *name == "vertex" {
                    "vertex"
                } else if *name == "face" {
                    "face"
                } else {
                    "other"
                };
                let c: usize = count
                    .parse()
                    .map_err(|_| format!("bad count in {line:?}"))?;
                if element == "vertex" {
                    nv = c
                } else if element == "face" {
                    nf = c
                } else {
                    return Err(format!("unsupported element {name}"));
                }
            }
            ["property", "float", _] if element == "vertex" => vprops += 1,
            ["property", "list", "uchar", "int", _] if element == "face" => {}
            ["property", ..] => return Err(format!("unsupported property {line:?}")),
            _ => {}
        }
    }
    let body = &bytes[end + 11..];
    let f32_at = |o: usize| {
        body.get(o..o + 4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let stride = 4 * vprops;
    let positions = (0..nv)
        .map(|i| {
            let o = i * stride;
            Some([f32_at(o)?, f32_at(o + 4)?, f32_at(o + 8)?])
        })
        .collect::<Option<Vec<_>>>()
        .ok_or("truncated vertex data")?;
    let mut o = nv * stride;
    let mut triangles = Vec::with_capacity(nf);
    for _ in 0..nf {
        if body.get(o) != Some(&3) {
            return Err("a face is not a triangle or the data is truncated".into());
        }
        let idx = |k: usize| {
            body.get(o + 1 + 4 * k..o + 5 + 4 * k)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        };
        triangles.push([
            idx(0).ok_or("truncated")?,
            idx(1).ok_or("truncated")?,
            idx(2).ok_or("truncated")?,
        ]);
        o += 13;
    }
    Ok(TriMesh::new(positions, triangles))
}

/// One directed nearest-neighbour pass (30k queries → 30k points, one thread) through
/// kiddo 6.3's query paths and through the leaf-blocked tree the Chamfer code uses.
fn kiddo_comparison() {
    use aortagen::geometry::point_tree::{LEAF, PointTree};
    use kiddo::{ImmutableKdTree, SquaredEuclidean};
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let a = sample_ellipsoid(30_000, &mut rng, [0.6, 0.4, 0.3]);
    let b = sample_ellipsoid(30_000, &mut rng, [0.5, 0.5, 0.35]);
    let ta: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(&a).unwrap();
    let tb: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(&b).unwrap();
    let leaf_ordered: Vec<[f32; 3]> = ta.iter().map(|(_, p)| p).collect();
    let (pa, pb) = (PointTree::new(&a), PointTree::new(&b));
    let mut sums = Vec::new();
    let mut run = |label: &str, f: &dyn Fn() -> f64| {
        let mut s = 0.0;
        report(label, time_it(5, 1, || s = f()), f64::NAN);
        sums.push(s);
    };
    let one = |q: &[f32; 3]| {
        tb.query(q)
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute()
            .distance
    };
    run("kiddo per-point query", &|| a.iter().map(one).sum());
    run("kiddo per-point query, leaf-ordered", &|| {
        leaf_ordered.iter().map(one).sum()
    });
    run("kiddo dual-tree nearest_one", &|| {
        let r = ta
            .query_tree(&tb)
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute();
        r.iter().map(|r| r.distance).sum()
    });
    run("leaf-blocked PointTree", &|| {
        let mut out = [0.0; LEAF];
        (0..pa.leaf_count())
            .map(|l| {
                let block = pa.leaf_points(l);
                pb.nearest_block(block, &mut out);
                out[..block.len()].iter().sum::<f64>()
            })
            .sum()
    });
    let spread = sums
        .iter()
        .fold(0.0f64, |m, s| m.max((s - sums[0]).abs() / sums[0]));
    println!("kiddo comparison: sums agree to {spread:.1e} relative");
}
