//! `aortagen generate`: a cohort drawn by the same pipeline the service runs
//! ([`crate::cohort`]), so a request gives the same shapes here as through the API. Each
//! shape is written as a mesh file with its record (`shape_NNNN.json`) beside it.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::{Context, bail};

use super::progress::{init_logging, terminal_bar};
use super::simulate::{self, GenerateSimulation, SimulationFlags, write_surface};
use crate::cohort::targets::feasibility::training_ranges;
use crate::cohort::targets::{DEFAULT_MAX_CANDIDATES, TargetRange, parse_target_arg};
use crate::cohort::weights::parse_weights;
use crate::cohort::{
    CohortFields, CohortGenerator, CohortPlan, CohortRequest, CohortSetup, CohortShape,
    CovarianceEstimate, DEFAULT_RESOLUTION, EngineHandle, LatentSource, ModelLatents, RequestError,
    RequestLimits, SamplerFields, SamplerKind, Selection, ShapeRecord, Weighting,
};
use crate::engine::{AnchorLatent, Engine, SdfEngine};
use crate::formats::{MeshFormat, MeshMetadata, write_mesh};
use crate::geometry::chamfer::DEFAULT_CHAMFER_POINTS;
use crate::sdf::backend::Backend;
use crate::sdf::inference::reconstruct::ExtractionMethod;
use crate::sdf::store::anchors::AnchorSet;
use crate::sdf::store::read_manifest;

/// Coordinates of the written meshes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Units {
    /// The training meshes' own units (millimetres for SynthAorta and the parametric roots),
    /// through the blended unit-ball transform.
    Mm,
    /// Unit-ball coordinates, as the model sees them.
    Unit,
}

impl Units {
    fn name(self) -> &'static str {
        match self {
            Self::Mm => "mm",
            Self::Unit => "unit",
        }
    }
}

/// Write a cohort of generated shapes (mesh + record JSON each).
#[derive(Debug, clap::Args)]
pub struct GenerateArgs {
    /// Model directory written by `aortagen train`.
    #[arg(long)]
    pub model: PathBuf,
    /// Shapes combined per generated shape, anchors included (k ≥ 2; required by the convex
    /// sampler; with a density sampler 1 + the anchors, and may be left out).
    #[arg(long)]
    pub arity: Option<usize>,
    /// How latents are drawn.
    #[command(flatten)]
    pub sampler: SamplerArgs,
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
    /// flagged `novelty_met: false` in its record.
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
    /// Seed of the cohort (same seed → same cohort, here and through the API).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Grid samples per axis over [-1,1]³ (32–1024).
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
    /// Simulation meshes beside the shapes.
    #[command(flatten)]
    pub simulation: GenerateSimulation,
}

/// The sampler flags of `aortagen generate`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct SamplerArgs {
    /// How latents are drawn: `convex` combinations of --arity training latents, or a
    /// density model of the training latents and their transforms: `pca-gaussian` (a
    /// Gaussian in the principal components) or `pca-mixture` (a Gaussian mixture on the
    /// leading whitened components).
    #[arg(long = "sampler", value_enum, default_value = "convex")]
    pub kind: SamplerKind,
    /// pca-gaussian: truncate each mode's normal variate at ±C (redrawn beyond).
    #[arg(long, value_name = "C")]
    pub truncation: Option<f64>,
    /// pca-gaussian: scale on every mode's standard deviation (default 1).
    #[arg(long)]
    pub sigma_scale: Option<f64>,
    /// pca-gaussian: how the covariance is estimated: `sample` (default) or `ledoit-wolf`
    /// (shrunk towards a multiple of the identity by the estimated intensity).
    #[arg(long, value_enum)]
    pub covariance: Option<CovarianceEstimate>,
    /// pca-gaussian: shrink the sample covariance towards a multiple of the identity by
    /// this intensity in [0, 1], keeping the total variance.
    #[arg(long, value_name = "RHO")]
    pub shrinkage: Option<f64>,
    /// Density samplers: keep the fewest modes explaining this share of the variance (0–1].
    #[arg(long)]
    pub variance_share: Option<f64>,
    /// pca-mixture: exactly this many components.
    #[arg(long)]
    pub components: Option<i64>,
    /// pca-mixture: choose the components by BIC from 1 to this many (default 4).
    #[arg(long)]
    pub max_components: Option<i64>,
    /// pca-mixture: leading principal modes the mixture models (default 4).
    #[arg(long)]
    pub mixture_modes: Option<i64>,
    /// Density samplers: fit the density to the `training` latents (default) or to the
    /// training shapes `refitted` with the network frozen (`aortagen refit` first).
    #[arg(long, value_enum, value_name = "SOURCE")]
    pub latents: Option<LatentSource>,
}

