//! The API's error type and its RFC 9457 `application/problem+json` rendering. Every 4xx
//! names the field (or parameter) and the rule; 5xx details are logged, not sent.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

/// Result alias for handlers.
pub type Result<T, E = ApiError> = std::result::Result<T, E>;

/// Everything a handler can answer other than success.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    /// An id that does not exist (404).
    #[error("{what} {id:?} does not exist")]
    NotFound {
        /// Kind of resource.
        what: &'static str,
        /// The id as requested.
        id: String,
    },
    /// A well-formed request that breaks a rule (422).
    #[error("{field}: {message}")]
    Validation {
        /// JSON path or header of the offending value.
        field: String,
        /// Short rule name (`range`, `length`, `sum`, `unknown-field`, …).
        rule: &'static str,
        /// Human sentence.
        message: String,
    },
    /// A request the server cannot interpret (400).
    #[error("{message}")]
    BadRequest {
        /// The query parameter or field, if one is to blame.
        field: Option<String>,
        /// Human sentence.
        message: String,
    },
    /// A body that is not valid JSON (400), with the position of the first error.
    #[error("malformed JSON at line {line}, column {column}: {message}")]
    MalformedJson {
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// Parser message.
        message: String,
    },
    /// A body in a media type the endpoint does not take (415).
    #[error("expected a body of type {expected}, got {got}")]
    UnsupportedMediaType {
        /// Accepted type.
        expected: &'static str,
        /// What the Content-Type header said.
        got: String,
    },
    /// A body over the configured limit (413).
    #[error("the request body exceeds the limit of {limit} bytes")]
    PayloadTooLarge {
        /// The limit.
        limit: usize,
    },
    /// An uploaded archive over its entry or expanded-size bound (413).
    #[error("{0}")]
    ArchiveTooLarge(String),
    /// The resource's state forbids the operation (409).
    #[error("{0}")]
    Conflict(String),
    /// The job queue is full (429 + Retry-After).
    #[error("the job queue is full ({pending} jobs waiting or running); retry in {retry_after} s")]
    QueueFull {
        /// Jobs queued or running.
        pending: i64,
        /// Seconds to wait.
        retry_after: u64,
    },
    /// A dependency is down (503).
    #[error("{0}")]
    Unavailable(String),
    /// The database or disk cannot take writes right now (503); reads may still work.
    #[error("storage unavailable: {0}")]
    StorageUnavailable(crate::db::StorageFault),
    /// Too many requests in flight (503 + Retry-After).
    #[error("the service is handling too many requests; retry in {retry_after} s")]
    Overloaded {
        /// Seconds to wait.
        retry_after: u64,
    },
    /// The request took longer than allowed (408).
    #[error("the request did not complete within {seconds} s")]
    Timeout {
        /// The limit.
        seconds: u64,
    },
    /// No usable credential for a protected request (401 + `WWW-Authenticate: Bearer`).
    #[error("this request needs an API key: send `Authorization: Bearer <key>`")]
    Unauthorized,
    /// A credential that is not a configured API key (403).
    #[error("the API key is not valid")]
    Forbidden,
    /// The database failed (500).
    #[error("database error")]
    Database(sqlx::Error),
    /// Anything else unexpected (500).
    #[error("internal error")]
    Internal(anyhow::Error),
}

/// What a request hears when a concurrent request deleted what it refers to, or started
/// using what it deletes, between its checks and its write (the database refused the
/// write on a foreign key; nothing was changed).
const CONCURRENT_CHANGE: &str = "a concurrent request changed a resource this one refers to (it \
    was deleted, or is now in use) while this one was being processed; nothing was changed: \
    read the resources again and retry";

/// Storage faults (read-only database, full disk) become 503; a foreign key broken by a
/// concurrent request 409; other database errors 500.
impl From<sqlx::Error> for ApiError {
    fn from(e: sqlx::Error) -> Self {
        match crate::db::storage_fault(&e) {
            Some(fault) => Self::StorageUnavailable(fault),
            None if crate::db::is_foreign_key_violation(&e) => {
                Self::Conflict(CONCURRENT_CHANGE.into())
            }
            None => Self::Database(e),
        }
    }
}

/// As for database errors, a storage fault anywhere in the chain becomes 503 and a broken
/// foreign key 409.
impl From<anyhow::Error> for ApiError {
    fn from(e: anyhow::Error) -> Self {
        match crate::db::storage_fault_in(&e) {
            Some(fault) => Self::StorageUnavailable(fault),
            None if crate::db::foreign_key_violation_in(&e) => {
                Self::Conflict(CONCURRENT_CHANGE.into())
            }
            None => Self::Internal(e),
        }
    }
}

/// A broken rule of a cohort request: 422 with its own field and rule.
impl From<crate::cohort::RequestError> for ApiError {
    fn from(e: crate::cohort::RequestError) -> Self {
        Self::Validation {
            field: e.field,
            rule: e.rule,
            message: e.message,
        }
    }
}

/// A target the model cannot reach: 422 naming the target, rule `feasible`.
impl From<crate::cohort::Infeasible> for ApiError {
    fn from(e: crate::cohort::Infeasible) -> Self {
        crate::cohort::RequestError::from(e).into()
    }
}

