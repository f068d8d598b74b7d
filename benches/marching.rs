//! Marching-cubes and extraction benchmarks.
//!
//! Run with `cargo bench --bench marching [-- mc|extract|counts|network]`. Prints
//! 1. `mc`: dense marching cubes on R³ grids (R = 256, 128) of the reference scene of
//!    peers/bench_marching_cubes.py (torus ∪ two spheres ∪ ellipsoid) and of a sphere;
//! 2. `extract`: sparse vs dense extraction from the analytic scene as a field at R = 256
//!    (evaluations and time), and the sparse path alone at R = 512 with peak memory;
//! 3. `counts`: evaluations of the sparse path on the analytic scene at R = 128/256/512 for
//!    several finest block sizes (deterministic);
//! 4. `network`: the sparse path on a neural field, one run per resolution. Options:
//!    `--net d,H` (geometric init, seed 1; repeatable) or `--model DIR` (first latent of a
//!    saved model; `--shape K`, repeatable, picks other latents), `--resolution R` (repeatable;
//!    default 128 and 256), `--block B`, `--tensor-forward` (burn's tensor forward pass instead
//!    of the host pass), `--compare-dense` (also run the dense reference path and print the
//!    triangle counts of both meshes and their largest vertex difference).
//!
//! All sections run when no section is named (`network` only with `--net`/`--model`).

use aortagen::extract::analytic::Shape;
use aortagen::extract::{ExtractOptions, Extraction, ScalarField, extract_dense, extract_surface};
use aortagen::geometry::marching_cubes::{Grid, marching_cubes};
use aortagen::sdf::inference::reconstruct::NeuralField;
use aortagen::sdf::store::LoadedModel;
use aortagen::sdf::{Backend, SdfField, SdfNetworkConfig};
use std::time::{Duration, Instant};

