//! Generated shapes: listing per cohort, provenance, and mesh downloads converted on the fly
//! from the stored unit-ball mesh to the requested format and units.

use axum::Json;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::cohorts::{load as load_cohort, next_offset, page};
use super::error::{ApiError, Problem, Result};
use super::extractors::{ApiQuery, parse_id};
use super::mesh_cache::MeshKey;
use super::simulation_meshes::{self, SimulationQuery, param_error};
use crate::anatomy::shape::ShapeAnatomy;
use crate::cohort::seeds::SEED_SCHEME;
use crate::cohort::{AnchorShare, ShapeProvenance};
use crate::db::{self, shapes::ShapeRow};
use crate::formats::mesh_blob;
use crate::formats::{MeshFormat, MeshMetadata, write_mesh};
use crate::simulation::MeshRequest;
use crate::telemetry::spawn_blocking_with_span;

/// A generated shape with its provenance.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ShapeView {
    /// Shape id.
    pub id: i64,
    /// Owning cohort.
    pub cohort_id: i64,
    /// Position within the cohort (0-based).
    pub index: i64,
    /// How it was made.
    pub provenance: Provenance,
    /// Vertex count.
    pub vertex_count: i64,
    /// Triangle count.
    pub triangle_count: i64,
    /// Surface area (mm²).
    pub area_mm2: f64,
    /// Enclosed volume (mm³).
    pub volume_mm3: f64,
    /// Units of downloads by default.
    pub units: &'static str,
    /// Unit ball → mm: p_mm = p_unit · radius + centre.
    pub transform: Transform,
    /// Sign and orientation conventions.
    pub conventions: &'static str,
    /// Download URL (add `?format=` and `&units=`).
    pub mesh_url: String,
    /// SHA-256 of the stored unit-ball mesh in its canonical encoding (what `aortagen
    /// generate` records as `mesh_sha256` for the same shape).
    pub mesh_sha256: String,
    /// Chamfer distance (squared, unit-ball coordinates) to the nearest training shape, as
    /// reconstructed by the model at this shape's resolution: how far it is from disclosing
    /// one training patient.
    pub novelty_cd: Option<f64>,
    /// Index of that training shape.
    pub nearest_training_index: Option<i64>,
    /// Draws rejected for being closer than the cohort's `min_novelty` (at most 10).
    pub redraws: i64,
    /// False when no draw reached the cohort's `min_novelty` and the most novel one was
    /// kept; true otherwise.
    pub novelty_met: Option<bool>,
    /// Anatomical measurements in mm (null when they failed; see `anatomy_error`).
    pub anatomy: Option<ShapeAnatomy>,
    /// Why the shape could not be measured as an aortic root nor as a vessel.
    pub anatomy_error: Option<String>,
    /// Face table of the capped simulation mesh with default options (wall, inlet,
    /// outlets: area, centroid, outward normal, equivalent diameter, perimeter), once it
    /// has been made by a download or `faces_url`; null before (and in shape lists).
    #[schema(value_type = Option<Vec<Object>>)]
    pub faces: Option<serde_json::Value>,
    /// Why no simulation mesh could be made with default options, when that was tried.
    pub faces_error: Option<String>,
    /// The face table and sidecar, made on request (add simulation parameters as for
    /// `mesh_url`).
    pub faces_url: String,
}

/// The model, training shapes, weights, seeds and resolution a shape came from (the record
/// `aortagen generate` writes beside each mesh holds the same), with the anchors' ids.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct Provenance {
    /// How it was made.
    #[serde(flatten)]
    pub shape: ShapeProvenance,
    /// Fitted anchors mixed as well (see `POST /v1/models/{id}/fit`); their weights follow
    /// the training shapes' in `weights`.
    pub anchor_ids: Vec<i64>,
}

/// A unit-ball transform.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct Transform {
    /// Centre in mm.
    pub centre: [f64; 3],
    /// Scale in mm per unit.
    pub radius: f64,
}

const CONVENTIONS: &str = "triangles counter-clockwise seen from outside (outward normals); \
    signed distance negative inside";

