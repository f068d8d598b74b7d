//! The OpenAPI 3.1 document, generated from the handlers' `#[utoipa::path]` annotations and
//! the DTOs' `ToSchema` derives, and a self-contained docs page that renders it.

use std::sync::OnceLock;

use axum::Json;
use axum::response::Html;
use utoipa::OpenApi;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "aortagen",
        description = "Synthetic cohorts of aortic shapes from a generative neural signed-distance \
                       model. Meshes are in millimetres unless `units=unit` (the shape's unit ball); \
                       Chamfer distances are squared distances in unit-ball coordinates; signed \
                       distances are negative inside.",
        license(name = "MIT OR Apache-2.0"),
    ),
    tags(
        (name = "cohorts", description = "Request and follow synthetic cohorts"),
        (name = "shapes", description = "Generated shapes and their meshes"),
        (name = "models", description = "Registered generative models"),
        (name = "jobs", description = "Background work"),
        (name = "reports", description = "Plots (SVG) and self-contained HTML reports of models and cohorts"),
        (name = "operations", description = "Health, metrics and documentation"),
    )
)]
struct ApiDoc;

/// The document's info and tags; paths are added by the routers.
pub fn base_document() -> utoipa::openapi::OpenApi {
    let mut doc = ApiDoc::openapi();
    doc.info.version = crate::VERSION.to_owned();
    doc
}

/// The full generated document.
pub fn document() -> &'static utoipa::openapi::OpenApi {
    static DOC: OnceLock<utoipa::openapi::OpenApi> = OnceLock::new();
    DOC.get_or_init(|| super::api_router().split_for_parts().1)
}

/// The document as committed in `openapi/openapi.json` (pretty, trailing newline).
pub fn document_json() -> String {
    let mut json = serde_json::to_string_pretty(document()).expect("the document serialises");
    json.push('\n');
    json
}

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(get_openapi))
        .routes(routes!(get_docs))
}

/// The OpenAPI document of this service.
#[utoipa::path(get, path = "/openapi.json", tag = "operations",
    responses((status = 200, description = "OpenAPI 3.1 document", content_type = "application/json")))]
async fn get_openapi() -> Json<&'static utoipa::openapi::OpenApi> {
    Json(document())
}

/// A human-readable API reference rendered in the browser from `/openapi.json`; the page is
/// self-contained (no external scripts or styles).
#[utoipa::path(get, path = "/docs", tag = "operations",
    responses((status = 200, description = "HTML page", content_type = "text/html")))]
async fn get_docs() -> Html<&'static str> {
    Html(include_str!("docs.html"))
}