impl SamplerArgs {
    /// The request's `sampler` (none for the default convex sampler without parameters).
    pub fn fields(&self) -> Option<SamplerFields> {
        let fields = SamplerFields {
            kind: self.kind,
            truncation: self.truncation,
            sigma_scale: self.sigma_scale,
            covariance: self.covariance,
            shrinkage: self.shrinkage,
            variance_share: self.variance_share,
            components: self.components,
            max_components: self.max_components,
            mixture_modes: self.mixture_modes,
            latents: self.latents,
        };
        (fields != SamplerFields::default()).then_some(fields)
    }
}

fn parse_format(s: &str) -> Result<MeshFormat, String> {
    s.parse::<MeshFormat>().map_err(|e| e.to_string())
}

impl GenerateArgs {
    /// The request the flags describe, in the pipeline's raw form.
    fn fields(&self) -> anyhow::Result<CohortFields<String>> {
        let weights = match &self.weights {
            Some(text) => Some(parse_weights(text).map_err(|e| anyhow::anyhow!("--weights: {e}"))?),
            None => None,
        };
        let targeted = !self.targets.is_empty();
        Ok(CohortFields {
            count: i64::try_from(self.count).unwrap_or(i64::MAX),
            arity: self.arity.map(|a| i64::try_from(a).unwrap_or(i64::MAX)),
            sampler: self.sampler.fields(),
            weights,
            weighting: Some(self.weighting),
            seed: Some(self.seed),
            resolution: Some(i64::try_from(self.resolution).unwrap_or(i64::MAX)),
            latent_noise: Some(self.latent_noise),
            selection: Some(self.selection),
            min_novelty: self.min_novelty,
            targets: targeted.then(|| self.targets.iter().cloned().collect()),
            max_candidates: targeted.then_some(i64::from(self.max_candidates)),
            anchors: (!self.anchors.is_empty()).then(|| self.anchors.clone()),
        })
    }
}

/// A request error in the words of the command line: the flag instead of the field.
fn flag_error(e: RequestError) -> anyhow::Error {
    let field = e.field.as_str();
    let flag = match field.split(['.', '[']).next().unwrap_or(field) {
        "targets" => "--target".to_owned(),
        "anchors" => "--anchor".to_owned(),
        "sampler" => match field.split_once('.') {
            Some((_, parameter)) => format!("--{}", parameter.replace('_', "-")),
            None => "--sampler".to_owned(),
        },
        name => format!("--{}", name.replace('_', "-")),
    };
    anyhow::anyhow!("{flag}: {} (rule {})", e.message, e.rule)
}

/// Runs `aortagen generate`.
pub fn run(args: GenerateArgs) -> anyhow::Result<()> {
    init_logging();
    let simulation = args.simulation.flags()?;
    if simulation.is_some() && args.units == Units::Unit {
        bail!("--simulation needs --units mm: simulation meshes are made in mm");
    }
    let request = CohortRequest::parse(args.fields()?, RequestLimits::NONE, || args.seed)
        .map_err(flag_error)?;
    let engine: Arc<dyn Engine> = Arc::new(
        SdfEngine::new(args.backend)
            .with_extraction(args.extraction)
            .with_chamfer_points(args.novelty_points),
    );
    let info = engine.model_info(&args.model)?;
    let count = info.training_shape_count();
    request.check_model(&info).map_err(flag_error)?;
    let manifest = read_manifest(&args.model)?;
    let anchors = anchor_latents(&args.model, &request)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let cancel = Arc::new(AtomicBool::new(false));
    tracing::info!(
        resolution = request.resolution,
        shapes = count,
        "reconstructing the training shapes to measure novelty against"
    );
    let setup = CohortSetup::compute(&*engine, &args.model, &request, count, &cancel)?;
    print_target_ranges(&request, &setup);
    let latents = ModelLatents::read(&*engine, &args.model, &request, count, None)?;
    let plan = CohortPlan::new(&request, count, latents.as_ref(), anchors)?;
    if let Some(sampler) = &plan.sampler {
        let s = sampler.summary();
        println!(
            "sampler {}: {} modes ({:.1} % of the variance), {} component(s), shrinkage {:.3}",
            args.sampler.kind.name(),
            s.modes,
            100.0 * s.explained_share,
            s.components,
            s.shrinkage
        );
    }
    let handle = EngineHandle {
        engine,
        model_dir: args.model.clone(),
        model_id: manifest.model_id().to_owned(),
        cancel,
    };
    let generator = CohortGenerator::new(handle, plan, &request, setup)?;
    let names: Vec<String> = manifest.shapes.iter().map(|s| s.name.clone()).collect();
    let writer = ShapeWriter {
        args: &args,
        simulation,
        model_sha256: &manifest.weights.sha256,
        names: &names,
    };
    let bar = terminal_bar(u64::from(request.count), "shapes");
    let mut report = Vec::new();
    generator.run(0..u64::from(request.count), |shape| -> anyhow::Result<()> {
        let path = writer.write(&shape)?;
        report.push(writer.report_line(&shape, &request));
        match &bar {
            Some(bar) => bar.inc(1),
            None => tracing::info!(
                shape = shape.index,
                indices = ?shape.spec.training_indices,
                weights = ?shape.spec.weights,
                triangles = shape.shape.mesh_unit.triangle_count(),
                path = %path.display(),
                "generated"
            ),
        }
        Ok(())
    })?;
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    for line in &report {
        println!("{line}");
    }
    println!(
        "{} shapes from model {} written to {} ({})",
        request.count,
        manifest.model_id(),
        args.out.display(),
        args.units.name()
    );
    Ok(())
}

