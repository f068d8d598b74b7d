//! `aortagen validate`: a generated cohort against a real population — the model's held-out
//! or training shapes, a directory of patient meshes, or a measurements table — with
//! acceptance criteria; prints the figures and the verdict, writes the JSON report and the
//! HTML page (the same report the service's validation job stores).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use anyhow::Context;

use super::progress::{init_logging, terminal_bar};
use crate::stats::bootstrap::{BandTestConfig, DEFAULT_DISCOUNT, DEFAULT_RESAMPLES, Discount};
use crate::validation::measures::MeasureSettings;
use crate::validation::report::ValidationReport;
use crate::validation::shapes::{DEFAULT_POINTS, Progress};
use crate::validation::sources::{
    ModelPopulations, mean_training_radius, model_populations, read_cohort_dir, read_reference_path,
};
use crate::validation::{
    AcceptanceCriteria, Dossier, Newcomers, Population, ShapeInputs, ShapeSettings, Subject,
    ValidationInput, validate,
};

/// Validate a generated cohort against a real population.
#[derive(Debug, clap::Args)]
pub struct ValidateArgs {
    /// Directory written by `aortagen generate` (or any directory of meshes in mm).
    #[arg(long)]
    pub cohort: PathBuf,
    /// The reference: `heldout` or `training` (the --model's shapes), a directory of
    /// meshes in mm, or a measurements table (`.csv`; SIMCor's column names accepted).
    #[arg(long)]
    pub reference: String,
    /// Model directory: its training shapes give DCR and the real-vs-real baseline, its
    /// hash goes into the dossier.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Directory of the model's training data (default: the one its manifest records).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Acceptance criteria as JSON, inline (`{"nna_max": 0.55}`) or a file name.
    #[arg(long)]
    pub criteria: Option<String>,
    /// The context of use, for the dossier.
    #[arg(long)]
    pub context_of_use: Option<String>,
    /// The question of interest, for the dossier.
    #[arg(long)]
    pub question: Option<String>,
    /// Surface samples per shape for the Chamfer distances.
    #[arg(long, default_value_t = DEFAULT_POINTS)]
    pub points: usize,
    /// Common scale of the shape level in mm (default: the model's mean training radius,
    /// else the reference's).
    #[arg(long)]
    pub scale_mm: Option<f64>,
    /// Equal-size subsets for 1-NNA, MMD and COV.
    #[arg(long, default_value_t = crate::shape_metrics::nna::DEFAULT_SUBSETS)]
    pub subsets: usize,
    /// Bootstrap resamples of SIMCor's density-band test.
    #[arg(long, default_value_t = DEFAULT_RESAMPLES)]
    pub resamples: usize,
    /// Uncertainty discount α of the band test: a number, or `variance-ratio`.
    #[arg(long, default_value_t = DEFAULT_DISCOUNT.to_string())]
    pub discount: String,
    /// Seed of the samplings, subsets and resamples.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write the JSON report here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the HTML report here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also write every plot as an SVG file into this directory.
    #[arg(long)]
    pub svg_dir: Option<PathBuf>,
}

