//! `GET /v1/shapes/{id}/thumbnail.png`: a small picture of a generated shape drawn by the
//! project's own software renderer, so a dashboard can show a cohort as a grid without
//! downloading every mesh. A picture is rendered once, off the async executor, and kept in
//! the database beside its shape; renders run at most two at a time so a page full of
//! thumbnails cannot fill the blocking pool with large frame buffers.

use std::sync::OnceLock;

use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use tokio::sync::Semaphore;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::error::{ApiError, Problem, Result};
use super::extractors::parse_id;
use crate::db;
use crate::formats::mesh_blob;
use crate::render::{View, encode_png, render_meshes};
use crate::telemetry::spawn_blocking_with_span;

/// Side of a thumbnail in pixels (sharp at 128 CSS pixels on a 2× display).
pub const THUMBNAIL_SIZE: u32 = 256;

/// Renders in progress at once.
const CONCURRENT_RENDERS: usize = 2;

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(get_shape_thumbnail))
}

/// A 256×256 PNG of the shape (three-quarter view, +z up), rendered on first request and
/// cached. Content never changes for a shape id: strong ETag, immutable caching.
#[utoipa::path(get, path = "/v1/shapes/{id}/thumbnail.png", tag = "shapes",
    params(("id" = i64, Path, description = "Shape id")),
    responses((status = 200, description = "PNG picture", content_type = "image/png"),
              (status = 304, description = "Matches If-None-Match"),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn get_shape_thumbnail(
    State(state): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response> {
    let shape_id = parse_id("shape", &id)?;
    let shape = db::shapes::get(&state.pool, shape_id)
        .await?
        .ok_or_else(|| ApiError::not_found("shape", &id))?;
    let etag = format!("\"{}-thumb{THUMBNAIL_SIZE}\"", &shape.mesh_sha256[..32]);
    let cache = [
        (header::ETAG, etag.clone()),
        (
            header::CACHE_CONTROL,
            super::shapes::CACHE_FOREVER.to_owned(),
        ),
    ];
    if super::shapes::if_none_match(&headers, &etag) {
        return Ok((StatusCode::NOT_MODIFIED, cache).into_response());
    }
    let sha = shape.mesh_sha256.as_str();
    let png = match db::thumbnails::get(&state.pool, shape_id, sha, THUMBNAIL_SIZE).await? {
        Some(png) => png,
        None => {
            let png = render_thumbnail(&state, shape_id).await?;
            // A cache that cannot be written (read-only database, full disk) costs a
            // re-render next time, not the answer.
            if let Err(e) =
                db::thumbnails::put(&state.pool, shape_id, sha, THUMBNAIL_SIZE, &png).await
            {
                tracing::warn!(shape_id, error = %e, "thumbnail not cached");
            }
            png
        }
    };
    Ok((cache, [(header::CONTENT_TYPE, "image/png")], png).into_response())
}

/// Decodes the stored unit-ball mesh and draws it, waiting for a render slot first.
async fn render_thumbnail(state: &AppState, shape_id: i64) -> Result<Vec<u8>> {
    static SLOTS: OnceLock<Semaphore> = OnceLock::new();
    let _slot = SLOTS
        .get_or_init(|| Semaphore::new(CONCURRENT_RENDERS))
        .acquire()
        .await
        .map_err(anyhow::Error::from)?;
    let stored = state
        .jobs
        .objects
        .shape_mesh(&state.pool, shape_id)
        .await?
        .ok_or_else(|| ApiError::not_found("shape", shape_id.to_string()))?;
    let png = spawn_blocking_with_span(move || -> anyhow::Result<Vec<u8>> {
        let mesh = mesh_blob::decode(&stored.mesh)?;
        let view = View {
            supersample: 2,
            ..View::default()
        };
        let image = render_meshes(&[&mesh], THUMBNAIL_SIZE, THUMBNAIL_SIZE, &view)?;
        Ok(encode_png(&image)?)
    })
    .await
    .map_err(anyhow::Error::from)??;
    Ok(png)
}