/// The request's anchors, by name, from the model's `anchors.json`.
fn anchor_latents(
    dir: &Path,
    request: &CohortRequest<String>,
) -> anyhow::Result<Vec<AnchorLatent>> {
    if request.anchors.is_empty() {
        return Ok(Vec::new());
    }
    let manifest = read_manifest(dir)?;
    let picked = AnchorSet::load(dir, &manifest)?
        .pick(&request.anchors, request.arity)
        .map_err(|e| anyhow::anyhow!("--anchor: {e}"))?;
    Ok(picked
        .into_iter()
        .map(|a| AnchorLatent {
            name: a.name,
            latent: a.latent,
            transform: a.transform,
        })
        .collect())
}

/// Prints each target beside the range the training shapes span.
fn print_target_ranges(request: &CohortRequest<String>, setup: &CohortSetup) {
    let (Some(search), Some(training)) = (&request.targets, &setup.training) else {
        return;
    };
    for (m, range) in search.targets.iter() {
        if let Some((lo, hi)) = training_ranges(&training.shapes, m) {
            println!(
                "target {} {range}; training shapes span [{lo:.2}, {hi:.2}] mm",
                m.name()
            );
        }
    }
}

/// Writes generated shapes with their records.
struct ShapeWriter<'a> {
    args: &'a GenerateArgs,
    simulation: Option<SimulationFlags>,
    model_sha256: &'a str,
    names: &'a [String],
}

impl ShapeWriter<'_> {
    /// Writes `shape_NNNN.<format>` and `shape_NNNN.json`; returns the mesh's path.
    fn write(&self, shape: &CohortShape) -> anyhow::Result<PathBuf> {
        let units = self.args.units;
        let record = ShapeRecord::new(shape, self.model_sha256, self.names, units.name());
        let mesh = match units {
            Units::Mm => shape
                .shape
                .transform
                .mesh_to_mesh_units(&shape.shape.mesh_unit),
            Units::Unit => shape.shape.mesh_unit.clone(),
        };
        let meta = MeshMetadata {
            extras: serde_json::to_value(&record)?,
            ..MeshMetadata::new(units.name())
        };
        let stem = self.args.out.join(format!("shape_{:04}", shape.index));
        let mesh_path = stem.with_extension(self.args.format.extension());
        let bytes = write_mesh(&mesh, self.args.format, &meta)?;
        std::fs::write(&mesh_path, bytes)
            .with_context(|| format!("cannot write {}", mesh_path.display()))?;
        let json_path = stem.with_extension("json");
        std::fs::write(&json_path, serde_json::to_vec_pretty(&record)?)
            .with_context(|| format!("cannot write {}", json_path.display()))?;
        if let Some(flags) = &self.simulation {
            let source = mesh_path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned());
            // A shape without usable openings is reported and the cohort goes on.
            match write_surface(&source.unwrap_or_default(), &mesh, &stem, flags) {
                Ok(out) => eprintln!("{}", simulate::to_text(&out)),
                Err(e) => eprintln!("shape_{:04}: {e:#}", shape.index),
            }
        }
        Ok(mesh_path)
    }

    /// One line of the summary printed at the end.
    fn report_line(&self, shape: &CohortShape, request: &CohortRequest<String>) -> String {
        let novelty = shape.novelty;
        let name = self.names.get(novelty.nearest).map_or("", String::as_str);
        let mut line = format!(
            "shape_{:04}: novelty {:.3e} (nearest training shape {} {name}){}{}",
            shape.index,
            novelty.chamfer,
            novelty.nearest,
            match shape.redraws {
                0 => String::new(),
                r => format!(", {r} redraws"),
            },
            if shape.novelty_met {
                ""
            } else {
                ", below --min-novelty"
            },
        );
        let (Some(search), Some(candidates), Some(met)) = (
            &request.targets,
            shape.provenance.candidates,
            shape.provenance.targets_met,
        ) else {
            return line;
        };
        let anatomy = shape.anatomy.as_ref().ok();
        let values: Vec<String> = search
            .targets
            .iter()
            .map(|(m, _)| {
                let v = anatomy.and_then(|a| m.value(a));
                let v = v.map_or("unmeasured".into(), |v| format!("{v:.2}"));
                format!("{} {v}", m.name())
            })
            .collect();
        line.push_str(&format!(
            "; {}; {candidates} candidates ({} weight refinements), {}",
            values.join(", "),
            shape.refinements.unwrap_or(0),
            if met {
                "targets met"
            } else {
                "targets NOT met (closest kept)"
            }
        ));
        line
    }
}
