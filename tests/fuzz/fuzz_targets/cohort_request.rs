//! Arbitrary bytes as the body of `POST /v1/cohorts`, decoded and parsed exactly as the
//! handler does. Decoding never panics; a rejection is a 4xx; an accepted request keeps
//! every rule (count, arity, resolution, weights, noise, novelty).
#![no_main]

use aortagen::cohort::weights::check_weights;
use aortagen::cohort::{CohortRequest, RESOLUTION_RANGE, RequestLimits};
use aortagen::http::cohorts::dto::CreateCohort;
use aortagen::http::error::ApiError;
use aortagen::http::extractors::parse_json;
use libfuzzer_sys::fuzz_target;

const LIMITS: RequestLimits = RequestLimits {
    max_count: 1000,
    max_voxels: 2_000_000_000,
};

fuzz_target!(|data: &[u8]| {
    let body = match parse_json::<CreateCohort>(data) {
        Ok(body) => body,
        Err(err) => {
            assert!(err.status_code().is_client_error(), "{err}");
            return;
        }
    };
    match CohortRequest::parse(body.fields(), LIMITS, || 0) {
        Err(err) => {
            let err = ApiError::from(err);
            assert!(err.status_code().is_client_error(), "{err}");
        }
        Ok(request) => {
            assert!((1..=LIMITS.max_count).contains(&request.count));
            assert!(request.arity >= 2);
            assert!(RESOLUTION_RANGE.contains(&request.resolution));
            assert!(request.latent_noise.is_finite() && request.latent_noise >= 0.0);
            if let Some(v) = request.min_novelty {
                assert!(v.is_finite() && v >= 0.0);
            }
            if let Some(w) = request.weights.fixed() {
                assert!(check_weights(w, request.arity).is_ok());
            }
            // The idempotency fingerprint of an accepted request is always computable.
            assert_eq!(body.fingerprint().len(), 64);
        }
    }
});
