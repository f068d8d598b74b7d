//! Extractors whose rejections are problem documents: JSON bodies (415 wrong type, 413 too
//! large, 400 malformed with line/column, 422 naming the field), query strings (400) and
//! numeric path ids (404 when not a number, since such an id cannot exist).

use axum::extract::{FromRequest, FromRequestParts, Query, Request};
use axum::http::{header, request::Parts};
use serde::de::DeserializeOwned;

use super::error::ApiError;

/// A JSON body deserialised with precise errors.
#[derive(Debug, Clone)]
pub struct ApiJson<T>(pub T);

impl<S, T> FromRequest<S> for ApiJson<T>
where
    S: Send + Sync,
    T: DeserializeOwned,
{
    type Rejection = ApiError;

    async fn from_request(req: Request, _state: &S) -> Result<Self, Self::Rejection> {
        let content_type = req
            .headers()
            .get(header::CONTENT_TYPE)
            .map(|v| v.to_str().unwrap_or("(not text)").to_owned());
        if !content_type.as_deref().is_some_and(is_json) {
            return Err(ApiError::UnsupportedMediaType {
                expected: "application/json",
                got: content_type.unwrap_or_else(|| "no Content-Type".into()),
            });
        }
        let limit = req
            .extensions()
            .get::<JsonBodyLimit>()
            .map_or(usize::MAX, |l| l.0);
        let bytes = axum::body::to_bytes(req.into_body(), limit)
            .await
            .map_err(|e| {
                if is_length_limit(&e) {
                    ApiError::PayloadTooLarge { limit }
                } else {
                    ApiError::BadRequest {
                        field: None,
                        message: format!("cannot read the request body: {e}"),
                    }
                }
            })?;
        parse_json(&bytes).map(ApiJson)
    }
}

/// The JSON body limit, announced by the router through a request extension.
#[derive(Debug, Clone, Copy)]
pub struct JsonBodyLimit(pub usize);

fn is_length_limit(err: &axum::Error) -> bool {
    let mut cause: Option<&(dyn std::error::Error + 'static)> = Some(err);
    while let Some(e) = cause {
        if e.is::<http_body_util::LengthLimitError>() {
            return true;
        }
        cause = e.source();
    }
    false
}

fn is_json(content_type: &str) -> bool {
    let essence = content_type
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    essence == "application/json"
        || (essence.starts_with("application/") && essence.ends_with("+json"))
}

/// Deserialises JSON, classifying failures: syntax → 400 with position, data → 422 with
/// the JSON path of the offending field.
pub fn parse_json<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let de = &mut serde_json::Deserializer::from_slice(bytes);
    let result: Result<T, _> = serde_path_to_error::deserialize(de);
    let err = match result {
        Ok(value) => return Ok(value),
        Err(err) => err,
    };
    let path = err.path().to_string();
    let inner = err.into_inner();
    use serde_json::error::Category;
    match inner.classify() {
        Category::Data => {
            let message = strip_position(&inner.to_string());
            let (field, rule) = data_error_field(&path, &message);
            Err(ApiError::Validation {
                field,
                rule,
                message,
            })
        }
        Category::Syntax | Category::Eof | Category::Io => Err(ApiError::MalformedJson {
            line: inner.line(),
            column: inner.column(),
            message: strip_position(&inner.to_string()),
        }),
    }
}

/// Finds the field a data error is about: an unknown or missing field names itself in the
/// message; otherwise the path points at the offending value.
fn data_error_field(path: &str, message: &str) -> (String, &'static str) {
    let quoted = || message.split('`').nth(1).unwrap_or("").to_owned();
    // The path of an unknown field already ends with it; that of a missing one does not.
    let join = |name: String| match path {
        "." => name,
        p if p.rsplit('.').next() == Some(name.as_str()) => p.to_owned(),
        p => format!("{p}.{name}"),
    };
    if message.starts_with("unknown field") {
        (join(quoted()), "unknown-field")
    } else if message.starts_with("missing field") {
        (join(quoted()), "required")
    } else if message.starts_with("unknown variant") {
        (path.to_owned(), "enum")
    } else {
        (path.to_owned(), "type")
    }
}

fn strip_position(message: &str) -> String {
    match message.rfind(" at line ") {
        Some(i) => message[..i].to_owned(),
        None => message.to_owned(),
    }
}

/// A query string deserialised into `T`; failures are 400 problem documents.
#[derive(Debug, Clone)]
pub struct ApiQuery<T>(pub T);

impl<S, T> FromRequestParts<S> for ApiQuery<T>
where
    S: Send + Sync,
    T: DeserializeOwned,
{
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        Query::<T>::from_request_parts(parts, state)
            .await
            .map(|Query(q)| ApiQuery(q))
            .map_err(|e| {
                let message = e.body_text();
                ApiError::BadRequest {
                    field: query_field(&message).map(str::to_owned),
                    message,
                }
            })
    }
}

/// The parameter a query-string rejection is about: axum reports the path of the value
/// that failed to deserialise before its message (`…query string: seed: invalid digit`).
fn query_field(message: &str) -> Option<&str> {
    let rest = message.strip_prefix("Failed to deserialize query string: ")?;
    let (field, _) = rest.split_once(": ")?;
    let plain = !field.is_empty()
        && field
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    plain.then_some(field)
}

/// Parses a numeric id from a path segment; anything else cannot exist (404).
pub fn parse_id(what: &'static str, raw: &str) -> Result<i64, ApiError> {
    raw.parse::<i64>()
        .ok()
        .filter(|id| *id > 0)
        .ok_or_else(|| ApiError::not_found(what, raw))
}

/// A number within `1..=max`, named on `field`, or its default.
pub(super) fn bounded(
    field: &str,
    value: Option<u64>,
    max: u64,
    default: u64,
) -> Result<usize, ApiError> {
    match value {
        None => Ok(default as usize),
        Some(v) if (1..=max).contains(&v) => Ok(v as usize),
        Some(v) => {
            let msg = format!("must be an integer from 1 to {max}, got {v}");
            Err(ApiError::invalid(field, "range", msg))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Body {
        count: u32,
        inner: Option<Inner>,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Inner {
        x: f64,
    }

    fn err(json: &str) -> ApiError {
        parse_json::<Body>(json.as_bytes()).unwrap_err()
    }

    #[test]
    fn syntax_errors_report_line_and_column() {
        match err("{\n  \"count\": 3,,\n}") {
            ApiError::MalformedJson { line, column, .. } => assert_eq!((line, column), (2, 14)),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn data_errors_name_the_field_and_rule() {
        let cases = [
            (r#"{"count": 1, "colour": 2}"#, "colour", "unknown-field"),
            (
                r#"{"count": 1, "inner": {"x": 1, "y": 2}}"#,
                "inner.y",
                "unknown-field",
            ),
            (r#"{"count": "three"}"#, "count", "type"),
            (r#"{"inner": null}"#, "count", "required"),
        ];
        for (json, field, rule) in cases {
            match err(json) {
                ApiError::Validation {
                    field: f, rule: r, ..
                } => {
                    assert_eq!((f.as_str(), r), (field, rule), "{json}")
                }
                other => panic!("{json}: {other:?}"),
            }
        }
    }

    #[test]
    fn json_media_types_are_recognised() {
        assert!(is_json("application/json"));
        assert!(is_json("Application/JSON; charset=utf-8"));
        assert!(is_json("application/merge-patch+json"));
        assert!(!is_json("text/plain"));
        assert!(!is_json("application/jsonx"));
    }
}
