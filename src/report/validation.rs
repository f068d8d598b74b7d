//! The validation report as one HTML page: the verdict and every acceptance check, the
//! credibility dossier, the shape level (pairwise and DCR distributions, 1-NNA, COV, MMD,
//! the real-vs-real baseline), one section per feature (overlaid histograms, then SIMCor's
//! density band) and the joint comparison (χ² QQ of Mahalanobis forms, Spearman
//! differences). Built from the stored JSON report alone, so the service and the command
//! line render the same page.

use super::figures::{BandPlot, QqSeries, band_svg, qq_svg};
use super::html::{Report, Section, render_html};
use super::plot::{Series, overlay_svg, tick};
use crate::validation::criteria::Check;
use crate::validation::measures::{FeatureComparison, JointComparison};
use crate::validation::report::ValidationReport;
use crate::validation::shapes::ShapeLevel;

/// The report's page.
pub fn validation_html(report: &ValidationReport) -> String {
    render_html(&validation_report(report))
}

/// The report's sections (the page without its markup), and the SVG files `--svg-dir`
/// writes, by name.
pub fn validation_report(r: &ValidationReport) -> Report {
    let mut sections = vec![verdict(r)];
    if let Some(level) = &r.shapes {
        sections.extend(shape_sections(level, &r.dossier.reference.label));
    }
    for f in &r.features {
        sections.push(feature_section(f));
        if let Some(s) = band_section(f) {
            sections.push(s);
        }
    }
    sections.push(joint_section(&r.joint));
    Report {
        title: format!(
            "Validation of {} against {}",
            r.dossier.cohort.label, r.dossier.reference.label
        ),
        facts: dossier_facts(r),
        sections,
        footer: format!(
            "aortagen {}. Shape-level distances are squared lengths on one common scale (see \
             the shape section); features in mm, mm² and mm³.",
            r.dossier.software_version
        ),
    }
}

/// The SVG figures of a report with file names, for `--svg-dir`.
pub fn validation_svgs(r: &ValidationReport) -> Vec<(String, String)> {
    let report = validation_report(r);
    report
        .sections
        .into_iter()
        .filter(|s| !s.svg.is_empty())
        .map(|s| (format!("{}.svg", file_name(&s.heading)), s.svg))
        .collect()
}

fn file_name(heading: &str) -> String {
    heading
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '-'
            }
        })
        .collect::<String>()
        .split('-')
        .filter(|p| !p.is_empty())
        .collect::<Vec<_>>()
        .join("-")
}

fn dossier_facts(r: &ValidationReport) -> Vec<(String, String)> {
    let d = &r.dossier;
    let or_dash = |s: &Option<String>| s.clone().unwrap_or_else(|| "—".into());
    let subject = |s: &crate::validation::Subject| {
        let mut text = format!("{} ({}, {} shapes", s.label, s.kind, s.shapes);
        if let Some(seed) = s.seed {
            text.push_str(&format!(", seed {seed}"));
        }
        if let Some(sha) = &s.sha256 {
            text.push_str(&format!(", SHA-256 {}", &sha[..16.min(sha.len())]));
        }
        text + ")"
    };
    vec![
        ("verdict".into(), format!("{:?}", r.verdict).to_lowercase()),
        ("context of use".into(), or_dash(&d.context_of_use)),
        (
            "question of interest".into(),
            or_dash(&d.question_of_interest),
        ),
        ("model".into(), d.model_id.clone()),
        ("model weights SHA-256".into(), or_dash(&d.model_sha256)),
        (
            "software".into(),
            format!("aortagen {}", d.software_version),
        ),
        ("cohort".into(), subject(&d.cohort)),
        ("cohort request".into(), d.cohort.details.to_string()),
        ("reference".into(), subject(&d.reference)),
        (
            "acceptance criteria (set before the run)".into(),
            serde_json::to_string(&d.criteria).unwrap_or_default(),
        ),
        ("computed".into(), d.computed_at.clone()),
    ]
}

