//! The dashboard: a browser page served at `/` that lists models and cohorts, follows their
//! jobs live, creates cohorts through a form, shows a cohort's statistics and thumbnails and
//! draws shapes in a 3-D viewer. Its source is `web/` (three.js, bundled by Vite); the built
//! files in `web/dist/` are committed and compiled into the binary, so the service needs no
//! node, no CDN and no network to serve it.
//!
//! The page and its assets hold no data and are public even when reads are protected: the
//! page asks for a key and sends it as a bearer token on its API calls. `GET /v1/access` tells
//! the page whether it must ask.

use std::sync::OnceLock;

use axum::Json;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde::Serialize;
use sha2::{Digest, Sha256};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;

/// One built file of the page.
struct Asset {
    path: &'static str,
    content_type: &'static str,
    bytes: &'static [u8],
}

/// The built page: `web/dist/` as produced by `npm run build` in `web/`.
const ASSETS: [Asset; 3] = [
    Asset {
        path: "/",
        content_type: "text/html; charset=utf-8",
        bytes: include_bytes!("../../web/dist/index.html"),
    },
    Asset {
        path: "/assets/app.js",
        content_type: "text/javascript; charset=utf-8",
        bytes: include_bytes!("../../web/dist/assets/app.js"),
    },
    Asset {
        path: "/assets/app.css",
        content_type: "text/css; charset=utf-8",
        bytes: include_bytes!("../../web/dist/assets/app.css"),
    },
];

/// What the page may load: only this origin, plus the object URLs it makes of downloads
/// and pictures fetched with a key; nothing may frame it.
const CONTENT_SECURITY_POLICY: &str = "default-src 'self'; img-src 'self' blob: data:; \
     connect-src 'self'; style-src 'self'; script-src 'self'; object-src 'none'; \
     base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

/// Whether `path` is part of the page (served without a key whatever the configuration).
pub fn is_public(path: &str) -> bool {
    path == ACCESS_PATH || ASSETS.iter().any(|a| a.path == path)
}

/// The route that tells the page what needs a key.
pub const ACCESS_PATH: &str = "/v1/access";

/// The page's routes (undocumented: they are not part of the API) and `GET /v1/access`.
pub(super) fn router() -> OpenApiRouter<AppState> {
    let mut router = OpenApiRouter::new().routes(routes!(get_access));
    for (index, asset) in ASSETS.iter().enumerate() {
        router = router.route(asset.path, get(move |h: HeaderMap| serve(index, h)));
    }
    router
}

/// Serves asset `index` with a content ETag; `no-cache` so a new binary's page is used at
/// once, the ETag so an unchanged one costs a 304.
async fn serve(index: usize, headers: HeaderMap) -> Response {
    let asset = &ASSETS[index];
    let etag = etag(index);
    let fresh = headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == etag));
    let mut response = if fresh {
        StatusCode::NOT_MODIFIED.into_response()
    } else {
        ([(header::CONTENT_TYPE, asset.content_type)], asset.bytes).into_response()
    };
    let h = response.headers_mut();
    h.insert(header::ETAG, HeaderValue::from_str(etag).expect("hex etag"));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    if asset.path == "/" {
        h.insert(
            header::CONTENT_SECURITY_POLICY,
            HeaderValue::from_static(CONTENT_SECURITY_POLICY),
        );
        h.insert(
            header::REFERRER_POLICY,
            HeaderValue::from_static("same-origin"),
        );
    }
    response
}

/// A strong ETag per asset, computed once.
fn etag(index: usize) -> &'static str {
    static TAGS: OnceLock<Vec<String>> = OnceLock::new();
    let tags = TAGS.get_or_init(|| {
        ASSETS
            .iter()
            .map(|a| {
                let digest = Sha256::digest(a.bytes);
                let hex: String = digest[..12].iter().map(|b| format!("{b:02x}")).collect();
                format!("\"{hex}\"")
            })
            .collect()
    });
    &tags[index]
}

/// What needs an API key on this service.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct AccessInfo {
    /// Whether POST, PUT, PATCH and DELETE need `Authorization: Bearer <key>`.
    pub writes_need_key: bool,
    /// Whether reads need it too (`--protect-reads`).
    pub reads_need_key: bool,
}

/// Whether requests need an API key (always public, so a client knows to ask for one).
#[utoipa::path(get, path = "/v1/access", tag = "operations",
    responses((status = 200, body = AccessInfo)))]
async fn get_access(State(state): State<AppState>) -> Json<AccessInfo> {
    let keys = state.access.is_enabled();
    Json(AccessInfo {
        writes_need_key: keys,
        reads_need_key: keys && state.access.protects_reads(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_and_its_assets_are_public_and_nothing_else() {
        for path in ["/", "/assets/app.js", "/assets/app.css", "/v1/access"] {
            assert!(is_public(path), "{path}");
        }
        for path in [
            "/v1/cohorts",
            "/assets/other.js",
            "/index.html",
            "/v1/access/x",
        ] {
            assert!(!is_public(path), "{path}");
        }
    }

    #[test]
    fn the_page_loads_the_bundled_script_and_style() {
        let html = std::str::from_utf8(ASSETS[0].bytes).unwrap();
        assert!(html.contains("/assets/app.js"), "{html}");
        assert!(html.contains("/assets/app.css"), "{html}");
        assert!(
            !html.contains("http://") && !html.contains("https://"),
            "{html}"
        );
    }

    #[test]
    fn etags_differ_between_assets_and_are_quoted() {
        let tags: Vec<&str> = (0..ASSETS.len()).map(etag).collect();
        assert!(tags.iter().all(|t| t.starts_with('"') && t.ends_with('"')));
        assert_ne!(tags[0], tags[1]);
        assert_ne!(tags[1], tags[2]);
    }
}
