//! Every shape of a cohort in one zip: the closed surfaces or the simulation meshes in one
//! format and variant, with a manifest CSV (shape id, provenance, measurements, face
//! areas, or why a shape has no simulation mesh).
//!
//! The simulation meshes come from [`crate::jobs::simulation`], one shape after the other:
//! those made before are read back, the others are made now. A cohort of many remeshed
//! shapes can take longer than the request deadline; what was made is kept, so repeating
//! the request continues where it stopped.

use std::io::Write as _;

use axum::extract::{Path, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::cohorts::load as load_cohort;
use super::error::{ApiError, Problem, Result};
use super::extractors::{ApiQuery, parse_id};
use super::shapes::{MeshQuery, encode_mesh};
use super::simulation_meshes::{SimulationQuery, check_remesh, metadata, param_error};
use crate::db::{self, shapes::ShapeRow};
use crate::jobs::simulation::{Admission, Prepared};
use crate::simulation::{MeshRequest, SimulationRequest};
use crate::telemetry::spawn_blocking_with_span;

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(get_cohort_meshes))
}

/// Shapes read per page of the cohort.
const PAGE: i64 = 100;

/// The manifest's header.
pub const MANIFEST_HEADER: &str = "shape_id,index,file,model_id,seed,cohort_seed,resolution,\
    training_indices,weights,area_mm2,volume_mm3,faces,error";

/// One file of the archive, or why a shape has none.
struct Entry {
    shape: ShapeRow,
    file: Option<(String, Vec<u8>)>,
    faces: String,
    error: String,
}

/// Every shape of the cohort in one zip with `manifest.csv`; the same parameters as a
/// shape's mesh download.
#[utoipa::path(get, path = "/v1/cohorts/{id}/meshes.zip", tag = "shapes",
    params(("id" = i64, Path, description = "Cohort id"), MeshQuery, SimulationQuery),
    responses((status = 200, description = "A zip of `shape-<id>[-<variant>].<format>` files and `manifest.csv` (face areas as `name:mm²` separated by `;`; shapes without a simulation mesh listed with their error)", content_type = "application/zip"),
              (status = 400, body = Problem, content_type = "application/problem+json", description = "A parameter out of range or unknown; `field` names it"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 408, body = Problem, content_type = "application/problem+json", description = "Longer than the request deadline; the meshes made are kept, repeat the request"),
              (status = 422, body = Problem, content_type = "application/problem+json", description = "`remesh_mm` finer than the service's remesh limit (`--max-remesh-triangles`) for the cohort's largest shape; the message names the finest edge length within it")))]
async fn get_cohort_meshes(
    State(state): State<AppState>,
    Path(id): Path<String>,
    ApiQuery(q): ApiQuery<MeshQuery>,
    ApiQuery(sim): ApiQuery<SimulationQuery>,
) -> Result<Response> {
    let request = MeshRequest::parse(q.format.as_deref(), &sim.params()).map_err(param_error)?;
    if q.units.as_deref().is_some_and(|u| u != "mm") {
        return Err(ApiError::BadRequest {
            field: Some("units".into()),
            message: "cohort archives are written in mm".into(),
        });
    }
    let cohort = load_cohort(&state, parse_id("cohort", &id)?, &id).await?;
    if let MeshRequest::Simulation { request, .. } = &request {
        let largest = db::shapes::measure_summary(&state.pool, cohort.cohort_id).await?;
        check_remesh(&state, largest.area_max.unwrap_or(0.0), request)?;
    }
    let mut entries = Vec::new();
    let mut offset = 0;
    loop {
        let page = db::shapes::list_for_cohort(&state.pool, cohort.cohort_id, PAGE, offset).await?;
        let last = (page.len() as i64) < PAGE;
        for shape in page {
            entries.push(entry(&state, shape, &request).await?);
        }
        if last {
            break;
        }
        offset += PAGE;
    }
    let zip = spawn_blocking_with_span(move || archive(&entries))
        .await
        .map_err(anyhow::Error::from)??;
    let disposition = format!(
        "attachment; filename=\"cohort-{}-meshes.zip\"",
        cohort.cohort_id
    );
    let headers = [
        (header::CONTENT_TYPE, "application/zip".to_owned()),
        (header::CONTENT_DISPOSITION, disposition),
    ];
    Ok((headers, zip).into_response())
}

async fn entry(state: &AppState, shape: ShapeRow, request: &MeshRequest) -> Result<Entry> {
    let id = shape.shape_id;
    let (format, request) = match request {
        MeshRequest::Closed(format) => {
            let bytes = encode_mesh(state, shape.clone(), *format, "mm").await?;
            let name = format!("shape-{id}.{}", format.extension());
            return Ok(Entry {
                shape,
                file: Some((name, bytes)),
                faces: String::new(),
                error: String::new(),
            });
        }
        MeshRequest::Simulation { format, request } => (*format, request),
    };
    let prepared = state
        .simulations
        .prepare(
            &state.pool,
            id,
            &shape.mesh_sha256,
            request,
            Admission::Unbounded,
        )
        .await
        .map_err(anyhow::Error::from)?;
    let prepared = match prepared {
        Prepared::Ready(p) => p,
        Prepared::Failed { error, field } => {
            return Ok(Entry {
                shape,
                file: None,
                faces: String::new(),
                error: format!("{field}: {error}"),
            });
        }
    };
    let faces = prepared
        .summary
        .faces(request.variant)
        .iter()
        .map(|f| format!("{}:{:.3}", f.name, f.area_mm2))
        .collect::<Vec<_>>()
        .join(";");
    let meta = metadata(&shape, request);
    let SimulationRequest { variant, .. } = *request;
    let bytes = spawn_blocking_with_span(move || prepared.file(format, variant, &meta))
        .await
        .map_err(anyhow::Error::from)?
        .map_err(anyhow::Error::from)?;
    let name = format!("shape-{id}-{}.{}", variant.name(), format.extension());
    Ok(Entry {
        shape,
        file: Some((name, bytes)),
        faces,
        error: String::new(),
    })
}

/// A CSV field, quoted when it holds a comma, quote or line break.
fn csv(field: &str) -> String {
    if field.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", field.replace('"', "\"\""))
    } else {
        field.to_owned()
    }
}

fn manifest_row(e: &Entry) -> String {
    let s = &e.shape;
    let list = |v: String| csv(&v);
    [
        s.shape_id.to_string(),
        s.shape_index.to_string(),
        csv(e.file.as_ref().map_or("", |(name, _)| name)),
        csv(&s.model_id),
        s.seed.to_string(),
        s.cohort_seed.to_string(),
        s.resolution.to_string(),
        list(serde_json::json!(s.training_indices.0).to_string()),
        list(serde_json::json!(s.weights.0).to_string()),
        format!("{:.3}", s.area_mm2),
        format!("{:.3}", s.volume_mm3),
        csv(&e.faces),
        csv(&e.error),
    ]
    .join(",")
}

fn archive(entries: &[Entry]) -> anyhow::Result<Vec<u8>> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    let mut manifest = format!("{MANIFEST_HEADER}\n");
    for e in entries {
        manifest.push_str(&manifest_row(e));
        manifest.push('\n');
        if let Some((name, bytes)) = &e.file {
            zip.start_file(name.as_str(), options)?;
            zip.write_all(bytes)?;
        }
    }
    zip.start_file("manifest.csv", options)?;
    zip.write_all(manifest.as_bytes())?;
    Ok(zip.finish()?.into_inner())
}
