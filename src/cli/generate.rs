//! `aortagen generate`: new shapes as convex combinations of learned latents.

use std::path::PathBuf;

use anyhow::{Context, ensure};

use super::progress::{init_logging, terminal_bar};
use crate::formats::{MeshFormat, MeshMetadata, write_mesh};
use crate::geometry::chamfer::DEFAULT_CHAMFER_POINTS;
use crate::sdf::backend::Backend;
use crate::sdf::generate::{
    Diversity, GeneratedShape, MAX_REDRAWS, MixSpec, Provenance, Selection, Weighting,
    generate_shape_with, parse_weights,
};
use crate::sdf::novelty::{Novelty, NoveltyReference, training_surfaces};
use crate::sdf::reconstruct::DEFAULT_RESOLUTION;
use crate::sdf::reconstruct::{ExtractionMethod, MAX_RESOLUTION, MIN_RESOLUTION};
use crate::sdf::store::LoadedModel;

/// Coordinates of the written meshes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Units {
    /// The training meshes' own units (millimetres for SynthAorta and the parametric roots),
    /// through the blended unit-ball transform.
    Mm,
    /// Unit-ball coordinates, as the model sees them.
    Unit,
}

/// Write a cohort of generated shapes (mesh + provenance JSON each).
#[derive(Debug, clap::Args)]
pub struct GenerateArgs {
    /// Model directory written by `aortagen train`.
    #[arg(long)]
    pub model: PathBuf,
    /// Training shapes combined per generated shape (k ≥ 2).
    #[arg(long)]
    pub arity: usize,
    /// Fixed weights, comma-separated (k values ≥ 0 summing to 1).
    #[arg(long)]
    pub weights: Option<String>,
    /// Weights when --weights is absent.
    #[arg(long, value_enum, default_value = "dirichlet")]
    pub weighting: Weighting,
    /// How the training latents are picked: `uniform`, or `spread` (k-means++ style, far
    /// from the mean and from each other).
    #[arg(long, value_enum, default_value = "uniform")]
    pub selection: Selection,
    /// Gaussian noise added to the mixed latent, in training standard deviations (≥ 0).
    #[arg(long, default_value_t = 0.0)]
    pub latent_noise: f64,
    /// Smallest accepted Chamfer distance (unit-ball coordinates) to the nearest training
    /// shape: closer shapes are redrawn up to 10 times, then the most novel draw is kept and
    /// flagged `novelty_met: false` in its provenance.
    #[arg(long)]
    pub min_novelty: Option<f64>,
    /// Surface samples per shape for the novelty Chamfer distance.
    #[arg(long, default_value_t = DEFAULT_CHAMFER_POINTS)]
    pub novelty_points: usize,
    /// Number of shapes.
    #[arg(long, default_value_t = 1)]
    pub count: u64,
    /// Seed of the index and weight draws (same seed → same cohort).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Grid samples per axis over [-1,1]³.
    #[arg(long, default_value_t = DEFAULT_RESOLUTION)]
    pub resolution: usize,
    /// Mesh file format.
    #[arg(long, default_value = "glb", value_parser = parse_format)]
    pub format: MeshFormat,
    /// Coordinates of the written meshes.
    #[arg(long, value_enum, default_value = "mm")]
    pub units: Units,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Compute backend.
    #[arg(long, default_value = "flex")]
    pub backend: Backend,
    /// Surface extraction: `fast` evaluates the network only near the surface, `dense` on
    /// every grid sample (the reference; both give the same mesh).
    #[arg(long, value_enum, default_value = "fast")]
    pub extraction: ExtractionMethod,
}

fn parse_format(s: &str) -> Result<MeshFormat, String> {
    s.parse::<MeshFormat>().map_err(|e| e.to_string())
}

