//! Protection of state-changing requests against cross-site request forgery, with or
//! without API keys. A page on another site can make a visitor's browser send a POST to this
//! service (a plain HTML form, or `fetch` in `no-cors` mode) without the preflight that
//! would stop other requests; with no key configured nothing else would refuse it.
//!
//! An unsafe request (POST, PUT, PATCH, DELETE) is refused with a 403 problem document
//! when any of these says it comes from another site:
//! - `Sec-Fetch-Site` is `cross-site` or `same-site` (browsers set it and pages cannot);
//! - `Origin` is `null` or names another host than `Host` (or `X-Forwarded-Host`, which a
//!   cross-site page cannot set without a preflight);
//! - its `Content-Type` is one an HTML form can send (`application/x-www-form-urlencoded`,
//!   `multipart/form-data`, `text/plain`) and the endpoint does not take that type, so a
//!   form cannot reach an endpoint whose body is JSON or that reads no body, even from a
//!   browser that sends no `Origin`.
//!
//! Clients that are not browsers (curl, scripts, SDKs) send none of these headers and are
//! not affected; the dashboard served at `/` is same-origin.

use std::collections::HashMap;
use std::sync::OnceLock;

use axum::extract::{MatchedPath, Request};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use utoipa::openapi::RefOr;

use super::error::Problem;

/// Content types an HTML form can submit without a CORS preflight.
pub const FORM_CONTENT_TYPES: [&str; 3] = [
    "application/x-www-form-urlencoded",
    "multipart/form-data",
    "text/plain",
];

/// Why a request was refused: the header that gave it away and a sentence saying why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refusal {
    /// `Sec-Fetch-Site`, `Origin` or `Content-Type`.
    pub header: &'static str,
    /// The explanation sent as the problem's `detail`.
    pub reason: String,
}

impl IntoResponse for Refusal {
    fn into_response(self) -> Response {
        let problem = Problem {
            kind: "/problems/cross-site-request".into(),
            title: "Forbidden".into(),
            status: StatusCode::FORBIDDEN.as_u16(),
            detail: self.reason,
            field: Some(self.header.into()),
            rule: Some("same-origin".into()),
            line: None,
            column: None,
        };
        let body = serde_json::to_vec(&problem).expect("problems serialise");
        let mut response = (StatusCode::FORBIDDEN, body).into_response();
        response.headers_mut().insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/problem+json"),
        );
        response
    }
}

/// Decides on a request from its method, headers and the media types its endpoint takes
/// as a body (`None` when the route is unknown: the fallback answers those).
pub fn check(
    method: &Method,
    headers: &HeaderMap,
    accepted: Option<&[String]>,
) -> Result<(), Refusal> {
    if !matches!(
        *method,
        Method::POST | Method::PUT | Method::PATCH | Method::DELETE
    ) {
        return Ok(());
    }
    let text = |name: header::HeaderName| headers.get(name).and_then(|v| v.to_str().ok());
    if let Some(site) = text(header::HeaderName::from_static("sec-fetch-site")) {
        let site = site.trim().to_ascii_lowercase();
        if site == "cross-site" || site == "same-site" {
            return Err(Refusal {
                header: "Sec-Fetch-Site",
                reason: format!(
                    "a {} {method} is refused: state-changing requests must come from this \
                     service's own pages or from a client that is not a browser",
                    site
                ),
            });
        }
    }
    if let Some(origin) = text(header::ORIGIN) {
        let hosts = [
            text(header::HOST),
            text(header::HeaderName::from_static("x-forwarded-host")),
        ];
        if !hosts.into_iter().flatten().any(|h| same_host(origin, h)) {
            return Err(Refusal {
                header: "Origin",
                reason: format!(
                    "a {method} from origin {origin:?} is refused: it is not this service's \
                     origin, and state-changing requests from other sites are not accepted"
                ),
            });
        }
    }
    if let (Some(accepted), Some(content_type)) = (accepted, text(header::CONTENT_TYPE)) {
        let essence = essence(content_type);
        let is_form = FORM_CONTENT_TYPES.contains(&essence.as_str());
        if is_form && !accepted.contains(&essence) {
            let takes = if accepted.is_empty() {
                "takes no request body".to_owned()
            } else {
                format!("takes {}", accepted.join(" or "))
            };
            return Err(Refusal {
                header: "Content-Type",
                reason: format!(
                    "a {method} with Content-Type {essence} is refused: this endpoint {takes}, \
                     and form submissions are refused so that other sites cannot post to it"
                ),
            });
        }
    }
    Ok(())
}

/// Whether an `Origin` (`scheme://host[:port]`) names the authority `host`.
fn same_host(origin: &str, host: &str) -> bool {
    let authority = origin
        .trim()
        .split_once("://")
        .map_or("", |(_, rest)| rest.trim_end_matches('/'));
    !authority.is_empty() && authority.eq_ignore_ascii_case(host.trim())
}

/// The media type without parameters, lower case.
fn essence(content_type: &str) -> String {
    content_type
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase()
}