fn verdict(r: &ValidationReport) -> Section {
    let failed = r.checks.iter().filter(|c| c.passed == Some(false)).count();
    let open = r.checks.iter().filter(|c| c.passed.is_none()).count();
    let mut caption = format!(
        "{} of {} checks passed, {failed} failed, {open} could not be evaluated.",
        r.checks.len() - failed - open,
        r.checks.len()
    );
    for (part, why) in &r.not_computed {
        caption.push_str(&format!(" The {part} level was not computed: {why}."));
    }
    for (feature, why) in &r.not_compared {
        caption.push_str(&format!(" {feature} not compared: {why}."));
    }
    Section {
        heading: format!("Verdict: {}", format!("{:?}", r.verdict).to_lowercase()),
        caption,
        svg: String::new(),
        rows: r.checks.iter().map(check_row).collect(),
    }
}

fn check_row(c: &Check) -> (String, String) {
    let subject = match &c.feature {
        Some(f) => format!("{} ({f}): {}", c.criterion, c.requirement),
        None => format!("{}: {}", c.criterion, c.requirement),
    };
    let outcome = match (c.passed, c.value) {
        (Some(true), Some(v)) => format!("pass ({})", tick(v)),
        (Some(false), Some(v)) => format!("FAIL ({})", tick(v)),
        _ => format!("not evaluated: {}", c.note.as_deref().unwrap_or("no value")),
    };
    (subject, outcome)
}

fn interval(i: &crate::validation::shapes::Interval) -> String {
    format!("{:.3} [{:.3}, {:.3}]", i.mean, i.low, i.high)
}

