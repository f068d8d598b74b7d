//! Simulation-ready meshes of generated shapes over HTTP: the labelled capped or open
//! surface in vtp, legacy vtk, multi-solid stl, grouped obj or per-face glb, and its face
//! table with boundary-condition data. The pipeline itself runs in
//! [`crate::jobs::simulation`] (off the executor, bounded, stored per shape and options);
//! the handlers here check parameters, wait for the prepared mesh and encode it.

use std::sync::Arc;

use axum::Json;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::error::{ApiError, Problem, Result};
use super::extractors::{ApiQuery, parse_id};
use super::shapes::if_none_match;
use crate::db::{self, shapes::ShapeRow};
use crate::formats::MeshMetadata;
use crate::jobs::simulation::{Admission, PrepareError, Prepared};
use crate::simulation::remesh;
use crate::simulation::request::parse_options;
use crate::simulation::{
    ParamError, PreparedSimulation, SimulationFormat, SimulationParams, SimulationRequest,
    SimulationSummary, Variant,
};
use crate::telemetry::spawn_blocking_with_span;

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(get_shape_faces))
}

/// What `openings` may be.
#[derive(Debug, Clone, Copy, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum OpeningsParam {
    /// The closed surface as generated.
    Closed,
    /// Openings cut flat and closed by labelled caps: watertight.
    Capped,
    /// Openings cut and left open: the wall only.
    Open,
}

/// What `kind` may be.
#[derive(Debug, Clone, Copy, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum KindParam {
    /// Decided from the shape.
    Auto,
    /// An aortic root: inlet at the annulus, outlet above the sinotubular junction.
    Root,
    /// An aorta with supra-aortic branches.
    Aorta,
    /// A vessel with two ends.
    Tube,
}

/// The parameters of a simulation mesh; given for the closed surface, each is refused.
#[derive(Debug, Default, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct SimulationQuery {
    /// `closed`, the surface as generated (default for glb, gltf, stl, obj, ply);
    /// `capped`, openings cut flat and closed by labelled caps (default for vtp, vtk);
    /// `open`, the openings left open.
    #[param(value_type = Option<OpeningsParam>)]
    pub openings: Option<String>,
    /// The rules the openings follow (default auto).
    #[param(value_type = Option<KindParam>)]
    pub kind: Option<String>,
    /// Target edge length of an isotropic remesh, mm (default: no remesh). Takes seconds:
    /// about ten for a 256³ shape, once per shape and options.
    pub remesh_mm: Option<f64>,
    /// Flow extensions: straight tubes appended at every opening, in diameters of the
    /// opening (default 0, none).
    pub extension_diameters: Option<f64>,
    /// Root: inlet below the annulus, mm (default 0).
    pub inlet_below_annulus_mm: Option<f64>,
    /// Root: outlet above the sinotubular junction, mm (default 20).
    pub outlet_above_stj_mm: Option<f64>,
    /// Aorta and tube: inlet and main outlet in from the vessel's ends, mm (default 20).
    pub end_trim_mm: Option<f64>,
    /// Aorta: branch outlets in from the branch ends, mm (default 8).
    pub branch_trim_mm: Option<f64>,
}

impl SimulationQuery {
    /// The parameters for [`crate::simulation::MeshRequest::parse`].
    pub fn params(&self) -> SimulationParams {
        SimulationParams {
            openings: self.openings.clone(),
            kind: self.kind.clone(),
            remesh_mm: self.remesh_mm,
            extension_diameters: self.extension_diameters,
            inlet_below_annulus_mm: self.inlet_below_annulus_mm,
            outlet_above_stj_mm: self.outlet_above_stj_mm,
            end_trim_mm: self.end_trim_mm,
            branch_trim_mm: self.branch_trim_mm,
        }
    }
}

/// A parameter at fault, as a 400 naming it.
pub fn param_error(e: ParamError) -> ApiError {
    ApiError::BadRequest {
        field: Some(e.field.to_owned()),
        message: e.message,
    }
}

/// Refuses, before any work, a remesh of a surface of `area_mm2` over the service's limit.
/// The stored closed surface stands for the capped one; the pipeline checks the capped
/// surface again, flow extensions included, before it remeshes.
pub fn check_remesh(state: &AppState, area_mm2: f64, request: &SimulationRequest) -> Result<()> {
    let Some(mm) = request.options.remesh_mm else {
        return Ok(());
    };
    let max = state.config.max_remesh_triangles;
    remesh::check_budget(area_mm2, mm, max)
        .map_err(|e| ApiError::invalid("remesh_mm", "budget", e.to_string()))
}

