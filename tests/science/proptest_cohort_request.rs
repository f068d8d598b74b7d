//! Property-based tests of the cohort request rules (DESIGN §4) and of the per-shape
//! weights and selections a valid request turns into.

use std::sync::Arc;

use aortagen::cohort::targets::Measurement;
use aortagen::cohort::weights::{WEIGHT_SUM_TOLERANCE, check_weights};
use aortagen::cohort::{
    CohortPlan, CohortRequest, RESOLUTION_RANGE, RequestLimits, Selection, WeightChoice,
};
use aortagen::http::cohorts::dto::CreateCohort;
use aortagen::http::error::ApiError;
use aortagen::http::extractors::parse_json;
use proptest::prelude::*;
use serde_json::json;

const MAX_COUNT: u32 = 500;
/// A work budget of `count × resolution³` voxels per cohort (one draw a shape here).
const MAX_VOXELS: u64 = 2_000_000_000;
/// Smallest and largest accepted resolution.
const RESOLUTIONS: (i64, i64) = (
    *RESOLUTION_RANGE.start() as i64,
    *RESOLUTION_RANGE.end() as i64,
);

fn request(body: serde_json::Value) -> Result<CohortRequest<i64>, ApiError> {
    let bytes = serde_json::to_vec(&body).unwrap();
    let parsed: CreateCohort = parse_json(&bytes)?;
    let limits = RequestLimits {
        max_count: MAX_COUNT,
        max_voxels: MAX_VOXELS,
    };
    Ok(CohortRequest::parse(
        parsed.fields(),
        limits,
        rand::random::<u64>,
    )?)
}

fn field_of(err: &ApiError) -> Option<&str> {
    match err {
        ApiError::Validation { field, .. } => Some(field),
        _ => None,
    }
}

/// Deterministic 4-dimensional latents for the spread selection.
fn pseudo_latents(n: usize, seed: u64) -> Vec<Vec<f32>> {
    let mut state = seed | 1;
    (0..n)
        .map(|_| {
            (0..4)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
                })
                .collect()
        })
        .collect()
}