fn shape_sections(level: &ShapeLevel, reference: &str) -> Vec<Section> {
    let mut rows = vec![("units".to_owned(), level.units.clone())];
    rows.push(("sampling floor (median)".into(), tick(level.sampling_floor)));
    if let Some(n) = &level.nna {
        let text = format!(
            "{:.3} [{:.3}, {:.3}] ({} per set, {} subsets)",
            n.mean, n.low, n.high, n.subset_size, n.subsets
        );
        rows.push(("1-NNA (0.5 ideal)".into(), text));
    }
    if let Some(c) = &level.coverage {
        rows.push((
            format!("COV ({} per subset)", c.subset_size),
            interval(&c.cov_subsets),
        ));
        rows.push((
            "MMD".into(),
            format!(
                "{} [{}, {}]",
                tick(c.mmd_subsets.mean),
                tick(c.mmd_subsets.low),
                tick(c.mmd_subsets.high)
            ),
        ));
        rows.push((
            "COV / MMD of the whole cohort".into(),
            format!("{:.3} / {}", c.cov, tick(c.mmd)),
        ));
    }
    if let Some(b) = &level.baseline {
        rows.push((
            format!("baseline: {}", b.label),
            format!(
                "1-NNA {:.3}, COV {}, pairwise median ratio {:.2}",
                b.nna.mean,
                interval(&b.coverage.cov_subsets),
                b.pairwise_median_ratio
            ),
        ));
    }
    for (name, why) in &level.not_computed {
        rows.push((format!("{name} not computed"), why.clone()));
    }
    let mut sections = Vec::new();
    let (svg, pair_rows) = match &level.pairwise {
        Some(p) => (
            overlay_svg(
                "Pairwise distances",
                "Chamfer distance (common scale)",
                &[
                    Series {
                        name: "cohort".into(),
                        values: p.cohort_values.clone(),
                    },
                    Series {
                        name: reference.to_owned(),
                        values: p.reference_values.clone(),
                    },
                ],
            ),
            vec![
                ("pairwise median: cohort".to_owned(), tick(p.cohort.median)),
                (
                    "pairwise median: reference".to_owned(),
                    tick(p.reference.median),
                ),
                ("ratio".to_owned(), format!("{:.3}", p.median_ratio)),
            ],
        ),
        None => (String::new(), Vec::new()),
    };
    rows.extend(pair_rows);
    sections.push(Section {
        heading: "Shape level".into(),
        caption: "Whole surfaces compared by Chamfer distance: 1-NNA tells the cohort from the \
                  reference (0.5 means it cannot), COV is the share of reference shapes that are \
                  some cohort shape's nearest, MMD how close the nearest cohort shape comes to each \
                  reference shape; both on subsets of the reference's size. The baseline puts the \
                  model's training shapes through the same protocol (real against real)."
            .into(),
        svg,
        rows,
    });
    if let Some(d) = &level.dcr {
        let svg = overlay_svg(
            "Distance to the closest training shape",
            "Chamfer distance (common scale)",
            &[
                Series {
                    name: "cohort".into(),
                    values: d.dcr.generated.clone(),
                },
                Series {
                    name: d.newcomers.clone(),
                    values: d.dcr.heldout.clone(),
                },
            ],
        );
        sections.push(Section {
            heading: "Privacy: distance to the closest record".into(),
            caption: format!(
                "Each cohort shape's distance to its nearest training shape beside the same figure \
                 for {} (new patients). A cohort closer to the training patients than new patients \
                 are, or one holding near-copies (within 2 sampling floors), is flagged.",
                d.newcomers
            ),
            svg,
            rows: vec![
                (
                    "DCR median: cohort".into(),
                    tick(d.dcr.generated_summary.median),
                ),
                (
                    "DCR median: new patients".into(),
                    tick(d.dcr.heldout_summary.median),
                ),
                (
                    "median ratio".into(),
                    d.dcr.median_ratio.map_or("—".into(), |r| format!("{r:.3}")),
                ),
                ("near-copies".into(), d.near_copies.to_string()),
                (
                    "near-copy threshold".into(),
                    format!("DCR < {:.3e}", d.near_copy_threshold),
                ),
                (
                    "share below the new patients' 5 % quantile".into(),
                    format!("{:.3}", d.dcr.share_below_heldout_p05),
                ),
                (
                    "flagged".into(),
                    if d.flagged { "yes".into() } else { "no".into() },
                ),
            ],
        });
    }
    sections
}

fn feature_section(f: &FeatureComparison) -> Section {
    let name = f.feature.name();
    let svg = overlay_svg(
        name,
        &format!("{name} ({})", f.unit),
        &[
            Series {
                name: "cohort".into(),
                values: f.cohort_values.clone(),
            },
            Series {
                name: "reference".into(),
                values: f.reference_values.clone(),
            },
        ],
    );
    let summary = |s: &Option<crate::stats::descriptive::Summary>| {
        s.as_ref().map_or("—".into(), |s| {
            format!(
                "{} ± {} (median {})",
                tick(s.mean),
                tick(s.sd),
                tick(s.median)
            )
        })
    };
    let mut rows = vec![
        (
            "measured (cohort)".to_owned(),
            format!("{} of {}", f.cohort_measured[0], f.cohort_measured[1]),
        ),
        (
            "measured (reference)".to_owned(),
            format!("{} of {}", f.reference_measured[0], f.reference_measured[1]),
        ),
        ("cohort mean ± sd".to_owned(), summary(&f.cohort)),
        ("reference mean ± sd".to_owned(), summary(&f.reference)),
    ];
    if let Some(k) = f.ks {
        rows.push((
            "KS D, p".into(),
            format!("{:.3}, {}", k.statistic, tick(k.p_value)),
        ));
    }
    if let Some(w) = f.wasserstein {
        rows.push(("Wasserstein-1".into(), format!("{} {}", tick(w), f.unit)));
    }
    if let Some(a) = f.ecdf_area {
        rows.push(("ECDF area".into(), format!("{} {}", tick(a), f.unit)));
    }
    if let Some(b) = &f.density_band {
        rows.push((
            "band p (p_min, p_max)".into(),
            format!("{:.3} ({:.3}, {:.3})", b.p_value, b.p_min, b.p_max),
        ));
    }
    if let Some(e) = &f.equivalence {
        rows.push((
            format!("TOST ±{} {}", e.margin, f.unit),
            format!(
                "p {}, 90 % CI [{}, {}]: {}",
                tick(e.test.p_value),
                tick(e.test.ci90.0),
                tick(e.test.ci90.1),
                if e.equivalent {
                    "equivalent"
                } else {
                    "not shown equivalent"
                }
            ),
        ));
    }
    for (stat, why) in &f.not_computed {
        rows.push((format!("{stat} not computed"), why.clone()));
    }
    Section {
        heading: format!("Feature {name}"),
        caption: format!("{name} over the cohort and the reference (fraction of each per bin)."),
        svg,
        rows,
    }
}

