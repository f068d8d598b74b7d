//! The measurement level of a validation: for every feature measured on both sides, the
//! summaries and common histograms, the two-sample Kolmogorov–Smirnov test, the
//! Wasserstein-1 distance and the ECDF area in the feature's unit, SIMCor's bootstrap
//! density-band test and, where the request gives a margin, Welch TOST equivalence of the
//! means; jointly, Mahalanobis forms of both sides against the reference's mean and
//! covariance (χ² QQ) and the difference of the Spearman matrices. Every statistic that
//! cannot be computed is absent with the reason in `not_computed`, never NaN.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::features::Feature;
use super::population::Population;
use crate::stats::bootstrap::{BandTest, BandTestConfig, density_band_test};
use crate::stats::descriptive::{CommonHistograms, Summary};
use crate::stats::distributions::chi2_quantile;
use crate::stats::ks::{KsResult, ks_two_sample};
use crate::stats::multivariate::{MahalanobisReference, chi2_qq};
use crate::stats::rank::CorrelationDifference;
use crate::stats::tost::{Tost, tost_welch};
use crate::stats::wasserstein::{ecdf_area, wasserstein_1};

/// Histogram bins of a feature's plot.
pub const FEATURE_BINS: usize = 20;
/// Significance level the KS test must be able to reach to be reported.
pub const KS_ALPHA: f64 = 0.05;
/// Significance level at which TOST shows equivalence.
pub const TOST_ALPHA: f64 = 0.05;

/// How the measurement level is computed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct MeasureSettings {
    /// SIMCor's bootstrap: resamples, uncertainty discount, seed.
    pub band: BandTestConfig,
    /// TOST margins by feature name, in the feature's unit.
    #[schema(value_type = BTreeMap<String, f64>)]
    pub tost_margins: BTreeMap<Feature, f64>,
}

/// A TOST with its margin and verdict.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Equivalence {
    /// The margin (±, in the feature's unit).
    pub margin: f64,
    /// The test.
    pub test: Tost,
    /// Whether equivalence is shown at α = 0.05 (p < 0.05: the 90 % interval of the
    /// difference lies inside ±margin).
    pub equivalent: bool,
}

/// One feature, cohort against reference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct FeatureComparison {
    /// The feature.
    #[schema(value_type = String)]
    pub feature: Feature,
    /// Its unit.
    pub unit: String,
    /// Cohort shapes measured / in the cohort.
    pub cohort_measured: [usize; 2],
    /// Reference shapes measured / in the reference.
    pub reference_measured: [usize; 2],
    /// Cohort summary.
    pub cohort: Option<Summary>,
    /// Reference summary.
    pub reference: Option<Summary>,
    /// Both samples on common bins (`counts_a`: cohort, `counts_b`: reference).
    pub histograms: Option<CommonHistograms>,
    /// Two-sample Kolmogorov–Smirnov test.
    pub ks: Option<KsResult>,
    /// Wasserstein-1 distance in the feature's unit.
    pub wasserstein: Option<f64>,
    /// Area between the two empirical distribution functions, in the feature's unit.
    pub ecdf_area: Option<f64>,
    /// SIMCor's bootstrap density-band test (the cohort is resampled).
    pub density_band: Option<BandTest>,
    /// TOST of the means, when the request gives this feature a margin.
    pub equivalence: Option<Equivalence>,
    /// Why a statistic is missing, by name.
    pub not_computed: BTreeMap<String, String>,
    /// The cohort's values (for plots).
    pub cohort_values: Vec<f64>,
    /// The reference's values.
    pub reference_values: Vec<f64>,
}