/// The options of the shape detail's face table: the defaults, capped.
pub fn default_options_key() -> String {
    let options = parse_options(&SimulationParams::default()).expect("defaults are valid");
    SimulationRequest {
        variant: Variant::Capped,
        options,
    }
    .options_key()
}

/// The stored face table (default options, capped) of a shape, when it has been made:
/// `(faces, error)`.
pub async fn stored_faces(
    state: &AppState,
    shape: &ShapeRow,
) -> Result<(Option<serde_json::Value>, Option<String>)> {
    let key = default_options_key();
    let row = db::simulations::get(&state.pool, shape.shape_id, &key).await?;
    let Some(row) =
        row.filter(|r| r.mesh_sha256 == shape.mesh_sha256 && r.software_version == crate::VERSION)
    else {
        return Ok((None, None));
    };
    Ok(match row.outcome {
        db::simulations::SimulationOutcome::Ready { summary, .. } => {
            let summary: SimulationSummary =
                serde_json::from_str(&summary).map_err(anyhow::Error::from)?;
            (Some(serde_json::json!(summary.capped_faces)), None)
        }
        db::simulations::SimulationOutcome::Failed { error, .. } => (None, Some(error)),
    })
}

/// The prepared simulation mesh of a shape, or the problem to answer with.
async fn prepare(
    state: &AppState,
    shape: &ShapeRow,
    request: &SimulationRequest,
) -> Result<Arc<PreparedSimulation>> {
    let prepared = state
        .simulations
        .prepare(
            &state.pool,
            shape.shape_id,
            &shape.mesh_sha256,
            request,
            Admission::Bounded,
        )
        .await;
    match prepared {
        Ok(Prepared::Ready(p)) => Ok(p),
        Ok(Prepared::Failed { error, field }) => Err(ApiError::Validation {
            field,
            rule: "simulation-mesh",
            message: format!("no simulation mesh for shape {}: {error}", shape.shape_id),
        }),
        Err(PrepareError::Busy(_)) => Err(ApiError::Overloaded {
            retry_after: state.config.retry_after_secs,
        }),
        Err(PrepareError::NoShape(id)) => Err(ApiError::not_found("shape", id)),
        Err(PrepareError::Other(e)) => Err(ApiError::Internal(e)),
    }
}

/// Strong validator of a simulation download: the shape's mesh, the variant, the options
/// and the software version (another version may make another mesh from the same shape).
fn simulation_etag(
    shape: &ShapeRow,
    request: &SimulationRequest,
    format: Option<SimulationFormat>,
) -> String {
    let mut hash = Sha256::new();
    hash.update(request.options_key().as_bytes());
    hash.update(crate::VERSION.as_bytes());
    let options = hash.finalize();
    let options: String = options[..8].iter().map(|b| format!("{b:02x}")).collect();
    let ext = format.map_or("json", SimulationFormat::extension);
    format!(
        "\"{}-{}-{options}-{ext}\"",
        &shape.mesh_sha256[..32],
        request.variant.name()
    )
}

/// Revalidated on every use (cheap with the ETag), since a new software version may make a
/// different mesh from the same shape.
const CACHE_REVALIDATE: &str = "public, no-cache";

/// Metadata of a simulation file: units, generator, the shape and the options.
pub(super) fn metadata(shape: &ShapeRow, request: &SimulationRequest) -> MeshMetadata {
    MeshMetadata {
        units: "mm".to_owned(),
        generator: format!("aortagen {}", crate::VERSION),
        extras: serde_json::json!({ "shape_id": shape.shape_id, "cohort_id": shape.cohort_id,
            "index": shape.shape_index, "mesh_sha256": shape.mesh_sha256,
            "simulation": request.options, "variant": request.variant }),
    }
}

