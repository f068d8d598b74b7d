//! `aortagen report`: a self-contained HTML report (and, optionally, the SVG plots) of a
//! model's reconstruction fidelity or of a directory of meshes (e.g. a generated cohort).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use rayon::prelude::*;

use super::progress::init_logging;
use crate::engine::read_evaluation;
use crate::geometry::chamfer::{DEFAULT_CHAMFER_POINTS, pairwise_chamfer};
use crate::geometry::normalize::normalize_to_unit_ball;
use crate::geometry::sampling::sample_surface;
use crate::report::{Report, Section, footer, render_html, sections};
use crate::sdf::data::read_mesh_directory;
use crate::sdf::inference::evaluation::EvaluationReport;

/// Write an HTML report of a model (`--model`) or of a directory of meshes (`--meshes`).
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("subject").required(true).args(["model", "meshes"])))]
pub struct ReportArgs {
    /// Model directory with an `evaluation.json` (written by `aortagen evaluate --json`).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Evaluation JSON to use instead of MODEL/evaluation.json.
    #[arg(long, requires = "model")]
    pub evaluation: Option<PathBuf>,
    /// Directory of meshes: pairwise Chamfer distances (each mesh in its own unit ball),
    /// areas and volumes.
    #[arg(long)]
    pub meshes: Option<PathBuf>,
    /// Points sampled per surface for the Chamfer distance (`--meshes`).
    #[arg(long, default_value_t = DEFAULT_CHAMFER_POINTS)]
    pub points: usize,
    /// Seed of those samplings.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The HTML file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write each plot as an SVG file into this directory.
    #[arg(long)]
    pub svg_dir: Option<PathBuf>,
}

/// Runs `aortagen report`.
pub fn run(args: ReportArgs) -> anyhow::Result<()> {
    init_logging();
    let report = match (&args.model, &args.meshes) {
        (Some(model), _) => model_report(model, args.evaluation.as_deref())?,
        (None, Some(dir)) => meshes_report(dir, args.points, args.seed)?,
        (None, None) => bail!("give --model or --meshes"),
    };
    std::fs::write(&args.out, render_html(&report))
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    if let Some(dir) = &args.svg_dir {
        write_svgs(dir, &report.sections)?;
    }
    println!(
        "wrote {} ({} plots)",
        args.out.display(),
        report.sections.len()
    );
    Ok(())
}

fn model_report(model: &Path, evaluation: Option<&Path>) -> anyhow::Result<Report> {
    let eval: EvaluationReport = match evaluation {
        Some(file) => serde_json::from_slice(
            &std::fs::read(file).with_context(|| format!("cannot read {}", file.display()))?,
        )
        .with_context(|| format!("{} is not an evaluation report", file.display()))?,
        None => read_evaluation(model).with_context(|| {
            format!(
                "{} has no readable evaluation.json; run `aortagen evaluate --model {0} --json {0}/evaluation.json` first",
                model.display()
            )
        })?,
    };
    let cds: Vec<f64> = eval.shapes.iter().filter_map(|s| s.chamfer).collect();
    let facts = vec![
        ("model".to_owned(), model.display().to_string()),
        ("weights hash".into(), eval.model_id.clone()),
        ("training shapes".into(), eval.shapes.len().to_string()),
        ("failed reconstructions".into(), eval.failures.to_string()),
        (
            "resolution".into(),
            format!("{}³", eval.settings.resolution),
        ),
        (
            "Chamfer points".into(),
            eval.settings.chamfer_points.to_string(),
        ),
    ];
    Ok(Report {
        title: format!("Model {}", model.display()),
        facts,
        sections: vec![sections::reconstruction_cd(
            &cds,
            Some(eval.sampling_floor_median),
        )],
        footer: footer(),
    })
}

fn meshes_report(dir: &Path, points: usize, seed: u64) -> anyhow::Result<Report> {
    let meshes = read_mesh_directory(dir)?;
    if meshes.is_empty() {
        bail!("{} holds no mesh files", dir.display());
    }
    tracing::info!(
        meshes = meshes.len(),
        "sampling surfaces for Chamfer distances"
    );
    let sets: Vec<Vec<[f32; 3]>> = meshes
        .par_iter()
        .enumerate()
        .map(|(i, (_, mesh))| {
            let (unit, _) = normalize_to_unit_ball(mesh);
            sample_surface(&unit, points, seed.wrapping_add(i as u64)).points
        })
        .collect();
    let matrix = pairwise_chamfer(&sets);
    let area: Vec<f64> = meshes.iter().map(|(_, m)| m.area()).collect();
    let volume: Vec<f64> = meshes.iter().map(|(_, m)| m.signed_volume()).collect();
    let facts = vec![
        ("meshes".to_owned(), dir.display().to_string()),
        ("count".into(), meshes.len().to_string()),
        ("Chamfer points".into(), points.to_string()),
    ];
    Ok(Report {
        title: format!("Meshes in {}", dir.display()),
        facts,
        sections: vec![
            sections::pairwise_cd(&sections::upper_triangle(&matrix), None),
            sections::distribution(
                "Surface area",
                "Area of each surface in the files' units.",
                "area",
                &area,
                &[],
            ),
            sections::distribution(
                "Enclosed volume",
                "Volume enclosed by each surface in the files' units.",
                "volume",
                &volume,
                &[],
            ),
        ],
        footer: footer(),
    })
}

fn write_svgs(dir: &Path, sections: &[Section]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    for s in sections {
        let name: String = s
            .heading
            .to_lowercase()
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
            .collect();
        let path = dir.join(format!("{}.svg", name.trim_matches('-')));
        std::fs::write(&path, &s.svg)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