/// Compares one feature of `cohort` with `reference`.
pub fn compare_feature(
    feature: Feature,
    cohort: &Population,
    reference: &Population,
    settings: &MeasureSettings,
) -> FeatureComparison {
    let (a, b) = (cohort.values(feature), reference.values(feature));
    let mut not_computed = BTreeMap::new();
    let n = &mut not_computed;
    let cohort_summary = keep(n, "cohort", Summary::of(&a));
    let reference_summary = keep(n, "reference", Summary::of(&b));
    let histograms = keep(n, "histograms", CommonHistograms::new(&a, &b, FEATURE_BINS));
    let ks = match ks_without_power(a.len(), b.len()) {
        Some(why) => {
            n.insert("ks".into(), why);
            None
        }
        None => keep(n, "ks", ks_two_sample(&a, &b)),
    };
    let wasserstein = keep(n, "wasserstein", wasserstein_1(&a, &b));
    let ecdf = keep(n, "ecdf_area", ecdf_area(&a, &b));
    let band = keep(n, "density_band", density_band_test(&a, &b, &settings.band));
    let equivalence = match settings.tost_margins.get(&feature) {
        None => {
            let why = "no TOST margin was given for this feature";
            not_computed.insert("equivalence".into(), why.into());
            None
        }
        Some(&margin) => match tost_welch(&a, &b, margin) {
            Ok(test) => Some(Equivalence {
                margin,
                equivalent: test.p_value < TOST_ALPHA,
                test,
            }),
            Err(e) => {
                not_computed.insert("equivalence".into(), e.to_string());
                None
            }
        },
    };
    FeatureComparison {
        feature,
        unit: feature.unit().into(),
        cohort_measured: [a.len(), cohort.len()],
        reference_measured: [b.len(), reference.len()],
        cohort: cohort_summary,
        reference: reference_summary,
        histograms,
        ks,
        wasserstein,
        ecdf_area: ecdf,
        density_band: band,
        equivalence,
        not_computed,
        cohort_values: a,
        reference_values: b,
    }
}

/// Why the KS test is not reported for samples of `n1` and `n2` values: when not even the
/// most extreme outcome (every value of one sample below every value of the other) reaches
/// p < [`KS_ALPHA`], the test cannot reject, and a p-value of 0.7 on 1 against 2 shapes
/// would read as agreement.
fn ks_without_power(n1: usize, n2: usize) -> Option<String> {
    if n1 == 0 || n2 == 0 {
        return None; // the test's own error names the empty sample
    }
    // Two of the C(n1 + n2, n1) equally likely orders give D = 1.
    let (small, total) = (n1.min(n2), n1 + n2);
    let orders = (1..=small).fold(1.0f64, |c, i| c * (total - small + i) as f64 / i as f64);
    let smallest_p = (2.0 / orders).min(1.0);
    (smallest_p >= KS_ALPHA).then(|| {
        format!(
            "too few shapes measured ({n1} in the cohort, {n2} in the reference): the smallest \
             p-value the KS test can give is {smallest_p:.3}, so it cannot reject at {KS_ALPHA}"
        )
    })
}

/// The value of `r`, or none with the reason noted under `name`.
fn keep<T>(
    notes: &mut BTreeMap<String, String>,
    name: &str,
    r: Result<T, crate::stats::StatsError>,
) -> Option<T> {
    r.map_err(|e| notes.insert(name.to_owned(), e.to_string()))
        .ok()
}

/// Mahalanobis forms of both samples against the reference's Gaussian.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct MahalanobisComparison {
    /// Features p (the χ² degrees of freedom).
    pub dimension: usize,
    /// q of each cohort shape.
    pub cohort_q: Vec<f64>,
    /// q of each reference shape.
    pub reference_q: Vec<f64>,
    /// (χ²_p quantile, observed q) of the sorted cohort forms.
    pub cohort_qq: Vec<(f64, f64)>,
    /// The same for the reference.
    pub reference_qq: Vec<(f64, f64)>,
    /// Median of χ²_p.
    pub chi2_median: f64,
    /// Share of cohort shapes beyond the χ²_p 95 % quantile (outside the reference's
    /// 95 % ellipsoid; about 0.05 for a cohort that fills it).
    pub cohort_outside_95: f64,
    /// The same for the reference.
    pub reference_outside_95: f64,
}

/// The joint comparison of the features every shape of both sides has.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct JointComparison {
    /// The features compared jointly.
    #[schema(value_type = Vec<String>)]
    pub features: Vec<Feature>,
    /// Mahalanobis forms against the reference.
    pub mahalanobis: Option<MahalanobisComparison>,
    /// Spearman matrices (`virtual_matrix`: the cohort) and their difference.
    pub spearman: Option<CorrelationDifference>,
    /// Why a part is missing, by name.
    pub not_computed: BTreeMap<String, String>,
}

