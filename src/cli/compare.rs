//! `aortagen compare`: the diversity of several generated cohorts side by side — pairwise
//! Chamfer distances within each cohort (the seed paper's Fig. 3) and each shape's distance
//! to its nearest training shape — as an HTML report, SVG plots and JSON numbers.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use anyhow::{Context, bail, ensure};
use rayon::prelude::*;
use serde::Serialize;

use super::progress::init_logging;
use crate::cohort::ShapeRecord;
use crate::geometry::TriMesh;
use crate::geometry::chamfer::{DEFAULT_CHAMFER_POINTS, pairwise_chamfer};
use crate::geometry::sampling::sample_surface;
use crate::report::plot::{Series, overlay_svg};
use crate::report::sections::{CD_LABEL, upper_triangle};
use crate::report::{Report, Section, footer, render_html};
use crate::sdf::backend::Backend;
use crate::sdf::data::read_mesh_directory;
use crate::sdf::inference::evaluation::{CHAMFER_UNITS, quantile};
use crate::sdf::inference::novelty::training_surfaces;
use crate::sdf::inference::reconstruct::ExtractionMethod;
use crate::sdf::store::LoadedModel;

/// Compare cohorts written by `aortagen generate` (each in its own directory).
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// A cohort as `LABEL=DIR`; repeat for each cohort, in the order to show them.
    #[arg(long = "cohort", required = true, value_parser = parse_cohort)]
    pub cohorts: Vec<(String, PathBuf)>,
    /// Also show the model's reconstructions of its own training shapes as a first series:
    /// the diversity of the data the cohorts were drawn from.
    #[arg(long)]
    pub training_model: Option<PathBuf>,
    /// Grid resolution of those reconstructions (use the cohorts' resolution).
    #[arg(long, default_value_t = 128)]
    pub resolution: usize,
    /// Points sampled per surface for the pairwise Chamfer distances.
    #[arg(long, default_value_t = DEFAULT_CHAMFER_POINTS)]
    pub points: usize,
    /// Seed of those samplings.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The HTML file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the numbers as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also write the two plots as SVG files into this directory.
    #[arg(long)]
    pub svg_dir: Option<PathBuf>,
}

fn parse_cohort(text: &str) -> Result<(String, PathBuf), String> {
    match text.split_once('=') {
        Some((label, dir)) if !label.trim().is_empty() && !dir.is_empty() => {
            Ok((label.trim().to_owned(), PathBuf::from(dir)))
        }
        _ => Err(format!("expected LABEL=DIR, got {text:?}")),
    }
}

/// Summary of one distribution.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Summary {
    /// Values summarised.
    pub n: usize,
    /// Mean.
    pub mean: f64,
    /// Standard deviation (population).
    pub std: f64,
    /// 10th percentile.
    pub p10: f64,
    /// Median.
    pub median: f64,
    /// 90th percentile.
    pub p90: f64,
}

impl Summary {
    fn of(values: &[f64]) -> Option<Self> {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let mean = v.iter().sum::<f64>() / n as f64;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        Some(Self {
            n,
            mean,
            std: var.sqrt(),
            p10: quantile(&v, 0.1),
            median: quantile(&v, 0.5),
            p90: quantile(&v, 0.9),
        })
    }
}

/// One cohort's numbers.
#[derive(Debug, Clone, Serialize)]
pub struct CohortDiversity {
    /// Label given on the command line.
    pub label: String,
    /// Directory read.
    pub dir: PathBuf,
    /// Shapes read.
    pub shapes: usize,
    /// Pairwise Chamfer distances (each unordered pair once).
    pub pairwise: Option<Summary>,
    /// Distance of each shape to its nearest training shape.
    pub novelty: Option<Summary>,
    /// Distinct training shapes named as nearest.
    pub distinct_nearest: usize,
    /// The raw values, for plots made elsewhere.
    #[serde(skip)]
    pairwise_values: Vec<f64>,
    #[serde(skip)]
    novelty_values: Vec<f64>,
}

