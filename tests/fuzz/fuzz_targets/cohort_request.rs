//! Arbitrary bytes as the body of `POST /v1/cohorts`, decoded and validated exactly as the
//! handler does. Decoding never panics; a rejection is a 4xx; an accepted request keeps
//! every rule (count, arity, resolution, weights).
#![no_main]

use aortagen::http::cohorts::dto::{CreateCohort, RESOLUTION_RANGE};
use aortagen::http::extractors::parse_json;
use aortagen::jobs::plan::check_weights;
use libfuzzer_sys::fuzz_target;

const MAX_COUNT: u32 = 1000;
const MAX_VOXELS: u64 = 2_000_000_000;

fuzz_target!(|data: &[u8]| {
    let request = match parse_json::<CreateCohort>(data) {
        Ok(request) => request,
        Err(err) => {
            assert!(err.status_code().is_client_error(), "{err}");
            return;
        }
    };
    match request.check_shape(MAX_COUNT, MAX_VOXELS) {
        Err(err) => assert!(err.status_code().is_client_error(), "{err}"),
        Ok(()) => {
            assert!((1..=i64::from(MAX_COUNT)).contains(&request.count));
            assert!(request.arity >= 2);
            if let Some(r) = request.resolution {
                assert!((RESOLUTION_RANGE.0..=RESOLUTION_RANGE.1).contains(&r));
            }
            for v in [request.latent_noise, request.min_novelty].into_iter().flatten() {
                assert!(v.is_finite() && v >= 0.0);
            }
            if let Some(w) = &request.weights {
                assert!(check_weights(w, request.arity as usize).is_ok());
            }
            // The idempotency fingerprint of an accepted request is always computable.
            assert_eq!(request.fingerprint().len(), 64);
        }
    }
});
