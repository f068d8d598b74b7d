//! Validation with known answers, on the parametric generator (shapes with known
//! parameters, no training): two independent draws of one parameter distribution pass
//! (1-NNA near 0.5, no feature rejected by KS); a draw with annuli 3 mm larger fails TOST
//! at a 2 mm margin and KS on the annulus; a cohort of copies of the training shapes sits
//! at the sampling floor and is flagged. Also the command line on directories and on a
//! SIMCor-style table.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use aortagen::anatomy::measurement::Measurement;
use aortagen::geometry::TriMesh;
use aortagen::stats::bootstrap::{BandTestConfig, Discount};
use aortagen::synth::{build_root, params_for};
use aortagen::validation::measures::MeasureSettings;
use aortagen::validation::{
    AcceptanceCriteria, Dossier, Feature, Newcomers, Population, Progress, ShapeInputs,
    ShapeSettings, ValidationInput, ValidationReport, Verdict, validate,
};

/// Shapes per parametric draw: enough for KS to see a 3 mm shift of a 9 mm-wide uniform
/// annulus (D ≈ 0.33 against a 5 % critical value of about 0.25 at 60 + 60).
const N: usize = 60;
const ANNULUS: Feature = Feature::Anatomy(Measurement::Annulus);

/// `n` closed parametric roots of draw `seed`, annuli widened by `shift` mm.
fn roots(seed: u64, n: usize, shift: f64) -> Vec<(String, TriMesh)> {
    (0..n as u64)
        .map(|i| {
            let mut p = params_for(seed, i);
            p.annulus_diameter_mm += shift;
            if p.validate().is_err() {
                // The sinus must stay wider than the annulus.
                p.sinus_diameter_mm += shift;
            }
            let mesh = build_root(&p, true).expect("widened roots stay valid");
            (format!("root_{seed}_{i}"), mesh)
        })
        .collect()
}

fn population(label: &str, seed: u64, n: usize, shift: f64) -> Population {
    Population::from_meshes(label, roots(seed, n, shift))
}

/// Validates `cohort` against `reference` (new patients for DCR) with `criteria`.
fn run(
    cohort: &Population,
    reference: &Population,
    training: Option<&Population>,
    criteria: AcceptanceCriteria,
) -> ValidationReport {
    run_counting(
        cohort,
        reference,
        training,
        criteria,
        Progress::counting(&AtomicU64::new(0)),
    )
}

/// [`run`] reporting to `progress`.
fn run_counting(
    cohort: &Population,
    reference: &Population,
    training: Option<&Population>,
    criteria: AcceptanceCriteria,
    progress: Progress<'_>,
) -> ValidationReport {
    let criteria = criteria.check().unwrap();
    let input = ValidationInput {
        shapes: ShapeInputs {
            cohort,
            reference,
            training,
            reference_is_training: false,
            newcomers: Newcomers::Reference,
        },
        shape_settings: ShapeSettings {
            points: 1_000,
            scale_mm: 40.0,
            seed: 3,
            subsets: 50,
        },
        measure_settings: MeasureSettings {
            band: BandTestConfig {
                resamples: 300,
                discount: Discount::Fixed(0.8),
                seed: 3,
            },
            tost_margins: criteria.tost_margins.clone(),
        },
        criteria: &criteria,
        ignored: Vec::new(),
        dossier: Dossier::default(),
    };
    validate(input, progress)
}

fn feature(r: &ValidationReport, f: Feature) -> &aortagen::validation::measures::FeatureComparison {
    r.features
        .iter()
        .find(|c| c.feature == f)
        .expect("feature compared")
}

#[test]
fn two_draws_of_one_distribution_pass_and_larger_annuli_fail_tost_and_ks() {
    let a = population("draw A", 1, N, 0.0);
    let b = population("draw B", 2, N, 0.0);
    let family = Feature::ALL.len() as f64;
    // Bonferroni: under the null, no feature of nine rejects at 0.05 / 9 with probability
    // at least 95 %.
    let same = run(
        &a,
        &b,
        None,
        AcceptanceCriteria {
            nna_max: Some(0.7),
            ks_p_min: Some(0.05 / family),
            ..Default::default()
        },
    );
    let nna = same.shapes.as_ref().unwrap().nna.as_ref().unwrap();
    // 1-NNA of two samples of one law has sd ≈ √(0.25 / 120) ≈ 0.046.
    assert!((nna.mean - 0.5).abs() < 0.15, "1-NNA {}", nna.mean);
    assert!(same.features.len() >= 5, "{:?}", same.not_compared);
    assert_eq!(same.verdict, Verdict::Pass, "{:#?}", same.checks);

    let wide = population("draw B, annuli + 3 mm", 2, N, 3.0);
    let shifted = run(
        &wide,
        &a,
        None,
        AcceptanceCriteria {
            ks_p_min: Some(0.05),
            tost_margin_mm: Some([("annulus_mm".to_owned(), 2.0)].into()),
            features: Some(vec!["annulus_mm".into()]),
            ..Default::default()
        },
    );
    let annulus = feature(&shifted, ANNULUS);
    let difference =
        annulus.cohort.as_ref().unwrap().mean - annulus.reference.as_ref().unwrap().mean;
    assert!(
        (2.0..4.0).contains(&difference),
        "measured shift {difference} mm"
    );
    assert!(annulus.ks.unwrap().p_value < 0.05, "{:?}", annulus.ks);
    let tost = annulus.equivalence.as_ref().unwrap();
    assert!(!tost.equivalent && tost.test.ci90.1 > 2.0, "{tost:?}");
    assert_eq!(shifted.verdict, Verdict::Fail);
    let failed: Vec<&str> = shifted
        .checks
        .iter()
        .filter(|c| c.passed == Some(false))
        .map(|c| c.criterion.as_str())
        .collect();
    assert_eq!(failed, ["ks_p_min", "tost_margin_mm"]);
}