/// Runs `aortagen compare`.
pub fn run(args: CompareArgs) -> anyhow::Result<()> {
    init_logging();
    ensure!(args.points > 0, "--points must be at least 1");
    let mut cohorts = Vec::new();
    if let Some(model) = &args.training_model {
        tracing::info!(model = %model.display(), "reconstructing the training shapes");
        let loaded = LoadedModel::load(model, Backend::default())?;
        let surfaces = training_surfaces(
            &loaded,
            &loaded.latents(),
            args.resolution,
            ExtractionMethod::Fast,
            &AtomicBool::new(false),
        )?;
        cohorts.push(diversity_of(
            "training shapes",
            model,
            &surfaces,
            Vec::new(),
            args.points,
            args.seed,
        )?);
    }
    for (label, dir) in &args.cohorts {
        tracing::info!(cohort = %label, dir = %dir.display(), "reading and measuring");
        cohorts.push(measure_cohort(label, dir, args.points, args.seed)?);
    }
    let report = comparison_report(&cohorts);
    std::fs::write(&args.out, render_html(&report))
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_vec_pretty(&cohorts)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    if let Some(dir) = &args.svg_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        for (section, file) in report.sections.iter().zip(["pairwise-cd", "novelty-cd"]) {
            let path = dir.join(format!("{file}.svg"));
            std::fs::write(&path, &section.svg)
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
    }
    for c in &cohorts {
        let median = |s: &Option<Summary>| s.as_ref().map_or(f64::NAN, |s| s.median);
        println!(
            "{:<16} {:>4} shapes  pairwise median {:.4e}  novelty median {:.4e}  nearest: {} distinct",
            c.label,
            c.shapes,
            median(&c.pairwise),
            median(&c.novelty),
            c.distinct_nearest
        );
    }
    println!("wrote {}", args.out.display());
    Ok(())
}

/// Reads a cohort directory: its meshes (brought into the model's unit ball through each
/// shape's provenance, so distances match the service's) and their recorded novelty.
pub fn measure_cohort(
    label: &str,
    dir: &Path,
    points: usize,
    seed: u64,
) -> anyhow::Result<CohortDiversity> {
    let meshes = read_mesh_directory(dir)?;
    let mut unit: Vec<TriMesh> = Vec::with_capacity(meshes.len());
    let mut novelty = Vec::new();
    let mut nearest = std::collections::BTreeSet::new();
    for (name, mesh) in &meshes {
        let provenance = read_provenance(dir, name)?;
        unit.push(match provenance.units.as_str() {
            "unit" => mesh.clone(),
            "mm" => provenance.transform.mesh_to_unit(mesh),
            other => bail!("{name}: unknown units {other:?} in its provenance"),
        });
        novelty.push(provenance.novelty.chamfer);
        nearest.insert(provenance.novelty.nearest);
    }
    let mut measured = diversity_of(label, dir, &unit, novelty, points, seed)?;
    measured.distinct_nearest = nearest.len();
    Ok(measured)
}

/// Pairwise distances among unit-ball meshes, with their novelty values if known.
fn diversity_of(
    label: &str,
    dir: &Path,
    unit: &[TriMesh],
    novelty: Vec<f64>,
    points: usize,
    seed: u64,
) -> anyhow::Result<CohortDiversity> {
    let sets: Vec<Vec<[f32; 3]>> = unit
        .par_iter()
        .enumerate()
        .map(|(i, mesh)| sample_surface(mesh, points, seed.wrapping_add(i as u64)).points)
        .collect();
    if let Some(i) = sets.iter().position(Vec::is_empty) {
        bail!("{}: shape {i} has no surface to sample", dir.display());
    }
    let pairwise_values = upper_triangle(&pairwise_chamfer(&sets));
    Ok(CohortDiversity {
        label: label.to_owned(),
        dir: dir.to_path_buf(),
        shapes: unit.len(),
        pairwise: Summary::of(&pairwise_values),
        novelty: Summary::of(&novelty),
        distinct_nearest: 0,
        pairwise_values,
        novelty_values: novelty,
    })
}