/// Compares the features in `candidates` that every member of both sides has.
pub fn compare_jointly(
    candidates: &[Feature],
    cohort: &Population,
    reference: &Population,
) -> JointComparison {
    let complete =
        |p: &Population, f: Feature| p.members.iter().all(|m| m.features.get(f).is_some());
    let features: Vec<Feature> = candidates
        .iter()
        .copied()
        .filter(|&f| complete(cohort, f) && complete(reference, f))
        .collect();
    let mut joint = JointComparison {
        features: features.clone(),
        mahalanobis: None,
        spearman: None,
        not_computed: BTreeMap::new(),
    };
    if features.len() < 2 {
        let why = format!(
            "needs at least 2 features measured on every shape of both sides, found {}",
            features.len()
        );
        joint.not_computed.insert("mahalanobis".into(), why.clone());
        joint.not_computed.insert("spearman".into(), why);
        return joint;
    }
    let rows = |p: &Population| -> Vec<Vec<f64>> {
        p.members
            .iter()
            .map(|m| features.iter().filter_map(|&f| m.features.get(f)).collect())
            .collect()
    };
    let (c, r) = (rows(cohort), rows(reference));
    match mahalanobis(&c, &r) {
        Ok(m) => joint.mahalanobis = Some(m),
        Err(e) => drop(
            joint
                .not_computed
                .insert("mahalanobis".into(), e.to_string()),
        ),
    }
    match CorrelationDifference::new(&c, &r) {
        Ok(s) => joint.spearman = Some(s),
        Err(e) => drop(joint.not_computed.insert("spearman".into(), e.to_string())),
    }
    joint
}

fn mahalanobis(
    cohort: &[Vec<f64>],
    reference: &[Vec<f64>],
) -> Result<MahalanobisComparison, crate::stats::StatsError> {
    let fitted = MahalanobisReference::fit(reference)?;
    let p = fitted.dimension();
    let (cq, rq) = (
        fitted.quadratic_forms(cohort)?,
        fitted.quadratic_forms(reference)?,
    );
    let limit = chi2_quantile(0.95, p as f64)?;
    let outside = |q: &[f64]| q.iter().filter(|v| **v > limit).count() as f64 / q.len() as f64;
    Ok(MahalanobisComparison {
        dimension: p,
        cohort_qq: chi2_qq(&cq, p)?,
        reference_qq: chi2_qq(&rq, p)?,
        chi2_median: chi2_quantile(0.5, p as f64)?,
        cohort_outside_95: outside(&cq),
        reference_outside_95: outside(&rq),
        cohort_q: cq,
        reference_q: rq,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validation::Member;
    use crate::validation::features::FeatureValues;

    #[test]
    fn ks_is_withheld_exactly_when_no_outcome_could_reject() {
        for n1 in 1..=8 {
            for n2 in 1..=45 {
                // The most extreme outcome: the samples do not overlap.
                let a: Vec<f64> = (0..n1).map(|i| i as f64).collect();
                let b: Vec<f64> = (0..n2).map(|i| 100.0 + i as f64).collect();
                let smallest = ks_two_sample(&a, &b).unwrap().p_value;
                let withheld = ks_without_power(n1, n2).is_some();
                // Off the boundary by a margin, so rounding cannot decide.
                if (smallest - KS_ALPHA).abs() > 1e-9 {
                    assert_eq!(withheld, smallest >= KS_ALPHA, "{n1} {n2}: p {smallest}");
                }
            }
        }
        assert!(ks_without_power(1, 2).is_some());
        assert!(ks_without_power(4, 4).is_none());
        assert!(ks_without_power(1, 40).is_none());
    }

    #[test]
    fn a_feature_measured_on_too_few_shapes_says_why_instead_of_a_p_value() {
        let population = |areas: &[f64]| Population {
            label: "p".into(),
            members: areas
                .iter()
                .map(|&a| Member {
                    name: a.to_string(),
                    surface_mm: None,
                    features: FeatureValues::of_shape(None, a, 1.0),
                })
                .collect(),
        };
        let settings = MeasureSettings {
            band: BandTestConfig {
                resamples: 200,
                ..BandTestConfig::default()
            },
            tost_margins: BTreeMap::new(),
        };
        let few = compare_feature(
            Feature::Area,
            &population(&[1.0]),
            &population(&[2.0, 3.0]),
            &settings,
        );
        assert!(few.ks.is_none());
        let why = &few.not_computed["ks"];
        assert!(why.contains("too few shapes measured (1 in the cohort, 2 in the reference)"));
        assert!(few.wasserstein.is_some(), "the distances are still given");
        let enough = compare_feature(
            Feature::Area,
            &population(&[1.0, 2.0, 3.0, 4.0]),
            &population(&[5.0, 6.0, 7.0, 8.0]),
            &settings,
        );
        assert!(enough.ks.is_some_and(|k| k.p_value < KS_ALPHA));
    }
}