/// Request body media types of every documented operation, by method and route template.
fn documented_bodies() -> &'static HashMap<(Method, String), Vec<String>> {
    static BODIES: OnceLock<HashMap<(Method, String), Vec<String>>> = OnceLock::new();
    BODIES.get_or_init(|| {
        let mut map = HashMap::new();
        for (path, item) in &super::openapi::document().paths.paths {
            let ops = [
                (Method::POST, &item.post),
                (Method::PUT, &item.put),
                (Method::PATCH, &item.patch),
                (Method::DELETE, &item.delete),
            ];
            for (method, op) in ops {
                let Some(op) = op else { continue };
                let types = op
                    .request_body
                    .as_ref()
                    .map(|body| match body {
                        RefOr::T(body) => body.content.keys().cloned().collect(),
                        // Bodies are declared inline; a shared one would need the components.
                        RefOr::Ref(_) => Vec::new(),
                    })
                    .unwrap_or_default();
                map.insert((method, path.clone()), types);
            }
        }
        map
    })
}

/// The middleware: answers 403 before the key check, the handler and any body read.
pub async fn refuse_cross_site_writes(req: Request, next: Next) -> Response {
    let accepted = req.extensions().get::<MatchedPath>().and_then(|route| {
        documented_bodies().get(&(req.method().clone(), route.as_str().to_owned()))
    });
    match check(req.method(), req.headers(), accepted.map(Vec::as_slice)) {
        Ok(()) => next.run(req).await,
        Err(refusal) => {
            tracing::info!(header = refusal.header, "cross-site write refused");
            refusal.into_response()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(pairs: &[(&'static str, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (name, value) in pairs {
            h.insert(*name, HeaderValue::from_str(value).unwrap());
        }
        h
    }

    fn json_only() -> Vec<String> {
        vec!["application/json".to_owned()]
    }

    #[test]
    fn a_client_without_browser_headers_passes() {
        let h = headers(&[
            ("host", "127.0.0.1:8080"),
            ("content-type", "application/json"),
        ]);
        assert_eq!(check(&Method::POST, &h, Some(&json_only())), Ok(()));
        let upload = headers(&[("content-type", "multipart/form-data; boundary=x")]);
        let takes = vec![
            "multipart/form-data".to_owned(),
            "application/zip".to_owned(),
        ];
        assert_eq!(check(&Method::POST, &upload, Some(&takes)), Ok(()));
    }

    #[test]
    fn fetch_metadata_of_another_site_is_refused_for_writes_only() {
        for site in ["cross-site", "same-site", "Cross-Site"] {
            let h = headers(&[("sec-fetch-site", site)]);
            let refusal = check(&Method::DELETE, &h, Some(&[])).unwrap_err();
            assert_eq!(refusal.header, "Sec-Fetch-Site", "{site}");
            assert_eq!(check(&Method::GET, &h, None), Ok(()));
        }
        for site in ["same-origin", "none"] {
            let h = headers(&[("sec-fetch-site", site)]);
            assert_eq!(check(&Method::POST, &h, Some(&[])), Ok(()), "{site}");
        }
    }

    #[test]
    fn an_origin_must_name_the_host() {
        let ours = headers(&[
            ("host", "localhost:8080"),
            ("origin", "http://LOCALHOST:8080"),
        ]);
        assert_eq!(check(&Method::POST, &ours, Some(&[])), Ok(()));
        for origin in [
            "http://evil.example",
            "http://localhost:8081",
            "null",
            "localhost:8080",
        ] {
            let h = headers(&[("host", "localhost:8080"), ("origin", origin)]);
            let refusal = check(&Method::POST, &h, Some(&[])).unwrap_err();
            assert_eq!(refusal.header, "Origin", "{origin}");
            assert!(refusal.reason.contains(origin), "{}", refusal.reason);
        }
        let proxied = headers(&[
            ("host", "10.0.0.5:8080"),
            ("x-forwarded-host", "aortagen.example"),
            ("origin", "https://aortagen.example"),
        ]);
        assert_eq!(check(&Method::POST, &proxied, Some(&[])), Ok(()));
    }

    #[test]
    fn form_content_types_reach_only_endpoints_that_take_them() {
        for form in [
            "text/plain",
            "application/x-www-form-urlencoded",
            "multipart/form-data; boundary=b",
        ] {
            let h = headers(&[("content-type", form)]);
            let refusal = check(&Method::POST, &h, Some(&json_only())).unwrap_err();
            assert_eq!(refusal.header, "Content-Type", "{form}");
            assert!(
                refusal.reason.contains("takes application/json"),
                "{}",
                refusal.reason
            );
            let bodiless = check(&Method::POST, &h, Some(&[])).unwrap_err();
            assert!(bodiless.reason.contains("takes no request body"));
        }
        // Not a form type: the endpoint's own media-type check answers (415).
        let zip = headers(&[("content-type", "application/zip")]);
        assert_eq!(check(&Method::POST, &zip, Some(&json_only())), Ok(()));
        // An unknown route is left to the fallback (404).
        let text = headers(&[("content-type", "text/plain")]);
        assert_eq!(check(&Method::POST, &text, None), Ok(()));
    }

    #[test]
    fn the_refusal_is_a_problem_document() {
        let refusal = Refusal {
            header: "Origin",
            reason: "because".into(),
        };
        let response = refusal.into_response();
        assert_eq!(response.status(), StatusCode::FORBIDDEN);
        assert_eq!(
            response.headers()[header::CONTENT_TYPE],
            "application/problem+json"
        );
    }
}