/// Runs `aortagen validate`.
pub fn run(args: ValidateArgs) -> anyhow::Result<()> {
    init_logging();
    let criteria = read_criteria(args.criteria.as_deref())?
        .check()
        .map_err(|e| anyhow::anyhow!("--criteria: {e} (rule {})", e.rule))?;
    let discount = parse_discount(&args.discount)?;
    anyhow::ensure!(args.points >= 1, "--points must be at least 1");
    let cohort = read_cohort_dir(&args.cohort)?;
    let model = match &args.model {
        Some(dir) => Some(model_populations(dir, args.data.as_deref())?),
        None => None,
    };
    let (reference, reference_subject, ignored) = reference(&args, model.as_ref())?;
    let reference_is_training = args.reference == "training";
    let training = model.as_ref().map(|m| &m.training);
    let newcomers = match (
        reference_is_training,
        model.as_ref().and_then(|m| m.heldout.as_ref()),
    ) {
        (false, _) => Newcomers::Reference,
        (true, Some(heldout)) => Newcomers::Other(heldout),
        (true, None) => Newcomers::Missing("the model has no held-out shapes".into()),
    };
    let scale_mm = match args.scale_mm {
        Some(s) => s,
        None => model
            .as_ref()
            .map(|m| mean_training_radius(&m.manifest))
            .or_else(|| reference.mean_radius_mm())
            .context("no common scale: give --scale-mm")?,
    };
    anyhow::ensure!(
        scale_mm.is_finite() && scale_mm > 0.0,
        "--scale-mm must be > 0"
    );
    let dossier = Dossier {
        context_of_use: args.context_of_use.clone(),
        question_of_interest: args.question.clone(),
        model_id: model.as_ref().map_or_else(
            || {
                cohort
                    .first_record
                    .as_ref()
                    .map_or("—".into(), |r| r.provenance.model_id.clone())
            },
            |m| m.manifest.model_id().to_owned(),
        ),
        model_sha256: model.as_ref().map(|m| m.manifest.weights.sha256.clone()),
        software_version: crate::VERSION.into(),
        cohort: Subject {
            label: cohort.population.label.clone(),
            id: None,
            kind: "directory".into(),
            shapes: cohort.population.len(),
            seed: cohort
                .first_record
                .as_ref()
                .map(|r| r.provenance.cohort_seed),
            details: serde_json::json!({
                "directory": args.cohort,
                "first_shape": cohort.first_record.as_ref().map(|r| &r.provenance),
            }),
            sha256: None,
        },
        reference: reference_subject,
        criteria: criteria.given.clone(),
        computed_at: crate::validation::report::utc_now(),
    };
    let input = ValidationInput {
        shapes: ShapeInputs {
            cohort: &cohort.population,
            reference: &reference,
            training,
            reference_is_training,
            newcomers,
        },
        shape_settings: ShapeSettings {
            points: args.points,
            scale_mm,
            seed: args.seed,
            subsets: args.subsets,
        },
        measure_settings: MeasureSettings {
            band: BandTestConfig {
                resamples: args.resamples,
                discount,
                seed: args.seed,
            },
            tost_margins: criteria.tost_margins.clone(),
        },
        criteria: &criteria,
        ignored,
        dossier,
    };
    let report = with_progress(input)?;
    print_report(&report);
    write_outputs(&args, &report)
}

/// Runs the validation on a scoped thread while a bar (or log lines) follows the Chamfer
/// distances done.
fn with_progress(input: ValidationInput<'_>) -> anyhow::Result<ValidationReport> {
    let total = input.shapes.pairs();
    let done = AtomicU64::new(0);
    let finished = AtomicBool::new(false);
    let bar = terminal_bar(total, "Chamfer distances");
    let report = std::thread::scope(|scope| {
        let work = scope.spawn(|| {
            let report = validate(input, Progress::counting(&done));
            finished.store(true, Ordering::SeqCst);
            report
        });
        let mut logged = 0;
        while !finished.load(Ordering::SeqCst) {
            std::thread::sleep(Duration::from_millis(200));
            let now = done.load(Ordering::Relaxed);
            match &bar {
                Some(bar) => bar.set_position(now),
                None if now > logged + total / 10 => {
                    tracing::info!(done = now, total, "Chamfer distances");
                    logged = now;
                }
                None => {}
            }
        }
        work.join()
    });
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    report.map_err(|_| anyhow::anyhow!("the validation panicked"))
}

/// The reference population, its dossier entry and the table columns not compared (name,
/// why).
type Reference = (Population, Subject, Vec<(String, String)>);

/// The reference `args` name, read from the model or from files.
fn reference(args: &ValidateArgs, model: Option<&ModelPopulations>) -> anyhow::Result<Reference> {
    let subject = |p: &Population, kind: &str, sha256| Subject {
        label: p.label.clone(),
        id: None,
        kind: kind.into(),
        shapes: p.len(),
        seed: None,
        details: serde_json::json!({ "reference": args.reference }),
        sha256,
    };
    match args.reference.as_str() {
        "training" | "heldout" => {
            let m =
                model.with_context(|| format!("--reference {} needs --model", args.reference))?;
            let p = match args.reference.as_str() {
                "training" => m.training.clone(),
                _ => m
                    .heldout
                    .clone()
                    .context("the model has no held-out shapes (train it with --holdout)")?,
            };
            let s = subject(
                &p,
                &args.reference,
                Some(m.manifest.data.dataset_key.clone()),
            );
            Ok((p, s, Vec::new()))
        }
        path => {
            let files = read_reference_path(Path::new(path))?;
            let s = subject(&files.population, files.kind, Some(files.sha256.clone()));
            Ok((files.population, s, files.ignored))
        }
    }
}