/// A full queue is 429 with `Retry-After`; a refused write as for database errors.
impl From<crate::jobs::SubmitError> for ApiError {
    fn from(e: crate::jobs::SubmitError) -> Self {
        match e {
            crate::jobs::SubmitError::QueueFull {
                pending,
                retry_after,
            } => Self::QueueFull {
                pending,
                retry_after,
            },
            crate::jobs::SubmitError::Storage(e) => e.into(),
        }
    }
}

/// An RFC 9457 problem document, extended with the offending field and rule.
#[derive(Debug, Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct Problem {
    /// Problem type URI (relative to the service).
    #[serde(rename = "type")]
    pub kind: String,
    /// Short summary of the problem type.
    pub title: String,
    /// HTTP status code.
    pub status: u16,
    /// Human-readable explanation of this occurrence.
    pub detail: String,
    /// The field, header or parameter at fault.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// The rule that failed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rule: Option<String>,
    /// Line of a JSON syntax error.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line: Option<usize>,
    /// Column of a JSON syntax error.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub column: Option<usize>,
}

impl ApiError {
    /// Shorthand for a 422 naming the field and the rule.
    pub fn invalid(
        field: impl Into<String>,
        rule: &'static str,
        message: impl Into<String>,
    ) -> Self {
        Self::Validation {
            field: field.into(),
            rule,
            message: message.into(),
        }
    }

    /// Shorthand for a 404.
    pub fn not_found(what: &'static str, id: impl ToString) -> Self {
        Self::NotFound {
            what,
            id: id.to_string(),
        }
    }

    /// The HTTP status this error maps to.
    pub fn status_code(&self) -> StatusCode {
        match self {
            Self::NotFound { .. } => StatusCode::NOT_FOUND,
            Self::Validation { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            Self::BadRequest { .. } | Self::MalformedJson { .. } => StatusCode::BAD_REQUEST,
            Self::UnsupportedMediaType { .. } => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            Self::PayloadTooLarge { .. } | Self::ArchiveTooLarge(_) => {
                StatusCode::PAYLOAD_TOO_LARGE
            }
            Self::Conflict(_) => StatusCode::CONFLICT,
            Self::QueueFull { .. } => StatusCode::TOO_MANY_REQUESTS,
            Self::Unavailable(_) | Self::StorageUnavailable(_) | Self::Overloaded { .. } => {
                StatusCode::SERVICE_UNAVAILABLE
            }
            Self::Timeout { .. } => StatusCode::REQUEST_TIMEOUT,
            Self::Unauthorized => StatusCode::UNAUTHORIZED,
            Self::Forbidden => StatusCode::FORBIDDEN,
            Self::Database(_) | Self::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    fn slug(&self) -> &'static str {
        match self {
            Self::NotFound { .. } => "not-found",
            Self::Validation { .. } => "validation-error",
            Self::BadRequest { .. } => "bad-request",
            Self::MalformedJson { .. } => "malformed-json",
            Self::UnsupportedMediaType { .. } => "unsupported-media-type",
            Self::PayloadTooLarge { .. } | Self::ArchiveTooLarge(_) => "payload-too-large",
            Self::Conflict(_) => "conflict",
            Self::QueueFull { .. } => "queue-full",
            Self::Unavailable(_) => "unavailable",
            Self::StorageUnavailable(_) => "storage-unavailable",
            Self::Overloaded { .. } => "overloaded",
            Self::Timeout { .. } => "timeout",
            Self::Unauthorized => "unauthorized",
            Self::Forbidden => "forbidden",
            Self::Database(_) | Self::Internal(_) => "internal-error",
        }
    }

    /// The problem document for this error.
    pub fn to_problem(&self) -> Problem {
        let status = self.status_code();
        let mut p = Problem {
            kind: format!("/problems/{}", self.slug()),
            title: status.canonical_reason().unwrap_or("Error").to_owned(),
            status: status.as_u16(),
            detail: self.to_string(),
            field: None,
            rule: None,
            line: None,
            column: None,
        };
        match self {
            Self::Validation { field, rule, .. } => {
                p.field = Some(field.clone());
                p.rule = Some((*rule).to_owned());
            }
            Self::BadRequest { field, .. } => p.field = field.clone(),
            Self::MalformedJson { line, column, .. } => {
                (p.line, p.column) = (Some(*line), Some(*column))
            }
            _ => {}
        }
        p
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        match &self {
            Self::Database(e) => tracing::error!(error = %e, "request failed"),
            Self::Internal(e) => tracing::error!(error = format!("{e:#}"), "request failed"),
            Self::Unavailable(_) | Self::StorageUnavailable(_) => {
                tracing::warn!(error = %self, "request refused")
            }
            _ => {}
        }
        let body = serde_json::to_vec(&self.to_problem()).expect("problems serialise");
        let mut response = (self.status_code(), body).into_response();
        let headers = response.headers_mut();
        headers.insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/problem+json"),
        );
        match self {
            Self::QueueFull { retry_after, .. } | Self::Overloaded { retry_after } => {
                headers.insert(header::RETRY_AFTER, HeaderValue::from(retry_after));
            }
            Self::Unauthorized => {
                headers.insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
            }
            _ => {}
        }
        response
    }
}