/// The download of a simulation mesh (the `openings=capped|open` case of the mesh route).
pub(super) async fn download(
    state: &AppState,
    shape: ShapeRow,
    format: SimulationFormat,
    request: SimulationRequest,
    headers: &HeaderMap,
) -> Result<Response> {
    let etag = simulation_etag(&shape, &request, Some(format));
    let cache = [
        (header::ETAG, etag.clone()),
        (header::CACHE_CONTROL, CACHE_REVALIDATE.to_owned()),
    ];
    if if_none_match(headers, &etag) {
        return Ok((StatusCode::NOT_MODIFIED, cache).into_response());
    }
    check_remesh(state, shape.area_mm2, &request)?;
    let prepared = prepare(state, &shape, &request).await?;
    let meta = metadata(&shape, &request);
    let variant = request.variant;
    let bytes = spawn_blocking_with_span(move || prepared.file(format, variant, &meta))
        .await
        .map_err(anyhow::Error::from)?
        .map_err(anyhow::Error::from)?;
    let disposition = format!(
        "attachment; filename=\"shape-{}-{}.{}\"",
        shape.shape_id,
        variant.name(),
        format.extension()
    );
    let headers = [
        (header::CONTENT_TYPE, content_type(format).to_owned()),
        (header::CONTENT_DISPOSITION, disposition),
    ];
    Ok((cache, headers, bytes).into_response())
}

/// Media type of a simulation format.
pub fn content_type(format: SimulationFormat) -> &'static str {
    match format {
        SimulationFormat::Vtp => "application/vnd.vtk.vtp+xml",
        SimulationFormat::Vtk => "application/vnd.vtk",
        SimulationFormat::Stl => "model/stl",
        SimulationFormat::Obj => "model/obj",
        SimulationFormat::Glb => "model/gltf-binary",
    }
}

/// The face table and sidecar of a shape's simulation mesh: one entry per face (wall,
/// each cap, extension walls) with area, centroid, outward normal, equivalent diameter and
/// perimeter; the openings with their planes; quality; the remesh report. The same JSON is
/// written beside every file by `aortagen mesh`.
#[utoipa::path(get, path = "/v1/shapes/{id}/faces", tag = "shapes",
    params(("id" = i64, Path, description = "Shape id"), SimulationQuery),
    responses((status = 200, description = "The sidecar JSON (faces, openings, quality, remesh)", body = Object),
              (status = 304, description = "Matches If-None-Match"),
              (status = 400, body = Problem, content_type = "application/problem+json", description = "A parameter out of range or unknown; `field` names it"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 422, body = Problem, content_type = "application/problem+json", description = "No simulation mesh for this shape (openings not found, a cut missing the surface), or `remesh_mm` finer than the service's remesh limit (`--max-remesh-triangles`, rule `budget`, checked before any work; the message names the finest edge length within it); `field` names the parameter to change, or `openings`"),
              (status = 503, body = Problem, content_type = "application/problem+json", description = "Too many simulation meshes being made; retry after Retry-After")))]
pub(super) async fn get_shape_faces(
    State(state): State<AppState>,
    Path(id): Path<String>,
    ApiQuery(q): ApiQuery<SimulationQuery>,
    headers: HeaderMap,
) -> Result<Response> {
    let mut params = q.params();
    let given = params.openings.as_deref().map(str::trim);
    let given = given.unwrap_or(Variant::ALL[0].name());
    let Some(variant) = Variant::ALL.into_iter().find(|v| v.name() == given) else {
        return Err(param_error(ParamError {
            field: "openings",
            message: format!("{given:?} has no face table; use capped or open"),
        }));
    };
    params.openings = None;
    let request = SimulationRequest {
        variant,
        options: parse_options(&params).map_err(param_error)?,
    };
    let shape = db::shapes::get(&state.pool, parse_id("shape", &id)?)
        .await?
        .ok_or_else(|| ApiError::not_found("shape", &id))?;
    let etag = simulation_etag(&shape, &request, None);
    let cache = [
        (header::ETAG, etag.clone()),
        (header::CACHE_CONTROL, CACHE_REVALIDATE.to_owned()),
    ];
    if if_none_match(&headers, &etag) {
        return Ok((StatusCode::NOT_MODIFIED, cache).into_response());
    }
    check_remesh(&state, shape.area_mm2, &request)?;
    let prepared = prepare(&state, &shape, &request).await?;
    let sidecar = prepared
        .summary
        .sidecar(variant, &metadata(&shape, &request));
    let disposition = format!(
        "inline; filename=\"shape-{}-{}.json\"",
        shape.shape_id,
        variant.name()
    );
    Ok((
        cache,
        [(header::CONTENT_DISPOSITION, disposition)],
        Json(sidecar),
    )
        .into_response())
}
