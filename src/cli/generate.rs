//! `aortagen generate`: new shapes as convex combinations of learned latents.

use std::path::PathBuf;

use anyhow::{Context, ensure};

use super::progress::{init_logging, terminal_bar};
use crate::anatomy::shape::{ShapeAnatomy, measure_shape};
use crate::anatomy::targets::{
    CandidateSource, DEFAULT_MAX_CANDIDATES, MAX_CANDIDATES, Measured, SCREEN_RESOLUTION,
    TargetRange, Targets, check_feasible, guided_pool, parse_target_arg, refine_weights, search,
    training_ranges,
};
use crate::formats::{MeshFormat, MeshMetadata, write_mesh};
use crate::geometry::chamfer::DEFAULT_CHAMFER_POINTS;
use crate::sdf::anchors::{Anchor, AnchorSet};
use crate::sdf::backend::Backend;
use crate::sdf::conditioned::{candidate_mixture, measure_training_shapes};
use crate::sdf::generate::{
    Diversity, GeneratedShape, MAX_REDRAWS, MixSpec, Mixture, Provenance, Selection, Weighting,
    generate_from_mixture, generate_shape_with, parse_weights,
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
    /// A fitted anchor of the model (the `--name` given to `aortagen fit`) forced into every
    /// shape; repeatable, at most --arity of them. Each shape mixes every anchor plus
    /// arity − anchors training shapes drawn as usual; weights (given or drawn) list the
    /// training shapes first, then the anchors in the order given here.
    #[arg(long = "anchor")]
    pub anchors: Vec<String>,
    /// Gaussian noise added to the mixed latent, in training standard deviations (≥ 0).
    #[arg(long, default_value_t = 0.0)]
    pub latent_noise: f64,
    /// Smallest accepted Chamfer distance (unit-ball coordinates) to the nearest training
    /// shape: closer shapes are redrawn up to 10 times, then the most novel draw is kept and
    /// flagged `novelty_met: false` in its provenance.
    #[arg(long)]
    pub min_novelty: Option<f64>,
    /// Target range of an anatomical measurement, `NAME=MIN:MAX` in mm (either bound may be
    /// empty; repeatable), e.g. `--target annulus_mm=23:27`. Names: annulus_mm, sinus_mm,
    /// stj_mm, sinus_height_mm, ascending_mm, length_mm, max_diameter_mm. Each shape then
    /// searches up to --max-candidates mixtures, screened on a 64³ mesh, for one inside
    /// every range: fresh draws, and (with drawn weights) refinements of a missing draw's
    /// weights; when none is inside, the closest is kept and flagged `targets_met: false`.
    #[arg(long = "target", value_parser = parse_target_arg)]
    pub targets: Vec<(String, TargetRange)>,
    /// Most candidates per shape with --target (1–100).
    #[arg(long, default_value_t = DEFAULT_MAX_CANDIDATES)]
    pub max_candidates: u32,
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
    ensure!(
        (1..=MAX_CANDIDATES).contains(&args.max_candidates),
        "--max-candidates must be between 1 and {MAX_CANDIDATES}"
    );
    let targets = match args.targets.is_empty() {
        true => None,
        false => {
            let ranges = args.targets.iter().cloned().collect();
            Some(Targets::parse(&ranges).map_err(|e| anyhow::anyhow!("--target: {e}"))?)
        }
    };
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
    let anchors = match args.anchors.is_empty() {
        true => Vec::new(),
        false => AnchorSet::load(&args.model, &model.manifest)?
            .pick(&args.anchors, args.arity)
            .map_err(|e| anyhow::anyhow!("--anchor: {e}"))?,
    };
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
    let screen_resolution = SCREEN_RESOLUTION.min(args.resolution);
    let (pool, training) = match &targets {
        Some(targets) => {
            let training =
                measure_training_shapes(&model, &latents, SCREEN_RESOLUTION, args.extraction)
                    .context("cannot measure the training shapes")?;
            for (m, range) in targets.iter() {
                if let Some((lo, hi)) = training_ranges(&training, m) {
                    println!(
                        "target {} {range}; training shapes span [{lo:.2}, {hi:.2}] mm",
                        m.name()
                    );
                }
            }
            check_feasible(targets, &training).map_err(|e| anyhow::anyhow!("--target: {e}"))?;
            (guided_pool(targets, &training, args.arity), training)
        }
        None => (Vec::new(), Vec::new()),
    };
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
        let mut searched = None;
        if let Some(targets) = &targets {
            let mut source = TargetedShape {
                model: &model,
                latents: &latents,
                spec: &spec,
                args: &args,
                anchors: &anchors,
                reference: &reference,
                pool: &pool,
                training: &training,
                targets,
                key: (args.seed, shape),
                screen_resolution,
            };
            let outcome = search(
                targets,
                args.max_candidates,
                screen_resolution < args.resolution,
                &mut source,
            )
            .with_context(|| format!("shape {shape}"))?;
            searched = Some((
                outcome.candidates,
                outcome.met,
                outcome.kept.anatomy.ok(),
                outcome.refined,
            ));
            best = Some(outcome.kept.candidate);
        }
        let attempts = if searched.is_some() { 0 } else { attempts };
        for attempt in 0..attempts {
            let generated = generate_shape_with(
                &model,
                &latents,
                &spec,
                diversity,
                &anchors,
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
            candidates: searched.as_ref().map(|s| s.0),
            targets_met: searched.as_ref().map(|s| s.1),
            anatomy: searched.as_ref().and_then(|s| s.2.clone()),
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
        if let (Some(targets), Some((candidates, met, anatomy, refined))) = (&targets, &searched) {
            let values: Vec<String> = targets
                .iter()
                .map(|(m, _)| {
                    let v = anatomy.as_ref().and_then(|a| m.value(a));
                    format!(
                        "{} {}",
                        m.name(),
                        v.map_or("unmeasured".into(), |v| format!("{v:.2}"))
                    )
                })
                .collect();
            let line = report.last_mut().expect("a line was just pushed");
            line.push_str(&format!(
                "; {}; {candidates} candidates ({refined} weight refinements), {}",
                values.join(", "),
                if *met {
                    "targets met"
                } else {
                    "targets NOT met (closest kept)"
                }
            ));
        }
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

/// The candidates of one targeted shape: mixtures drawn (and weight-refined) from the
/// command line's spec, meshed by the loaded model. A spec keeps its draw's attempt, which
/// seeds the latent noise, so a refinement changes only the weights.
struct TargetedShape<'a> {
    model: &'a LoadedModel,
    latents: &'a [Vec<f32>],
    spec: &'a MixSpec,
    args: &'a GenerateArgs,
    anchors: &'a [Anchor],
    reference: &'a NoveltyReference,
    pool: &'a [usize],
    training: &'a [Option<ShapeAnatomy>],
    targets: &'a Targets,
    /// (seed, shape index).
    key: (u64, u64),
    screen_resolution: usize,
}

impl TargetedShape<'_> {
    fn mesh(
        &self,
        (mixture, attempt): &(Mixture, u32),
        resolution: usize,
    ) -> anyhow::Result<GeneratedShape> {
        let (seed, shape) = self.key;
        Ok(generate_from_mixture(
            self.model,
            self.latents,
            mixture.clone(),
            self.args.latent_noise,
            self.anchors,
            (seed, shape, *attempt),
            resolution,
            self.args.extraction,
        )?)
    }
}

impl CandidateSource for TargetedShape<'_> {
    type Spec = (Mixture, u32);
    type Kept = (GeneratedShape, Novelty, u32);
    type Error = anyhow::Error;

    fn draw(&mut self, attempt: u32) -> anyhow::Result<(Mixture, u32)> {
        let (seed, shape) = self.key;
        let key = (seed, shape, attempt);
        let mixture =
            candidate_mixture(self.spec, self.latents, self.args.selection, key, self.pool)?;
        Ok((mixture, attempt))
    }

    /// Only drawn weights are refined: `--weights` and `--weighting equal` are kept.
    fn refine(
        &mut self,
        (mixture, attempt): &(Mixture, u32),
        measured: &ShapeAnatomy,
    ) -> Option<(Mixture, u32)> {
        if self.spec.weights.is_some() || self.spec.weighting != Weighting::Dirichlet {
            return None;
        }
        let parts = mixture.indices.len().saturating_sub(self.anchors.len());
        let weights = refine_weights(
            self.targets,
            self.training,
            &mixture.indices[..parts],
            &mixture.weights,
            measured,
        )?;
        let refined = Mixture {
            indices: mixture.indices.clone(),
            weights,
        };
        Some((refined, *attempt))
    }

    fn screen(&mut self, spec: &(Mixture, u32)) -> anyhow::Result<Result<ShapeAnatomy, String>> {
        let g = self.mesh(spec, self.screen_resolution)?;
        Ok(measure_shape(&g.mesh_in_mesh_units()).map_err(|e| e.to_string()))
    }

    /// Keeps the draw's attempt, which with the weights in the provenance reproduces it.
    fn finalize(
        &mut self,
        _: u32,
        spec: &(Mixture, u32),
    ) -> anyhow::Result<Measured<(GeneratedShape, Novelty, u32)>> {
        let g = self.mesh(spec, self.args.resolution)?;
        let novelty = self.reference.novelty(&g.mesh, self.key.0 ^ self.key.1)?;
        let anatomy = measure_shape(&g.mesh_in_mesh_units()).map_err(|e| e.to_string());
        Ok(Measured {
            rank: novelty.chamfer,
            accept: self.args.min_novelty.is_none_or(|m| novelty.chamfer >= m),
            candidate: (g, novelty, spec.1),
            anatomy,
        })
    }
}
