//! The OpenAPI 3.1 document, generated from the handlers' `#[utoipa::path]` annotations and
//! the DTOs' `ToSchema` derives, and a self-contained docs page that renders it.

use std::sync::OnceLock;

use axum::Json;
use axum::response::Html;
use utoipa::openapi::security::{Http, HttpAuthScheme, SecurityRequirement, SecurityScheme};
use utoipa::openapi::{ContentBuilder, Ref, ResponseBuilder};
use utoipa::{Modify, OpenApi};
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
        (name = "anchors", description = "New shapes fitted to a trained model (latent optimisation with the network frozen)"),
        (name = "jobs", description = "Background work"),
        (name = "reports", description = "Plots (SVG) and self-contained HTML reports of models and cohorts"),
        (name = "validation", description = "Reference populations of real patients and the validation of cohorts against them (shape and measurement level, acceptance criteria, credibility dossier)"),
        (name = "operations", description = "Health, metrics and documentation"),
    ),
    // Enumerations that query parameters and JSON-value fields name by `value_type`; the
    // routers collect only the schemas of bodies.
    components(schemas(
        super::shapes::DownloadFormat,
        super::simulation_meshes::OpeningsParam,
        super::simulation_meshes::KindParam,
        super::validations::ReferenceName,
    ))
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
    DOC.get_or_init(|| {
        let mut doc = super::api_router().split_for_parts().1;
        AccessDocs.modify(&mut doc);
        super::contract::write_rules(&mut doc);
        doc
    })
}

/// Documents the API-key scheme and the answers every route may give besides its own:
/// state-changing operations need `bearerAuth` when keys are configured, reads only when
/// reads are protected; the probes and metrics are public.
struct AccessDocs;

impl Modify for AccessDocs {
    fn modify(&self, doc: &mut utoipa::openapi::OpenApi) {
        let mut scheme = Http::new(HttpAuthScheme::Bearer);
        scheme.description = Some(
            "An API key configured with AORTAGEN_API_KEYS or AORTAGEN_API_KEYS_FILE. Needed for \
             POST, PUT, PATCH and DELETE once any key is configured, and for reads too with \
             AORTAGEN_PROTECT_READS=true."
                .into(),
        );
        doc.components
            .get_or_insert_with(Default::default)
            .add_security_scheme("bearerAuth", SecurityScheme::Http(scheme));
        let problem = |description: &str| {
            let content = ContentBuilder::new()
                .schema(Some(Ref::from_schema_name("Problem")))
                .build();
            ResponseBuilder::new()
                .description(description)
                .content("application/problem+json", content)
                .build()
        };
        for (path, item) in doc.paths.paths.iter_mut() {
            let path = path.as_str();
            if super::access::PUBLIC_PATHS.contains(&path) || super::dashboard::is_public(path) {
                continue;
            }
            let reads = [&mut item.get, &mut item.head, &mut item.options];
            for op in reads.into_iter().flatten() {
                op.security = Some(vec![
                    SecurityRequirement::default(),
                    SecurityRequirement::new("bearerAuth", Vec::<String>::new()),
                ]);
                let r = &mut op.responses.responses;
                let unauthorized = problem("No API key, when reads are protected");
                r.entry("401".into()).or_insert(unauthorized.into());
                let forbidden = problem("Not a valid API key, when reads are protected");
                r.entry("403".into()).or_insert(forbidden.into());
                let timeout = problem(
                    "The request took longer than the configured timeout (a simulation mesh \
                     made on request may)",
                );
                r.entry("408".into()).or_insert(timeout.into());
                let busy = problem("Too many requests in flight (see Retry-After)");
                r.entry("503".into()).or_insert(busy.into());
            }
            let writes = [
                &mut item.post,
                &mut item.put,
                &mut item.patch,
                &mut item.delete,
            ];
            for op in writes.into_iter().flatten() {
                op.security = Some(vec![SecurityRequirement::new(
                    "bearerAuth",
                    Vec::<String>::new(),
                )]);
                let r = &mut op.responses.responses;
                let unauthorized = problem("No API key (when keys are configured)");
                r.entry("401".into()).or_insert(unauthorized.into());
                let forbidden = problem(
                    "Not a valid API key, or a cross-site request (`Origin` or `Sec-Fetch-Site` of \
                     another site, or a form `Content-Type` the operation does not take)",
                );
                r.entry("403".into()).or_insert(forbidden.into());
                let timeout = problem("The request took longer than the configured timeout");
                r.entry("408".into()).or_insert(timeout.into());
                let unavailable = problem(
                    "Too many requests in flight (see Retry-After), or storage cannot take \
                     writes (read-only database, full disk)",
                );
                r.entry("503".into()).or_insert(unavailable.into());
            }
        }
    }
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