fn read_criteria(text: Option<&str>) -> anyhow::Result<AcceptanceCriteria> {
    let Some(text) = text else {
        return Ok(AcceptanceCriteria::default());
    };
    let json = match text.trim_start().starts_with('{') {
        true => text.to_owned(),
        false => std::fs::read_to_string(text).with_context(|| format!("cannot read {text}"))?,
    };
    serde_json::from_str(&json).context("--criteria is not a valid criteria object")
}

fn parse_discount(text: &str) -> anyhow::Result<Discount> {
    if text == "variance-ratio" {
        return Ok(Discount::VarianceRatio);
    }
    let a: f64 = text
        .parse()
        .context("--discount must be a number or variance-ratio")?;
    anyhow::ensure!(a > 0.0 && a.is_finite(), "--discount must be > 0");
    Ok(Discount::Fixed(a))
}

fn print_report(r: &ValidationReport) {
    println!(
        "{} against {}",
        r.dossier.cohort.label, r.dossier.reference.label
    );
    match &r.shapes {
        Some(s) => {
            println!("shape level ({}):", s.units);
            if let Some(n) = &s.nna {
                println!("  1-NNA {:.3} [{:.3}, {:.3}]", n.mean, n.low, n.high);
            }
            if let Some(c) = &s.coverage {
                println!(
                    "  COV {:.3} [{:.3}, {:.3}]  MMD {:.3e}",
                    c.cov_subsets.mean, c.cov_subsets.low, c.cov_subsets.high, c.mmd_subsets.mean
                );
            }
            if let Some(p) = &s.pairwise {
                println!(
                    "  pairwise median {:.3e} (reference {:.3e}, ratio {:.3})",
                    p.cohort.median, p.reference.median, p.median_ratio
                );
            }
            if let Some(d) = &s.dcr {
                println!(
                    "  DCR median {:.3e} ({} {:.3e}), {} near-copies{}",
                    d.dcr.generated_summary.median,
                    d.newcomers,
                    d.dcr.heldout_summary.median,
                    d.near_copies,
                    if d.flagged { ", FLAGGED" } else { "" }
                );
            }
            if let Some(b) = &s.baseline {
                println!(
                    "  baseline ({}): 1-NNA {:.3}, COV {:.3}, pairwise ratio {:.3}",
                    b.label, b.nna.mean, b.coverage.cov_subsets.mean, b.pairwise_median_ratio
                );
            }
            for (name, why) in &s.not_computed {
                println!("  {name}: not computed ({why})");
            }
        }
        None => println!(
            "shape level not computed: {}",
            r.not_computed.get("shapes").map_or("", String::as_str)
        ),
    }
    println!("features (cohort vs reference: KS p, W₁, band p):");
    for f in &r.features {
        let p = |v: Option<f64>| v.map_or("—".to_owned(), |v| format!("{v:.3}"));
        println!(
            "  {:<16} KS p {}  W₁ {} {}  band p {}",
            f.feature.name(),
            p(f.ks.map(|k| k.p_value)),
            p(f.wasserstein),
            f.unit,
            p(f.density_band.as_ref().map(|b| b.p_value))
        );
    }
    for c in &r.checks {
        let outcome = match c.passed {
            Some(true) => "pass",
            Some(false) => "FAIL",
            None => "not evaluated",
        };
        let feature = c
            .feature
            .as_deref()
            .map(|f| format!(" {f}"))
            .unwrap_or_default();
        println!(
            "check {}{feature} ({}): {outcome}",
            c.criterion, c.requirement
        );
    }
    println!("verdict: {:?}", r.verdict);
}

fn write_outputs(args: &ValidateArgs, report: &ValidationReport) -> anyhow::Result<()> {
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_vec_pretty(report)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("report written to {}", path.display());
    }
    if let Some(path) = &args.out {
        std::fs::write(path, crate::report::validation::validation_html(report))
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("HTML report written to {}", path.display());
    }
    if let Some(dir) = &args.svg_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        for (name, svg) in crate::report::validation::validation_svgs(report) {
            std::fs::write(dir.join(&name), svg).with_context(|| format!("cannot write {name}"))?;
        }
    }
    Ok(())
}