impl ShapeView {
    fn from_row(s: ShapeRow) -> Self {
        let weights = s.weights.0;
        let sampler = s.sampler.map(|j| j.0);
        let k = s.training_indices.0.len() + usize::from(sampler.is_some());
        let names = s.anchor_names.map(|n| n.0).unwrap_or_default();
        let anchors = names
            .into_iter()
            .zip(weights.iter().skip(k))
            .map(|(name, &weight)| AnchorShare { name, weight })
            .collect();
        Self {
            id: s.shape_id,
            cohort_id: s.cohort_id,
            index: s.shape_index,
            provenance: Provenance {
                shape: ShapeProvenance {
                    model_id: s.model_id,
                    training_indices: s.training_indices.0,
                    weights,
                    anchors,
                    seed: s.seed as u64,
                    cohort_seed: s.cohort_seed as u64,
                    seed_scheme: SEED_SCHEME,
                    resolution: s.resolution,
                    software_version: s.software_version,
                    latent_noise: s.latent_noise,
                    selection: s.selection,
                    attempt: s.attempt,
                    candidates: s.candidates,
                    targets_met: s.targets_met.map(bool::from),
                    sampler,
                },
                anchor_ids: s.anchor_ids.map(|a| a.0).unwrap_or_default(),
            },
            vertex_count: s.vertex_count,
            triangle_count: s.triangle_count,
            area_mm2: s.area_mm2,
            volume_mm3: s.volume_mm3,
            units: "mm",
            transform: Transform {
                centre: [s.centre_x, s.centre_y, s.centre_z],
                radius: s.radius,
            },
            conventions: CONVENTIONS,
            mesh_url: format!("/v1/shapes/{}/mesh", s.shape_id),
            mesh_sha256: s.mesh_sha256,
            novelty_cd: s.novelty_cd,
            nearest_training_index: s.nearest_training_index,
            redraws: s.redraws,
            novelty_met: s.novelty_met.map(bool::from),
            anatomy: s.anatomy.map(|a| a.0),
            anatomy_error: s.anatomy_error,
            faces: None,
            faces_error: None,
            faces_url: format!("/v1/shapes/{}/faces", s.shape_id),
        }
    }
}

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_cohort_shapes))
        .routes(routes!(get_shape))
        .routes(routes!(get_shape_mesh))
}

/// Page parameters.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct PageQuery {
    /// Page size, 1–100 (default 20).
    pub limit: Option<i64>,
    /// Items to skip (default 0).
    pub offset: Option<i64>,
}

/// A page of shapes.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ShapePage {
    /// Shapes in index order.
    pub items: Vec<ShapeView>,
    /// Offset of the next page, when there may be one.
    pub next_offset: Option<i64>,
}