/// Median wall time of `runs` calls after `warmup` untimed ones, and the last result.
fn median<T>(warmup: usize, runs: usize, mut f: impl FnMut() -> T) -> (Duration, T) {
    for _ in 0..warmup {
        std::hint::black_box(f());
    }
    let mut times = Vec::with_capacity(runs);
    let mut last = None;
    for _ in 0..runs {
        let start = Instant::now();
        last = Some(f());
        times.push(start.elapsed());
    }
    times.sort();
    (times[runs / 2], last.expect("at least one run"))
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Peak resident memory of this process so far (Linux), in MiB.
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

fn dense_marching_cubes() {
    let sphere = Shape::Sphere {
        centre: [0.0; 3],
        radius: 0.5,
    };
    for (name, shape) in [("scene", Shape::benchmark_scene()), ("sphere", sphere)] {
        for (resolution, runs) in [(256, 15), (128, 30)] {
            let grid = Grid::new(resolution);
            let values: Vec<f32> = grid
                .points()
                .map(|p| shape.value_and_gradient(p).0)
                .collect();
            let (t, mesh) = median(3, runs, || marching_cubes(&grid, &values, 0.0));
            println!(
                "marching_cubes {name} {resolution}^3: median {:.1} ms of {runs}; {} triangles, {} vertices, closed {}",
                ms(t),
                mesh.triangle_count(),
                mesh.vertex_count(),
                mesh.edge_report().is_closed_and_oriented()
            );
        }
    }
}

fn report(label: &str, t: Duration, out: &Extraction) {
    println!(
        "{label}: median {:.1} ms (evaluation {:.1} ms, meshing {:.1} ms); evaluations {} \
         (centres {}, samples {}, normals {}); {} triangles; kept blocks {}",
        ms(t),
        ms(out.timings.evaluation),
        ms(out.timings.meshing),
        out.evaluations.total(),
        out.evaluations.block_centres,
        out.evaluations.samples,
        out.evaluations.normals,
        out.mesh.triangle_count(),
        out.kept_blocks
    );
}

fn sparse_vs_dense() {
    let scene = Shape::benchmark_scene();
    let options = ExtractOptions::default();
    let (t, out) = median(1, 5, || {
        extract_surface(&scene, 512, &options).expect("valid options")
    });
    report("extract sparse R=512", t, &out);
    if let Some(peak) = peak_rss_mib() {
        println!("peak RSS after sparse R=512: {peak:.0} MiB");
    }
    let (ts, sparse) = median(1, 7, || {
        extract_surface(&scene, 256, &options).expect("valid options")
    });
    report("extract sparse R=256", ts, &sparse);
    let (td, dense) = median(1, 7, || {
        extract_dense(&scene, 256, &options).expect("valid options")
    });
    report("extract dense  R=256", td, &dense);
    println!(
        "sparse/dense at R=256: {:.2}x fewer evaluations, {:.2}x faster; same triangles: {}",
        dense.evaluations.total() as f64 / sparse.evaluations.total() as f64,
        td.as_secs_f64() / ts.as_secs_f64(),
        dense.mesh.triangle_count() == sparse.mesh.triangle_count()
    );
}

fn hierarchy_counts() {
    let scene = Shape::benchmark_scene();
    for resolution in [128, 256, 512] {
        for block_cells in [8, 4, 2] {
            let options = ExtractOptions {
                block_cells,
                ..Default::default()
            };
            let start = Instant::now();
            let out = extract_surface(&scene, resolution, &options).expect("valid options");
            report(
                &format!("counts scene R={resolution} B={block_cells}"),
                start.elapsed(),
                &out,
            );
        }
    }
}

/// The neural fields named on the command line: `(label, field)`.
fn neural_fields(
    nets: &[(usize, usize)],
    models: &[String],
    shapes: &[usize],
    tensor_forward: bool,
) -> Vec<(String, SdfField)> {
    let mut out = Vec::new();
    let device = Backend::default().device(false).expect("default backend");
    for &(d, h) in nets {
        let network = SdfNetworkConfig::new()
            .with_latent_dim(d)
            .with_hidden(h)
            .init(1, &device)
            .expect("valid network size");
        let field = SdfField::new(&network, &vec![0.0; d]).expect("latent of length d");
        out.push((format!("net ({d},{h}) geometric init"), field));
    }
    for dir in models {
        let model =
            LoadedModel::load(std::path::Path::new(dir), Backend::default()).expect("model loads");
        let latents = model.latents();
        for &k in shapes {
            let latent = latents
                .get(k)
                .expect("--shape within the model's training shapes");
            out.push((
                format!("model {dir} shape {k}"),
                model.field(latent).expect("latent fits"),
            ));
        }
    }
    if tensor_forward {
        out = out
            .into_iter()
            .map(|(label, f)| (format!("{label} tensor forward"), f.with_tensor_forward()))
            .collect();
    }
    out
}

fn network_extraction(
    nets: &[(usize, usize)],
    models: &[String],
    shapes: &[usize],
    resolutions: &[usize],
    block: usize,
    tensor_forward: bool,
    compare_dense: bool,
) {
    for (label, field) in neural_fields(nets, models, shapes, tensor_forward) {
        let neural = NeuralField::new(&field).expect("finite field");
        let options = ExtractOptions {
            block_cells: block,
            ..Default::default()
        };
        for &resolution in resolutions {
            let start = Instant::now();
            let out = extract_surface(&neural, resolution, &options).expect("valid options");
            let t = start.elapsed();
            report(
                &format!("network {label} R={resolution} B={block}"),
                t,
                &out,
            );
            println!(
                "  {:.0} evaluations/s inside eval_batch; L = {:.3}",
                out.evaluations.total() as f64 / out.timings.evaluation.as_secs_f64(),
                neural.lipschitz_bound()
            );
            if compare_dense {
                let start = Instant::now();
                let dense = extract_dense(&neural, resolution, &options).expect("valid options");
                let t = start.elapsed();
                let difference = out.mesh.max_surface_difference(&dense.mesh);
                println!(
                    "  dense path: {:.0} ms, {} evaluations; triangles fast {} / dense {}; \
                     vertices fast {} / dense {}; largest vertex difference {}",
                    ms(t),
                    dense.evaluations.total(),
                    out.mesh.triangle_count(),
                    dense.mesh.triangle_count(),
                    out.mesh.vertex_count(),
                    dense.mesh.vertex_count(),
                    difference.map_or("— (counts differ)".to_owned(), |d| format!("{d:.2e}")),
                );
            }
        }
    }
}

fn main() {
    // `cargo bench --bench marching -- mc` runs only the sections whose name matches.
    let mut filters: Vec<String> = Vec::new();
    let (mut nets, mut models, mut resolutions, mut block) =
        (Vec::new(), Vec::new(), Vec::new(), 2);
    let mut shapes = Vec::new();
    let (mut tensor_forward, mut compare_dense) = (false, false);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().unwrap_or_else(|| panic!("{a} needs a value"));
        match a.as_str() {
            "--net" => {
                let v = value();
                let (d, h) = v.split_once(',').expect("--net d,H");
                nets.push((d.parse().expect("d"), h.parse().expect("H")));
            }
            "--model" => models.push(value()),
            "--resolution" => resolutions.push(value().parse().expect("--resolution R")),
            "--block" => block = value().parse().expect("--block B"),
            "--shape" => shapes.push(value().parse().expect("--shape K")),
            "--tensor-forward" => tensor_forward = true,
            "--compare-dense" => compare_dense = true,
            other if other.starts_with("--") => {} // cargo bench passes --bench
            other => filters.push(other.to_owned()),
        }
    }
    if resolutions.is_empty() {
        resolutions = vec![128, 256];
    }
    if shapes.is_empty() {
        shapes.push(0);
    }
    let wanted =
        |name: &str| filters.is_empty() || filters.iter().any(|f| name.contains(f.as_str()));
    println!("threads: {}", rayon::current_num_threads());
    if wanted("mc") {
        dense_marching_cubes();
    }
    if wanted("extract") {
        sparse_vs_dense();
    }
    if wanted("counts") {
        hierarchy_counts();
    }
    if wanted("network") && !(nets.is_empty() && models.is_empty()) {
        network_extraction(
            &nets,
            &models,
            &shapes,
            &resolutions,
            block,
            tensor_forward,
            compare_dense,
        );
    }
}