fn band_section(f: &FeatureComparison) -> Option<Section> {
    let b = f.density_band.as_ref()?;
    let name = f.feature.name();
    let svg = band_svg(&BandPlot {
        title: &format!("{name}: bootstrap density band"),
        x_label: &format!("{name} ({})", f.unit),
        grid: &b.grid,
        lower: &b.lower,
        upper: &b.upper,
        real: &b.real_density,
        virtual_density: &b.virtual_density,
    });
    Some(Section {
        heading: format!("Density band {name}"),
        caption: format!(
            "SIMCor's test: the cohort resampled with replacement at m = α·n_real = {} (α = \
             {:.2}), the 2.5–97.5 % band of the resamples' kernel densities; p is half the share \
             of the grid where the real density lies above the band plus half where it lies below.",
            b.subsample_size, b.alpha
        ),
        svg,
        rows: vec![
            ("above the band".into(), format!("{:.3}", b.share_above)),
            ("below the band".into(), format!("{:.3}", b.share_below)),
            ("p".into(), format!("{:.3}", b.p_value)),
        ],
    })
}

fn joint_section(j: &JointComparison) -> Section {
    let names: Vec<&str> = j.features.iter().map(|f| f.name()).collect();
    let mut rows = vec![("features".to_owned(), names.join(", "))];
    let svg = match &j.mahalanobis {
        Some(m) => {
            rows.push((
                "cohort beyond the χ² 95 % quantile".into(),
                format!("{:.3}", m.cohort_outside_95),
            ));
            rows.push((
                "reference beyond it".into(),
                format!("{:.3}", m.reference_outside_95),
            ));
            qq_svg(
                &format!("Mahalanobis forms against χ²({})", m.dimension),
                "χ² quantile",
                &[
                    QqSeries {
                        name: "cohort".into(),
                        points: m.cohort_qq.clone(),
                    },
                    QqSeries {
                        name: "reference".into(),
                        points: m.reference_qq.clone(),
                    },
                ],
            )
        }
        None => String::new(),
    };
    if let Some(s) = &j.spearman {
        rows.push((
            "largest |Δ Spearman ρ|".into(),
            format!("{:.3}", s.max_abs_difference),
        ));
        for (a, row) in s.difference.iter().enumerate() {
            for (b, d) in row.iter().enumerate().skip(a + 1) {
                rows.push((
                    format!("Δρ {} × {}", names[a], names[b]),
                    format!("{d:+.3}"),
                ));
            }
        }
    }
    for (part, why) in &j.not_computed {
        rows.push((format!("{part} not computed"), why.clone()));
    }
    Section {
        heading: "Joint comparison".into(),
        caption: "Each shape's Mahalanobis form against the reference's mean and covariance, \
                  quantile against quantile of χ² with as many degrees of freedom as features: \
                  points below the line mean a cohort narrower than the population, above it one \
                  that strays outside it. Δρ: cohort minus reference Spearman correlations."
            .into(),
        svg,
        rows,
    }
}