/// The cohort's stored shapes in index order.
#[utoipa::path(get, path = "/v1/cohorts/{id}/shapes", tag = "shapes",
    params(("id" = i64, Path, description = "Cohort id"), PageQuery),
    responses((status = 200, body = ShapePage),
              (status = 400, body = Problem, content_type = "application/problem+json", description = "Bad limit or offset"),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn list_cohort_shapes(
    State(state): State<AppState>,
    Path(id): Path<String>,
    ApiQuery(q): ApiQuery<PageQuery>,
) -> Result<Json<ShapePage>> {
    let cohort = load_cohort(&state, parse_id("cohort", &id)?, &id).await?;
    let (limit, offset) = page(q.limit, q.offset)?;
    let rows = db::shapes::list_for_cohort(&state.pool, cohort.cohort_id, limit, offset).await?;
    let next_offset = next_offset(rows.len(), limit, offset);
    let items = rows.into_iter().map(ShapeView::from_row).collect();
    Ok(Json(ShapePage { items, next_offset }))
}

/// One shape: provenance, counts, area, volume, units, and the face table of its
/// simulation mesh once made.
#[utoipa::path(get, path = "/v1/shapes/{id}", tag = "shapes",
    params(("id" = i64, Path, description = "Shape id")),
    responses((status = 200, body = ShapeView),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn get_shape(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<ShapeView>> {
    let row = db::shapes::get(&state.pool, parse_id("shape", &id)?)
        .await?
        .ok_or_else(|| ApiError::not_found("shape", &id))?;
    let (faces, faces_error) = simulation_meshes::stored_faces(&state, &row).await?;
    Ok(Json(ShapeView {
        faces,
        faces_error,
        ..ShapeView::from_row(row)
    }))
}

/// The units a mesh is served in, the default first: millimetres, or the shape's unit ball.
pub const UNITS: [&str; 2] = ["mm", "unit"];

/// Download options.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct MeshQuery {
    /// glb (default), gltf, stl, obj or ply for the closed surface; vtp (default), vtk,
    /// stl (one solid per face), obj (one group per face) or glb (one primitive per face)
    /// with `openings=capped|open`.
    #[param(value_type = Option<DownloadFormat>)]
    pub format: Option<String>,
    /// mm (default) or unit (the shape's unit ball; closed surface only).
    pub units: Option<String>,
}

/// Every `format` of a download.
#[derive(Debug, Clone, Copy, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum DownloadFormat {
    /// Binary glTF (one primitive per face for simulation meshes).
    Glb,
    /// glTF with embedded buffers (closed surface).
    Gltf,
    /// Binary STL (one named solid per face, ASCII, for simulation meshes).
    Stl,
    /// Wavefront OBJ (one group per face for simulation meshes).
    Obj,
    /// Binary PLY (closed surface).
    Ply,
    /// VTK XML PolyData with a `ModelFaceID` cell array (simulation meshes).
    Vtp,
    /// Legacy VTK PolyData with `ModelFaceID` (simulation meshes).
    Vtk,
}

/// The shape's mesh: the closed surface as generated (content never changes for a shape
/// id: strong ETag, immutable caching), or with `openings=capped|open` its simulation mesh,
/// labelled per face, made once per shape and options (seconds with remeshing) and then
/// read back.
#[utoipa::path(get, path = "/v1/shapes/{id}/mesh", tag = "shapes",
    params(("id" = i64, Path, description = "Shape id"), MeshQuery, SimulationQuery),
    responses((status = 200, description = "The mesh in the requested format (model/gltf-binary by default; vtp for simulation meshes)",
               content(("model/gltf-binary"), ("model/gltf+json"), ("model/stl"), ("model/obj"), ("application/x-ply"), ("application/vnd.vtk.vtp+xml"), ("application/vnd.vtk"))),
              (status = 304, description = "Matches If-None-Match"),
              (status = 400, body = Problem, content_type = "application/problem+json", description = "Unknown format, units or openings, a parameter out of range, or a simulation parameter for the closed surface; `field` names it"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 422, body = Problem, content_type = "application/problem+json", description = "No simulation mesh for this shape (openings not found, a cut missing the surface), or `remesh_mm` finer than the service's remesh limit (`--max-remesh-triangles`, rule `budget`, checked before any work; the message names the finest edge length within it); `field` names the parameter to change, or `openings`"),
              (status = 503, body = Problem, content_type = "application/problem+json", description = "Too many simulation meshes being made; retry after Retry-After")))]