/// Non-negative weights normalised to sum to one.
fn simplex(k: usize) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(0.0f64..10.0, k)
        .prop_filter("not all zero", |w| w.iter().sum::<f64>() > 1e-3)
        .prop_map(|w| {
            let s: f64 = w.iter().sum();
            w.into_iter().map(|x| x / s).collect()
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn valid_requests_are_accepted_within_the_work_budget(
        count in 1i64..=i64::from(MAX_COUNT),
        arity in 2i64..=12,
        resolution in RESOLUTIONS.0..=RESOLUTIONS.1,
        seed in any::<u64>(),
        dirichlet in any::<bool>(),
    ) {
        let weighting = if dirichlet { "dirichlet" } else { "equal" };
        let body = json!({"model_id": "m", "count": count, "arity": arity,
            "resolution": resolution, "seed": seed, "weighting": weighting});
        let voxels = count as u64 * (resolution as u64).pow(3);
        match request(body) {
            Ok(parsed) => {
                prop_assert!(voxels <= MAX_VOXELS);
                prop_assert_eq!(i64::from(parsed.count), count);
                prop_assert_eq!(parsed.seed, seed);
            }
            Err(err) => {
                // The only rule such a request can break is the work budget, named on count.
                prop_assert!(voxels > MAX_VOXELS, "{}", err);
                prop_assert_eq!(field_of(&err), Some("count"));
            }
        }
    }

    #[test]
    fn diversity_controls_must_be_finite_and_non_negative(
        field in prop_oneof![Just("latent_noise"), Just("min_novelty")],
        value in prop_oneof![-1e6f64..-1e-12, 0.0f64..10.0],
    ) {
        let mut body = json!({"model_id": "m", "count": 1, "arity": 2, "resolution": 64});
        body[field] = json!(value);
        match request(body) {
            Ok(_) => prop_assert!(value >= 0.0),
            Err(err) => {
                prop_assert!(value < 0.0, "{}", err);
                prop_assert_eq!(field_of(&err), Some(field));
            }
        }
    }

    #[test]
    fn counts_out_of_range_name_count(count in prop_oneof![i64::MIN..=0, i64::from(MAX_COUNT) + 1..=i64::MAX]) {
        let err = request(json!({"model_id": "m", "count": count, "arity": 2})).unwrap_err();
        prop_assert_eq!(err.status_code().as_u16(), 422);
        prop_assert_eq!(field_of(&err), Some("count"));
    }

    #[test]
    fn arity_below_two_names_arity(arity in i64::MIN..2) {
        let err = request(json!({"model_id": "m", "count": 1, "arity": arity})).unwrap_err();
        prop_assert_eq!(field_of(&err), Some("arity"));
    }

    #[test]
    fn resolutions_out_of_range_name_resolution(
        resolution in prop_oneof![i64::MIN..RESOLUTIONS.0, RESOLUTIONS.1 + 1..=i64::MAX]
    ) {
        let body = json!({"model_id": "m", "count": 1, "arity": 2, "resolution": resolution});
        let err = request(body).unwrap_err();
        prop_assert_eq!(field_of(&err), Some("resolution"));
    }

    #[test]
    fn normalised_weights_are_accepted(w in (2usize..=16).prop_flat_map(simplex)) {
        let arity = w.len();
        prop_assert!(check_weights(&w, arity).is_ok());
        let body = json!({"model_id": "m", "count": 3, "arity": arity, "weights": w});
        prop_assert!(request(body).is_ok());
    }

    #[test]
    fn weights_of_the_wrong_length_are_rejected(w in (2usize..=16).prop_flat_map(simplex), extra in 1usize..4) {
        let arity = w.len() + extra;
        prop_assert!(check_weights(&w, arity).is_err());
        let body = json!({"model_id": "m", "count": 3, "arity": arity, "weights": w});
        let err = request(body).unwrap_err();
        prop_assert!(field_of(&err).is_some_and(|f| f.starts_with("weights")));
    }

    #[test]
    fn weights_off_the_simplex_are_rejected(
        w in (2usize..=16).prop_flat_map(simplex),
        scale in prop_oneof![0.0f64..0.999, 1.001f64..100.0],
    ) {
        let scaled: Vec<f64> = w.iter().map(|x| x * scale).collect();
        let sum: f64 = scaled.iter().sum();
        prop_assume!((sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE);
        prop_assert!(check_weights(&scaled, w.len()).is_err());
    }

    #[test]
    fn a_negative_or_non_finite_entry_is_rejected(
        w in (2usize..=16).prop_flat_map(simplex),
        position in any::<prop::sample::Index>(),
        bad in prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY), -1e3f64..-1e-12],
    ) {
        let mut w = w;
        let i = position.index(w.len());
        w[i] = bad;
        let err = check_weights(&w, w.len()).unwrap_err().to_string();
        prop_assert!(err.contains(&format!("entry {i}")), "{}", err);
    }

    #[test]
    fn any_text_is_a_client_error_or_a_request(text in ".{0,200}") {
        if let Err(err) = parse_json::<CreateCohort>(text.as_bytes()) {
            prop_assert!(err.status_code().is_client_error());
        }
    }

    #[test]
    fn shape_specs_are_valid_reproducible_mixtures(
        training_shapes in 2usize..40,
        arity_fraction in 0.0f64..1.0,
        seed in any::<u64>(),
        index in any::<u64>(),
        dirichlet in any::<bool>(),
        spread in any::<bool>(),
        latent_seed in any::<u64>(),
    ) {
        let arity = 2 + ((training_shapes - 2) as f64 * arity_fraction) as usize;
        let plan = CohortPlan {
            training_shapes,
            arity,
            weights: if dirichlet { WeightChoice::Dirichlet } else { WeightChoice::Equal },
            seed,
            resolution: 64,
            selection: if spread { Selection::Spread } else { Selection::Uniform },
            latent_noise: 0.0,
            latents: Some(Arc::new(pseudo_latents(training_shapes, latent_seed))),
            anchors: Vec::new(),
            sampler: None,
        };
        let spec = plan.shape_spec(index);
        prop_assert_eq!(&spec, &plan.shape_spec(index));
        prop_assert_eq!(spec.training_indices.len(), arity);
        let mut sorted = spec.training_indices.clone();
        sorted.sort_unstable();
        sorted.dedup();
        prop_assert_eq!(sorted.len(), arity, "indices repeat: {:?}", spec.training_indices);
        prop_assert!(sorted.iter().all(|&i| i < training_shapes));
        prop_assert!(check_weights(&spec.weights, arity).is_ok(), "{:?}", spec.weights);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Ordered non-negative bounds on a known measurement are accepted (and round-trip);
    /// inverted or negative ones are refused naming the measurement or the bound.
    #[test]
    fn target_ranges_follow_their_rules(
        which in 0..Measurement::ALL.len(),
        a in 0.0f64..200.0,
        b in 0.0f64..200.0,
        negative in -200.0f64..-1e-9,
        candidates in 1i64..=100,
    ) {
        let name = Measurement::ALL[which].name();
        let (lo, hi) = (a.min(b), a.max(b));
        let base = json!({ "model_id": "m", "count": 1, "arity": 2, "resolution": 32 });
        let with = |targets: serde_json::Value| {
            let mut body = base.clone();
            body["targets"] = targets;
            body["max_candidates"] = json!(candidates);
            request(body)
        };
        let ok = with(json!({ name: { "min": lo, "max": hi } })).unwrap();
        let search = ok.targets.unwrap();
        prop_assert_eq!(search.targets.iter().count(), 1);
        prop_assert_eq!(i64::from(search.max_candidates), candidates);
        if lo < hi {
            let err = with(json!({ name: { "min": hi, "max": lo } })).unwrap_err();
            let field = format!("targets.{name}");
            prop_assert_eq!(field_of(&err), Some(field.as_str()));
        }
        let err = with(json!({ name: { "min": negative } })).unwrap_err();
        let field = format!("targets.{name}.min");
        prop_assert_eq!(field_of(&err), Some(field.as_str()));
    }
}