/// The provenance JSON `aortagen generate` writes beside each mesh.
fn read_provenance(dir: &Path, mesh_name: &str) -> anyhow::Result<ShapeRecord> {
    let stem = Path::new(mesh_name)
        .file_stem()
        .context("mesh file without a name")?;
    let path = dir.join(stem).with_extension("json");
    let bytes = std::fs::read(&path).with_context(|| {
        format!(
            "cannot read {} (the provenance `aortagen generate` writes beside each mesh)",
            path.display()
        )
    })?;
    serde_json::from_slice(&bytes)
        .with_context(|| format!("{} is not a provenance", path.display()))
}

fn comparison_report(cohorts: &[CohortDiversity]) -> Report {
    let series = |pick: fn(&CohortDiversity) -> &Vec<f64>| -> Vec<Series> {
        cohorts
            .iter()
            .map(|c| Series {
                name: c.label.clone(),
                values: pick(c).clone(),
            })
            .collect()
    };
    let rows = |pick: fn(&CohortDiversity) -> &Option<Summary>| -> Vec<(String, String)> {
        cohorts
            .iter()
            .map(|c| {
                let text = pick(c).as_ref().map_or("—".to_owned(), |s| {
                    format!(
                        "median {:.3e}, mean {:.3e} ± {:.3e}",
                        s.median, s.mean, s.std
                    )
                });
                (c.label.clone(), text)
            })
            .collect()
    };
    let pairwise = Section {
        heading: "Pairwise Chamfer distance within each cohort".into(),
        caption: format!(
            "Every unordered pair of shapes of a cohort; a distribution further right is a more \
             diverse cohort. {CHAMFER_UNITS}."
        ),
        svg: overlay_svg(
            "Pairwise Chamfer distance",
            CD_LABEL,
            &series(|c| &c.pairwise_values),
        ),
        rows: rows(|c| &c.pairwise),
    };
    let novelty = Section {
        heading: "Novelty: distance to the nearest training shape".into(),
        caption: format!(
            "For each generated shape, the Chamfer distance to the closest reconstruction of a \
             training shape; values near the reconstruction error mean near-copies. \
             {CHAMFER_UNITS}."
        ),
        svg: overlay_svg("Novelty", CD_LABEL, &series(|c| &c.novelty_values)),
        rows: rows(|c| &c.novelty),
    };
    Report {
        title: "Cohort diversity".into(),
        facts: cohorts
            .iter()
            .map(|c| {
                (
                    c.label.clone(),
                    format!("{} shapes in {}", c.shapes, c.dir.display()),
                )
            })
            .collect(),
        sections: vec![pairwise, novelty],
        footer: footer(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_matches_hand_computed_statistics() {
        let s = Summary::of(&[4.0, 1.0, f64::NAN, 3.0, 2.0]).unwrap();
        assert_eq!(s.n, 4);
        assert!((s.mean - 2.5).abs() < 1e-12);
        assert!((s.std - 1.25f64.sqrt()).abs() < 1e-12);
        assert!((s.median - 2.5).abs() < 1e-12);
        assert!(s.p10 >= 1.0 && s.p10 < s.median && s.p90 > s.median && s.p90 <= 4.0);
        assert!(Summary::of(&[f64::NAN]).is_none());
    }

    #[test]
    fn cohort_arguments_need_a_label_and_a_directory() {
        assert_eq!(
            parse_cohort("arity 2=/tmp/a").unwrap(),
            ("arity 2".to_owned(), PathBuf::from("/tmp/a"))
        );
        for bad in ["/tmp/a", "=/tmp/a", "k2="] {
            assert!(parse_cohort(bad).is_err(), "{bad}");
        }
    }
}