async fn get_shape_mesh(
    State(state): State<AppState>,
    Path(id): Path<String>,
    ApiQuery(q): ApiQuery<MeshQuery>,
    ApiQuery(sim): ApiQuery<SimulationQuery>,
    headers: HeaderMap,
) -> Result<Response> {
    let request = MeshRequest::parse(q.format.as_deref(), &sim.params()).map_err(param_error)?;
    let given = q.units.as_deref().unwrap_or(UNITS[0]);
    let units = match UNITS.iter().find(|known| **known == given) {
        Some(known) => *known,
        None => {
            let u = given;
            let message = format!("unknown units {u:?}; use {}", UNITS.join(" or "));
            return Err(ApiError::BadRequest {
                field: Some("units".into()),
                message,
            });
        }
    };
    let shape_id = parse_id("shape", &id)?;
    let shape = db::shapes::get(&state.pool, shape_id)
        .await?
        .ok_or_else(|| ApiError::not_found("shape", &id))?;
    let format = match request {
        MeshRequest::Closed(format) => format,
        MeshRequest::Simulation { .. } if units != "mm" => {
            return Err(ApiError::BadRequest {
                field: Some("units".into()),
                message: "simulation meshes are written in mm".into(),
            });
        }
        MeshRequest::Simulation { format, request } => {
            return simulation_meshes::download(&state, shape, format, request, &headers).await;
        }
    };
    let etag = format!(
        "\"{}-{}-{units}\"",
        &shape.mesh_sha256[..32],
        format.extension()
    );
    let cache = [
        (header::ETAG, etag.clone()),
        (header::CACHE_CONTROL, CACHE_FOREVER.to_owned()),
    ];
    if if_none_match(&headers, &etag) {
        return Ok((StatusCode::NOT_MODIFIED, cache).into_response());
    }
    let key = MeshKey {
        shape_id,
        cohort_id: shape.cohort_id,
        mesh_sha256: shape.mesh_sha256.clone(),
        format: format.extension(),
        units,
    };
    let bytes = match state.mesh_cache.get(&key) {
        Some(bytes) => bytes,
        None => {
            let bytes = Bytes::from(encode_mesh(&state, shape, format, units).await?);
            state.mesh_cache.insert(key, bytes.clone());
            bytes
        }
    };
    let disposition = format!(
        "attachment; filename=\"shape-{shape_id}.{}\"",
        format.extension()
    );
    let headers = [
        (header::CONTENT_TYPE, content_type(format).to_owned()),
        (header::CONTENT_DISPOSITION, disposition),
    ];
    Ok((cache, headers, bytes).into_response())
}

/// Caching of a shape's closed mesh and thumbnail, with a strong ETag from the mesh's
/// SHA-256. Immutable caching is honest because a shape's content never changes and its id
/// is never given to another shape, even after it is deleted (`crate::db::ids`): a URL a
/// browser or CDN keeps can only ever name these bytes, or nothing.
pub(super) const CACHE_FOREVER: &str = "public, max-age=31536000, immutable";

/// Reads the stored unit-ball mesh and writes it in `format` and `units`, off the executor.
pub(super) async fn encode_mesh(
    state: &AppState,
    shape: ShapeRow,
    format: MeshFormat,
    units: &'static str,
) -> Result<Vec<u8>> {
    let shape_id = shape.shape_id;
    let stored = state
        .jobs
        .objects
        .shape_mesh(&state.pool, shape_id)
        .await?
        .ok_or_else(|| ApiError::not_found("shape", shape_id.to_string()))?;
    let view = ShapeView::from_row(shape);
    let meta = MeshMetadata {
        units: units.to_owned(),
        generator: format!("aortagen {}", crate::VERSION),
        extras: serde_json::json!({ "shape_id": view.id, "cohort_id": view.cohort_id,
            "index": view.index, "provenance": view.provenance }),
    };
    let bytes = spawn_blocking_with_span(move || -> anyhow::Result<Vec<u8>> {
        let unit = mesh_blob::decode(&stored.mesh)?;
        let transform = stored.transform();
        let mesh = if units == "mm" {
            transform.mesh_to_mesh_units(&unit)
        } else {
            unit
        };
        Ok(write_mesh(&mesh, format, &meta)?)
    })
    .await
    .map_err(anyhow::Error::from)??;
    Ok(bytes)
}

fn content_type(format: MeshFormat) -> &'static str {
    match format {
        MeshFormat::Glb => "model/gltf-binary",
        MeshFormat::Gltf => "model/gltf+json",
        MeshFormat::Stl => "model/stl",
        MeshFormat::Obj => "model/obj",
        MeshFormat::Ply => "application/x-ply",
    }
}

/// Whether `If-None-Match` names `etag` (or `*`).
pub(super) fn if_none_match(headers: &HeaderMap, etag: &str) -> bool {
    headers
        .get_all(header::IF_NONE_MATCH)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|t| t.trim() == etag || t.trim() == "*")
}
