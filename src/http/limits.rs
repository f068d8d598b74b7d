//! Request limits answered as problem documents: a deadline per request (408) and a bound
//! on requests in flight (503 + Retry-After). Body sizes are limited by the extractors.

use std::sync::Arc;
use std::time::Duration;

use axum::extract::{Request, State};
use axum::http::header;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use tokio::sync::Semaphore;

use super::access::PUBLIC_PATHS;
use super::error::ApiError;
use crate::config::Config;

/// Settings of the two middlewares.
#[derive(Debug, Clone)]
pub struct Limits {
    in_flight: Arc<Semaphore>,
    retry_after: u64,
    request_timeout: u64,
    upload_timeout: u64,
}

impl Limits {
    /// From the service configuration.
    pub fn from_config(config: &Config) -> Self {
        Self {
            in_flight: Arc::new(Semaphore::new(config.max_in_flight.max(1))),
            retry_after: config.retry_after_secs,
            request_timeout: config.request_timeout_secs,
            upload_timeout: config.upload_timeout_secs,
        }
    }
}

/// Answers 503 at once when the in-flight bound is reached (shedding load rather than
/// queueing it in memory). Probes and metrics are not counted, so an orchestrator can still
/// see a busy service as alive.
pub async fn bound_in_flight(State(limits): State<Limits>, req: Request, next: Next) -> Response {
    if PUBLIC_PATHS.contains(&req.uri().path()) {
        return next.run(req).await;
    }
    match limits.in_flight.clone().try_acquire_owned() {
        Ok(_permit) => next.run(req).await,
        Err(_) => ApiError::Overloaded {
            retry_after: limits.retry_after,
        }
        .into_response(),
    }
}

/// Answers 408 when the response is not ready within the deadline. The deadline covers
/// reading the request and building the response, not sending a response body, so a long
/// download is not cut. A multipart upload gets the longer upload deadline.
pub async fn deadline(State(limits): State<Limits>, req: Request, next: Next) -> Response {
    let seconds = if is_multipart(&req) {
        limits.upload_timeout
    } else {
        limits.request_timeout
    };
    match tokio::time::timeout(Duration::from_secs(seconds), next.run(req)).await {
        Ok(response) => response,
        Err(_) => {
            let mut response = ApiError::Timeout { seconds }.into_response();
            // The unread rest of the body makes the connection unusable for another request.
            response.headers_mut().insert(
                header::CONNECTION,
                header::HeaderValue::from_static("close"),
            );
            response
        }
    }
}

fn is_multipart(req: &Request) -> bool {
    req.headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| {
            v.trim_start()
                .to_ascii_lowercase()
                .starts_with("multipart/form-data")
        })
}
