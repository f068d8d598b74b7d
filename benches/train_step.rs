//! Training-step and inference throughput of the SDF auto-decoder.
//!
//! One IGR step = build a batch on the host (8 shapes × 2048 surface points with normals, 2048
//! eikonal points per shape: half Gaussian around the batch's surface points with a per-point
//! σ, half uniform in [-1,1]³), loss with explicit ∇ₓf, backward, Adam over network and
//! latents — the same work as the PyTorch reference `bench_sdf_train.py` (which draws 7/8 of
//! its eikonal points locally; the cost is identical). The data are random ellipsoids, as in
//! the reference.
//!
//! ```text
//! cargo bench --bench train_step -- [--backend flex|ndarray]... [--config a|b|c]...
//!     [--steps 7] [--warmup 2] [--inference-points 262144]
//! ```
//! Configurations: a (d=256, H=512), b (256, 256), c (64, 128). Each (backend, config) runs in
//! a child process so that its peak RSS is its own.

use std::process::Command;
use std::time::Instant;

use aortagen::sdf::{
    Backend, SdfAutoDecoder, SdfField, SdfNetworkConfig, SdfTrainer, TrainStepConfig, TrainingBatch,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

const SHAPES: usize = 64;
const POOL: usize = 16_384;
const BATCH_SHAPES: usize = 8;
const POINTS: usize = 2048;

struct Args {
    backends: Vec<Backend>,
    configs: Vec<char>,
    steps: usize,
    warmup: usize,
    inference_points: usize,
    child: bool,
}

fn parse_args() -> Args {
    let mut args = Args {
        backends: vec![],
        configs: vec![],
        steps: 7,
        warmup: 2,
        inference_points: 262_144,
        child: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut value = || it.next().unwrap_or_else(|| panic!("{a} needs a value"));
        match a.as_str() {
            "--backend" => args.backends.push(value().parse().expect("backend")),
            "--config" => args.configs.push(value().chars().next().expect("config")),
            "--steps" => args.steps = value().parse().expect("--steps"),
            "--warmup" => args.warmup = value().parse().expect("--warmup"),
            "--inference-points" => args.inference_points = value().parse().expect("points"),
            "--child" => args.child = true,
            _ => {} // cargo bench passes --bench
        }
    }
    if args.backends.is_empty() {
        args.backends = Backend::ALL
            .into_iter()
            .filter(|b| b.is_compiled())
            .collect();
    }
    if args.configs.is_empty() {
        args.configs = vec!['a', 'b', 'c'];
    }
    args
}

fn dims(config: char) -> (usize, usize) {
    match config {
        'a' => (256, 512),
        'b' => (256, 256),
        'c' => (64, 128),
        other => panic!("unknown config {other}: expected a, b or c"),
    }
}

/// Random ellipsoids: surface points, outward normals and a per-point σ.
struct Dataset {
    points: Vec<Vec<[f32; 3]>>,
    normals: Vec<Vec<[f32; 3]>>,
    sigma: Vec<Vec<f32>>,
}

fn ellipsoids(rng: &mut ChaCha8Rng) -> Dataset {
    let mut data = Dataset {
        points: vec![],
        normals: vec![],
        sigma: vec![],
    };
    for _ in 0..SHAPES {
        let axes: [f32; 3] = std::array::from_fn(|_| 0.3 + 0.6 * rng.random::<f32>());
        let (mut p, mut n, mut s) = (vec![], vec![], vec![]);
        for _ in 0..POOL {
            let u: [f32; 3] = std::array::from_fn(|_| StandardNormal.sample(rng));
            let len = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
            let q: [f32; 3] = std::array::from_fn(|k| u[k] / len * axes[k]);
            let m: [f32; 3] = std::array::from_fn(|k| q[k] / (axes[k] * axes[k]));
            let ml = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
            p.push(q);
            n.push(m.map(|c| c / ml));
            s.push(0.005 + 0.02 * rng.random::<f32>());
        }
        data.points.push(p);
        data.normals.push(n);
        data.sigma.push(s);
    }
    data
}

fn sample_batch(data: &Dataset, rng: &mut ChaCha8Rng) -> TrainingBatch {
    let mut batch = TrainingBatch::default();
    for _ in 0..BATCH_SHAPES {
        let shape = rng.random_range(0..SHAPES);
        batch.shape_indices.push(shape);
        let picks: Vec<usize> = (0..POINTS).map(|_| rng.random_range(0..POOL)).collect();
        for &i in &picks {
            batch.surface_points.push(data.points[shape][i]);
            batch.surface_normals.push(data.normals[shape][i]);
        }
        for (j, &i) in picks.iter().enumerate() {
            let e = if j < POINTS / 2 {
                let s = data.sigma[shape][i];
                let p = data.points[shape][i];
                std::array::from_fn(|k| {
                    p[k] + s * Distribution::<f32>::sample(&StandardNormal, rng)
                })
            } else {
                std::array::from_fn(|_| rng.random_range(-1.0f32..1.0))
            };
            batch.eikonal_points.push(e);
        }
    }
    batch
}

fn peak_rss_mib() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn run_one(backend: Backend, config: char, args: &Args) {
    let (d, h) = dims(config);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let data = ellipsoids(&mut rng);
    let device = backend.device(true).expect("backend compiled in");
    let net = SdfNetworkConfig::new().with_latent_dim(d).with_hidden(h);
    let model = SdfAutoDecoder::new(&net, SHAPES, 0, &device).expect("valid config");
    let mut trainer = SdfTrainer::new(model, TrainStepConfig::new());
    let mut times = vec![];
    let mut last_loss = f32::NAN;
    for step in 0..args.warmup + args.steps {
        let start = Instant::now();
        let batch = sample_batch(&data, &mut rng);
        last_loss = trainer.step(&batch, 5e-4).expect("valid batch").loss;
        if step >= args.warmup {
            times.push(start.elapsed().as_secs_f64());
        }
    }
    let step_s = median(times.clone());
    let (min, max) = times
        .iter()
        .fold((f64::MAX, 0f64), |(a, b), &t| (a.min(t), b.max(t)));
    let surface = (BATCH_SHAPES * POINTS) as f64;
    let train_rss = peak_rss_mib();

    let (model, _) = trainer.into_parts();
    let latent = model.latents_to_vec().swap_remove(0);
    let field = SdfField::new(&model.network, &latent).expect("latent length");
    let points: Vec<[f32; 3]> = (0..args.inference_points)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0f32..1.0)))
        .collect();
    let mut values = vec![0.0; points.len()];
    let mut grads = vec![[0.0; 3]; points.len()];
    let mut time_eval = |with_grad: bool| {
        let runs: Vec<f64> = (0..3)
            .map(|_| {
                let start = Instant::now();
                field.eval_batch(&points, &mut values, with_grad.then_some(&mut grads[..]));
                start.elapsed().as_secs_f64()
            })
            .collect();
        points.len() as f64 / median(runs)
    };
    let f_only = time_eval(false);
    let with_grad = time_eval(true);
    println!(
        "backend {backend} config {config} (d={d}, H={h}): step median {step_s:.3} s \
         (min {min:.3}, max {max:.3}, {} steps) -> {:.0} surface points/s; loss {last_loss:.4}; \
         peak RSS training {train_rss:.0} MiB; inference {} points: f {f_only:.0} points/s, \
         f+grad {with_grad:.0} points/s; peak RSS {:.0} MiB",
        times.len(),
        surface / step_s,
        points.len(),
        peak_rss_mib()
    );
}

fn main() {
    let args = parse_args();
    if args.child {
        run_one(args.backends[0], args.configs[0], &args);
        return;
    }
    let exe = std::env::current_exe().expect("own path");
    for &backend in &args.backends {
        for &config in &args.configs {
            let status = Command::new(&exe)
                .args([
                    "--child",
                    "--backend",
                    backend.name(),
                    "--config",
                    &config.to_string(),
                ])
                .args([
                    "--steps",
                    &args.steps.to_string(),
                    "--warmup",
                    &args.warmup.to_string(),
                ])
                .args(["--inference-points", &args.inference_points.to_string()])
                .status()
                .expect("spawn benchmark child");
            assert!(status.success(), "benchmark {backend}/{config} failed");
        }
    }
}