#[test]
fn copies_of_the_training_shapes_sit_at_the_sampling_floor_and_are_flagged() {
    let n = 12;
    let training = population("training", 5, n, 0.0);
    let copies = Population {
        label: "copies".into(),
        ..training.clone()
    };
    let newcomers = population("new patients", 6, n, 0.0);
    let report = run(
        &copies,
        &newcomers,
        Some(&training),
        AcceptanceCriteria {
            dcr_ratio_min: Some(1.0),
            no_near_copies: Some(true),
            ..Default::default()
        },
    );
    let level = report.shapes.as_ref().unwrap();
    let dcr = level.dcr.as_ref().unwrap();
    let floor = level.sampling_floor;
    // A copy's nearest training shape is itself, sampled anew: the sampling floor.
    assert!(
        dcr.dcr.generated_summary.median < 1.5 * floor,
        "{} vs floor {floor}",
        dcr.dcr.generated_summary.median
    );
    // New patients of the same law sit about three floors away at 1,000 points.
    assert!(
        dcr.dcr.heldout_summary.median > 2.0 * floor,
        "new patients {} vs floor {floor}",
        dcr.dcr.heldout_summary.median
    );
    assert_eq!(dcr.near_copies, n);
    assert!(dcr.flagged);
    assert_eq!(report.verdict, Verdict::Fail);
    // Copies of the training set against the training set: 1-NNA far below 0.5.
    let self_report = run(
        &copies,
        &training,
        Some(&training),
        AcceptanceCriteria::default(),
    );
    let nna = self_report.shapes.unwrap().nna.unwrap();
    assert!(
        nna.mean < 0.2,
        "copies are told apart only by sampling noise: {}",
        nna.mean
    );
}

#[test]
fn a_cov_margin_accepts_a_cohort_that_far_below_the_baseline_and_no_further() {
    let cohort = population("cohort", 51, 16, 0.0);
    let reference = population("reference", 52, 8, 0.0);
    let training = population("training", 53, 16, 0.0);
    let report = run(
        &cohort,
        &reference,
        Some(&training),
        AcceptanceCriteria::default(),
    );
    let mut level = report.shapes.unwrap();
    // Pin the figures so that the cohort sits 0.04 below the baseline.
    level.baseline.as_mut().unwrap().coverage.cov_subsets.mean = 0.55;
    level.coverage.as_mut().unwrap().cov_subsets.mean = 0.51;
    let cov_check = |criteria: AcceptanceCriteria| {
        let criteria = criteria.check().unwrap();
        let checks = aortagen::validation::criteria::evaluate(&criteria, Ok(&level), &[]);
        let cov: Vec<_> = checks
            .into_iter()
            .filter(|c| c.criterion == "cov_at_least_baseline")
            .collect();
        assert_eq!(cov.len(), 1, "{cov:?}");
        (cov[0].passed, cov[0].requirement.clone())
    };
    let strict = AcceptanceCriteria {
        cov_at_least_baseline: Some(true),
        ..Default::default()
    };
    assert_eq!(cov_check(strict.clone()).0, Some(false));
    let wide = cov_check(AcceptanceCriteria {
        cov_baseline_margin: Some(0.05),
        ..strict.clone()
    });
    assert_eq!(wide.0, Some(true));
    assert!(wide.1.contains("0.550 − 0.05"), "{}", wide.1);
    // The margin alone asks for the check.
    let narrow = cov_check(AcceptanceCriteria {
        cov_baseline_margin: Some(0.03),
        ..Default::default()
    });
    assert_eq!(narrow.0, Some(false));
}

#[test]
fn a_raised_stop_flag_skips_the_chamfer_distances_and_says_so() {
    let cohort = population("cohort", 41, 6, 0.0);
    let reference = population("reference", 42, 6, 0.0);
    let (done, stop) = (AtomicU64::new(0), AtomicBool::new(true));
    let report = run_counting(
        &cohort,
        &reference,
        None,
        AcceptanceCriteria::default(),
        Progress {
            done: &done,
            stop: Some(&stop),
        },
    );
    assert_eq!(done.load(Ordering::SeqCst), 0, "distances were computed");
    assert!(report.shapes.is_none());
    assert_eq!(
        report.not_computed.get("shapes").map(String::as_str),
        Some("stopped before every Chamfer distance was computed")
    );
    // Left alone, the same inputs give the shape level and count every distance.
    let done = AtomicU64::new(0);
    let report = run_counting(
        &cohort,
        &reference,
        None,
        AcceptanceCriteria::default(),
        Progress::counting(&done),
    );
    assert!(report.shapes.is_some(), "{:?}", report.not_computed);
    assert!(done.load(Ordering::SeqCst) > 0);
}