/// Runs `aortagen generate`.
pub fn run(args: GenerateArgs) -> anyhow::Result<()> {
    init_logging();
    ensure!(
        (MIN_RESOLUTION..=MAX_RESOLUTION).contains(&args.resolution),
        "--resolution must be between {MIN_RESOLUTION} and {MAX_RESOLUTION}"
    );
    ensure!(
        args.latent_noise.is_finite() && args.latent_noise >= 0.0,
        "--latent-noise must be a finite number ≥ 0"
    );
    if let Some(m) = args.min_novelty {
        ensure!(
            m.is_finite() && m >= 0.0,
            "--min-novelty must be a finite number ≥ 0"
        );
    }
    let diversity = Diversity {
        selection: args.selection,
        latent_noise: args.latent_noise,
    };
    let weights = match &args.weights {
        Some(text) => Some(parse_weights(text).map_err(|e| anyhow::anyhow!("--weights: {e}"))?),
        None => None,
    };
    let spec = MixSpec {
        arity: args.arity,
        weights,
        weighting: args.weighting,
    };
    let model = LoadedModel::load(&args.model, args.backend)?;
    spec.validate(model.num_shapes())
        .map_err(|e| anyhow::anyhow!("--{}: {e}", e.field()))?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let latents = model.latents();
    let units = match args.units {
        Units::Mm => "mm",
        Units::Unit => "unit",
    };
    let surfaces = training_surfaces(
        &model,
        &latents,
        args.resolution,
        args.extraction,
        &std::sync::atomic::AtomicBool::new(false),
    )
    .context("cannot reconstruct the training shapes for the novelty measure")?;
    let reference = NoveltyReference::new(&surfaces, args.novelty_points)?;
    let attempts = if args.min_novelty.is_some() {
        MAX_REDRAWS + 1
    } else {
        1
    };
    let bar = terminal_bar(args.count, "shapes");
    let mut report = Vec::new();
    for shape in 0..args.count {
        let mut best: Option<(GeneratedShape, Novelty, u32)> = None;
        let mut redraws = 0;
        for attempt in 0..attempts {
            let generated = generate_shape_with(
                &model,
                &latents,
                &spec,
                diversity,
                (args.seed, shape, attempt),
                args.resolution,
                args.extraction,
            )
            .with_context(|| format!("shape {shape}"))?;
            let novelty = reference
                .novelty(&generated.mesh, args.seed ^ shape)
                .with_context(|| format!("shape {shape}: novelty"))?;
            redraws = attempt;
            if best
                .as_ref()
                .is_none_or(|(_, b, _)| novelty.chamfer > b.chamfer)
            {
                best = Some((generated, novelty, attempt));
            }
            if args.min_novelty.is_none_or(|m| novelty.chamfer >= m) {
                break;
            }
        }
        let (generated, novelty, attempt) = best.context("no draw was made")?;
        let novelty_met = args.min_novelty.is_none_or(|m| novelty.chamfer >= m);
        let provenance = Provenance {
            selection: diversity.selection,
            latent_noise: diversity.latent_noise,
            attempt,
            novelty: Some(novelty),
            redraws,
            novelty_met: Some(novelty_met),
            ..Provenance::new(&model, &generated, args.seed, shape, args.resolution, units)
        };
        let mesh = match args.units {
            Units::Mm => generated.mesh_in_mesh_units(),
            Units::Unit => generated.mesh.clone(),
        };
        let meta = MeshMetadata {
            extras: serde_json::to_value(&provenance)?,
            ..MeshMetadata::new(units)
        };
        let stem = args.out.join(format!("shape_{shape:04}"));
        let mesh_path = stem.with_extension(args.format.extension());
        let bytes = write_mesh(&mesh, args.format, &meta)?;
        std::fs::write(&mesh_path, bytes)
            .with_context(|| format!("cannot write {}", mesh_path.display()))?;
        let json_path = stem.with_extension("json");
        std::fs::write(&json_path, serde_json::to_vec_pretty(&provenance)?)
            .with_context(|| format!("cannot write {}", json_path.display()))?;
        let name = &model.manifest.shapes[novelty.nearest].name;
        report.push(format!(
            "shape_{shape:04}: novelty {:.3e} (nearest training shape {} {name}){}{}",
            novelty.chamfer,
            novelty.nearest,
            match redraws {
                0 => String::new(),
                r => format!(", {r} redraws"),
            },
            if novelty_met {
                ""
            } else {
                ", below --min-novelty"
            },
        ));
        match &bar {
            Some(bar) => bar.inc(1),
            None => tracing::info!(
                shape,
                indices = ?provenance.indices,
                weights = ?provenance.weights,
                triangles = mesh.triangles.len(),
                path = %mesh_path.display(),
                "generated"
            ),
        }
    }
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    for line in &report {
        println!("{line}");
    }
    println!(
        "{} shapes from model {} written to {} ({units})",
        args.count,
        model.manifest.model_id(),
        args.out.display()
    );
    Ok(())
}
