//! Fitting new shapes to a ready model: `POST /v1/models/{id}/fit` uploads one mesh and
//! queues a `fit` job that optimises a latent for the frozen network; the result is an
//! *anchor* (`/v1/anchors/{id}`) that cohorts can mix in without retraining.

use axum::Json;
use axum::body::Bytes;
use axum::extract::{FromRequest, Multipart, Path, Request, State};
use axum::http::{StatusCode, header};
use axum::response::IntoResponse;
use serde::{Deserialize, Serialize};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::error::{ApiError, Problem, Result};
use super::extractors::{ApiQuery, bounded, parse_id};
use super::model_upload::{body_error, is_zip_body, parse_number, unpack_blocking, validate_mesh};
use super::upload_archive::{ArchiveLimits, Unpacked, count_files, looks_like_zip};
use crate::db::states::{AnchorStatus, JobStatus, ModelStatus};
use crate::db::{self, anchors::AnchorRow};
use crate::engine::FitSpec;
use crate::jobs::Job;
use crate::jobs::fit::FitPayload;
use crate::sdf::training::fit::{DEFAULT_FIT_ITERATIONS, MAX_FIT_ITERATIONS};

/// Accepted fit upload (documentation of the multipart form).
#[derive(Debug, utoipa::ToSchema)]
#[allow(dead_code)]
pub struct FitUpload {
    /// Anchor name, unique per model: 1–64 of `A-Z a-z 0-9 - _ .` (default: the file's
    /// stem, made unique with a numeric suffix).
    name: Option<String>,
    /// Adam steps on the latent, 1–10000 (default 800).
    iterations: Option<u64>,
    /// Seed of the surface sampling and the batches (default 0).
    seed: Option<u64>,
    /// The mesh (STL, OBJ, PLY, GLB, glTF), one part named `file`; a zip archive holding
    /// exactly one mesh is accepted too.
    #[schema(value_type = String, format = Binary)]
    file: Vec<u8>,
}

/// Query parameters: the form fields, and the file name of a raw body.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct FitQuery {
    /// Anchor name (see the form field).
    pub name: Option<String>,
    /// Adam steps, 1–10000.
    pub iterations: Option<u64>,
    /// Seed.
    pub seed: Option<u64>,
    /// File name of a raw (non-multipart) body; its extension names the format (PLY, GLB and
    /// glTF are also recognised by content).
    pub file_name: Option<String>,
}

/// The accepted fit request.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct FitAccepted {
    /// The new anchor (status `fitting` until the job ends).
    pub anchor_id: i64,
    /// Its name.
    pub name: String,
    /// The fit job (progress = steps done).
    pub job_id: i64,
    /// Related resources.
    pub links: AnchorLinks,
}

/// URLs of an anchor's related resources.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct AnchorLinks {
    /// This anchor.
    #[serde(rename = "self")]
    pub this: String,
    /// Its fit job.
    pub job: String,
    /// Its model.
    pub model: String,
}

/// Unit ball → mesh units of the fitted mesh: `p = p_unit · radius + centre`.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct TransformView {
    /// Centre in mesh units.
    pub centre: [f64; 3],
    /// Scale in mesh units.
    pub radius: f64,
}

/// A fitted (or fitting) anchor.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct AnchorView {
    /// Anchor id (what a cohort's `anchors` lists).
    pub id: i64,
    /// Model it belongs to.
    pub model_id: String,
    /// Unique per model.
    pub name: String,
    /// fitting | ready | failed.
    pub status: AnchorStatus,
    /// Uploaded file name.
    pub source_name: String,
    /// Adam steps.
    pub iterations: i64,
    /// Seed.
    pub seed: i64,
    /// Reconstruction Chamfer distance of the fitted latent (unit-ball coordinates, squared
    /// distances, 30 000 points: the measure reported for training shapes).
    pub chamfer: Option<f64>,
    /// The fitted latent code.
    pub latent: Option<Vec<f32>>,
    /// The fitted mesh's unit-ball transform.
    pub transform: Option<TransformView>,
    /// Why fitting failed.
    pub error: Option<String>,
    /// The fit job.
    pub job_id: i64,
    /// Creation time (UTC, RFC 3339).
    pub created_at: String,
    /// Related resources.
    pub links: AnchorLinks,
}

impl AnchorView {
    fn from_row(row: AnchorRow, job_status: Option<JobStatus>) -> Self {
        let id = row.anchor_id;
        // A job that ended without recording its outcome (e.g. failed at recovery after
        // repeated crashes) leaves the row `fitting`: the job's state decides.
        let status = match (row.status, job_status) {
            (AnchorStatus::Fitting, Some(JobStatus::Failed | JobStatus::Cancelled)) => {
                AnchorStatus::Failed
            }
            (status, _) => status,
        };
        Self {
            latent: row.latent_values(),
            transform: row.transform().map(|t| TransformView {
                centre: t.centre,
                radius: t.radius,
            }),
            links: AnchorLinks {
                this: format!("/v1/anchors/{id}"),
                job: format!("/v1/jobs/{}", row.job_id),
                model: format!("/v1/models/{}", row.model_id),
            },
            id,
            model_id: row.model_id,
            name: row.name,
            status,
            source_name: row.source_name,
            iterations: row.iterations,
            seed: row.seed,
            chamfer: row.chamfer,
            error: row.error,
            job_id: row.job_id,
            created_at: row.created_at,
        }
    }
}

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(fit_model))
        .routes(routes!(list_model_anchors))
        .routes(routes!(get_anchor, delete_anchor))
}

/// Fits a latent to one uploaded mesh for a ready model, its network frozen (DeepSDF-style
/// latent optimisation on the training loss); answers 202 with the `fit` job, whose progress
/// counts Adam steps. The result is an anchor with its reconstruction Chamfer distance,
/// usable in cohorts (`anchors`). The mesh comes as a multipart part `file` or as the raw
/// body (then `name`, `iterations`, `seed` and `file_name` in the query); size limits and
/// formats are those of `POST /v1/models`.
#[utoipa::path(post, path = "/v1/models/{id}/fit", tag = "anchors",
    params(("id" = String, Path, description = "Model id"), FitQuery),
    request_body(content(
        (FitUpload = "multipart/form-data"),
        (Vec<u8> = "application/octet-stream"),
        (Vec<u8> = "application/zip")
    )),
    responses((status = 202, body = FitAccepted),
              (status = 400, body = Problem, content_type = "application/problem+json", description = "Malformed body"),
              (status = 404, body = Problem, content_type = "application/problem+json", description = "Unknown model"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Model not ready, or name taken"),
              (status = 413, body = Problem, content_type = "application/problem+json"),
              (status = 422, body = Problem, content_type = "application/problem+json", description = "Not a usable mesh, or a field out of range"),
              (status = 429, body = Problem, content_type = "application/problem+json")))]
async fn fit_model(
    State(state): State<AppState>,
    Path(model_id): Path<String>,
    ApiQuery(query): ApiQuery<FitQuery>,
    request: Request,
) -> Result<impl IntoResponse> {
    let model = db::models::get(&state.pool, &model_id)
        .await?
        .ok_or_else(|| ApiError::not_found("model", &model_id))?;
    if model.status != ModelStatus::Ready {
        return Err(ApiError::Conflict(format!(
            "model {model_id:?} is {}; only a ready model can be fitted",
            model.status
        )));
    }
    let upload = read_upload(&state, query, request).await?;
    let iterations = bounded(
        "iterations",
        upload.iterations,
        MAX_FIT_ITERATIONS as u64,
        DEFAULT_FIT_ITERATIONS as u64,
    )?;
    if let Some(name) = &upload.name {
        check_name(name)?;
    }
    // Moved to the validating thread and back: the file is held once, not copied.
    let (file_name, bytes, format) = tokio::task::spawn_blocking(move || {
        let (file_name, bytes) = upload.file;
        let format = validate_mesh("file", &file_name, &bytes)?;
        Ok::<_, ApiError>((file_name, bytes, format))
    })
    .await
    .map_err(anyhow::Error::from)??;
    let ext = format.extension();

    // Kept in the object store too, for a worker on another machine; written before the
    // submission's transaction, which holds SQLite's one write lock.
    let mesh_sha256 = state.jobs.objects.put(&bytes).await?;
    let mut submission = state.queue.begin().await?;
    let name = match &upload.name {
        Some(name) => {
            if db::anchors::get_by_name(submission.conn(), &model_id, name)
                .await?
                .is_some()
            {
                return Err(ApiError::Conflict(format!(
                    "model {model_id:?} already has an anchor named {name:?}"
                )));
            }
            name.clone()
        }
        None => free_name(submission.conn(), &model_id, &file_name).await?,
    };
    let anchor_id = db::anchors::next_id(submission.conn()).await?;
    // Stored under the format validation read it as: no path from the client reaches the disk.
    let path = state
        .config
        .storage
        .models_dir
        .join("fits")
        .join(format!("anchor-{anchor_id}.{ext}"));
    let job = Job::Fit(FitPayload {
        anchor_id,
        model_id: model_id.clone(),
        spec: FitSpec {
            mesh_path: path.clone(),
            iterations,
            seed: upload.seed,
            mesh_sha256: Some(mesh_sha256),
        },
    });
    let job_id = submission.enqueue(&job, iterations as i64).await?;
    write_source(&path, &bytes).await?;
    db::anchors::insert(
        submission.conn(),
        &db::anchors::NewAnchor {
            anchor_id,
            model_id: &model_id,
            job_id,
            name: &name,
            source_name: &file_name,
            source_path: &path.to_string_lossy(),
            iterations: iterations as i64,
            seed: upload.seed as i64,
        },
    )
    .await?;
    submission.commit().await?;
    let body = FitAccepted {
        anchor_id,
        name,
        job_id,
        links: AnchorLinks {
            this: format!("/v1/anchors/{anchor_id}"),
            job: format!("/v1/jobs/{job_id}"),
            model: format!("/v1/models/{model_id}"),
        },
    };
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, format!("/v1/jobs/{job_id}"))],
        Json(body),
    ))
}

/// A model's anchors, oldest first.
#[utoipa::path(get, path = "/v1/models/{id}/anchors", tag = "anchors",
    params(("id" = String, Path, description = "Model id")),
    responses((status = 200, body = Vec<AnchorView>),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn list_model_anchors(
    State(state): State<AppState>,
    Path(model_id): Path<String>,
) -> Result<Json<Vec<AnchorView>>> {
    db::models::get(&state.pool, &model_id)
        .await?
        .ok_or_else(|| ApiError::not_found("model", &model_id))?;
    let rows = db::anchors::list_for_model(&state.pool, &model_id).await?;
    let mut views = Vec::with_capacity(rows.len());
    for row in rows {
        let job = db::jobs::get(&state.pool, row.job_id).await?;
        views.push(AnchorView::from_row(row, job.as_ref().map(|j| j.status)));
    }
    Ok(Json(views))
}

/// One anchor: status, fitted latent, transform and reconstruction Chamfer distance.
#[utoipa::path(get, path = "/v1/anchors/{id}", tag = "anchors",
    params(("id" = i64, Path, description = "Anchor id")),
    responses((status = 200, body = AnchorView),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn get_anchor(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<AnchorView>> {
    let row = load(&state, &id).await?;
    let job = db::jobs::get(&state.pool, row.job_id).await?;
    Ok(Json(AnchorView::from_row(
        row,
        job.as_ref().map(|j| j.status),
    )))
}

/// Deletes an anchor. Refused while its fit job is queued or running, or while a cohort
/// names it.
#[utoipa::path(delete, path = "/v1/anchors/{id}", tag = "anchors",
    params(("id" = i64, Path, description = "Anchor id")),
    responses((status = 204, description = "Deleted"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Fitting or in use")))]
async fn delete_anchor(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode> {
    let row = load(&state, &id).await?;
    let job = db::jobs::get(&state.pool, row.job_id).await?;
    if job.as_ref().is_some_and(|j| j.status.is_pending()) {
        return Err(ApiError::Conflict(format!(
            "anchor {id} is still fitting (job {}); wait for the job to end",
            row.job_id
        )));
    }
    let cohorts = db::anchors::cohort_count(&state.pool, row.anchor_id).await?;
    if cohorts > 0 {
        return Err(ApiError::Conflict(format!(
            "anchor {id} is used by {cohorts} cohort(s); delete them first"
        )));
    }
    db::anchors::delete(&state.pool, row.anchor_id).await?;
    let _ = tokio::fs::remove_file(&row.source_path).await;
    Ok(StatusCode::NO_CONTENT)
}

/// Checks a cohort request's `anchors` against the database: each must exist, belong to
/// `model_id` and be ready.
pub(super) async fn check_cohort_anchors(
    state: &AppState,
    model_id: &str,
    ids: &[i64],
) -> Result<()> {
    for (i, &id) in ids.iter().enumerate() {
        let field = format!("anchors[{i}]");
        let row = db::anchors::get(&state.pool, id).await?;
        let Some(row) = row else {
            let msg = format!("anchor {id} does not exist");
            return Err(ApiError::invalid(field, "exists", msg));
        };
        if row.model_id != model_id {
            let msg = format!(
                "anchor {id} belongs to model {:?}, not {model_id:?}",
                row.model_id
            );
            return Err(ApiError::invalid(field, "same-model", msg));
        }
        if row.status != AnchorStatus::Ready || row.latent.is_none() {
            let msg = format!("anchor {id} is {}, not ready", row.status);
            return Err(ApiError::invalid(field, "ready", msg));
        }
    }
    Ok(())
}

async fn load(state: &AppState, id: &str) -> Result<AnchorRow> {
    let anchor_id = parse_id("anchor", id)?;
    db::anchors::get(&state.pool, anchor_id)
        .await?
        .ok_or_else(|| ApiError::not_found("anchor", id))
}

/// The fields and the one file of a fit request, from either body form.
struct Upload {
    name: Option<String>,
    iterations: Option<u64>,
    seed: u64,
    file: (String, Vec<u8>),
}

/// Reads a fit request. The one-file rule is checked on the parts and on an archive's
/// directory before anything is decompressed.
async fn read_upload(state: &AppState, query: FitQuery, request: Request) -> Result<Upload> {
    let limit = state.config.max_upload_bytes;
    let archive_limits = ArchiveLimits {
        entries: state.config.max_archive_entries,
        bytes: state.config.max_archive_bytes,
    };
    let (mut name, mut iterations, mut seed) =
        (query.name, query.iterations, query.seed.unwrap_or(0));
    let mut file: Option<(String, Bytes)> = None;
    let multipart = request
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|t| {
            t.trim_start()
                .to_ascii_lowercase()
                .starts_with("multipart/")
        });
    if !multipart {
        let zip = is_zip_body(request.headers());
        let body = Bytes::from_request(request, state)
            .await
            .map_err(|e| body_error(e.status(), e.body_text(), limit))?;
        let file_name = query.file_name.unwrap_or_else(|| "upload".into());
        let file = one_file(zip, file_name, body, archive_limits).await?;
        return Ok(Upload {
            name,
            iterations,
            seed,
            file,
        });
    }
    let mut form = Multipart::from_request(request, state).await.map_err(|e| {
        ApiError::UnsupportedMediaType {
            expected: "multipart/form-data or a raw mesh body",
            got: e.body_text(),
        }
    })?;
    while let Some(field) = form
        .next_field()
        .await
        .map_err(|e| body_error(e.status(), e.body_text(), limit))?
    {
        let field_name = field.name().unwrap_or("").to_owned();
        let file_name = field.file_name().map(str::to_owned);
        let bytes = field
            .bytes()
            .await
            .map_err(|e| body_error(e.status(), e.body_text(), limit))?;
        match field_name.as_str() {
            "name" => name = Some(String::from_utf8_lossy(&bytes).trim().to_owned()),
            "iterations" => iterations = Some(parse_number("iterations", &bytes)?),
            "seed" => seed = parse_number("seed", &bytes)?,
            "file" | "files" => {
                if file.is_some() {
                    return Err(file_count_error("more than one"));
                }
                file = Some((file_name.unwrap_or_else(|| "upload".into()), bytes));
            }
            other => {
                return Err(ApiError::invalid(
                    other,
                    "unknown-field",
                    "unexpected form field",
                ));
            }
        }
    }
    let Some((file_name, bytes)) = file else {
        return Err(file_count_error("0"));
    };
    let file = one_file(false, file_name, bytes, archive_limits).await?;
    Ok(Upload {
        name,
        iterations,
        seed,
        file,
    })
}

fn file_count_error(got: &str) -> ApiError {
    let msg = format!("exactly one mesh file is needed, got {got}");
    ApiError::invalid("file", "count", msg)
}

/// The uploaded file, or the one mesh file of an uploaded archive (`zip`: the body said it
/// is one), whose directory is counted before its member is decompressed.
async fn one_file(
    zip: bool,
    name: String,
    bytes: Bytes,
    limits: ArchiveLimits,
) -> Result<(String, Vec<u8>)> {
    if !(zip || looks_like_zip(Some(&name), &bytes)) {
        return Ok((name, Vec::from(bytes)));
    }
    let files = count_files(&name, &bytes, limits)?;
    if files != 1 {
        return Err(file_count_error(&format!("{files} in {name}")));
    }
    let mut unpacked = unpack_blocking(name, bytes, limits, Unpacked::default()).await?;
    unpacked.files.pop().ok_or_else(|| file_count_error("0"))
}

pub(super) fn check_name(name: &str) -> Result<()> {
    let ok = (1..=64).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.'));
    if ok {
        Ok(())
    } else {
        Err(ApiError::invalid(
            "name",
            "format",
            "must be 1–64 characters of A-Z, a-z, 0-9, '-', '_' or '.'",
        ))
    }
}

/// The file's stem (restricted to the name alphabet), with `-2`, `-3`… when taken.
async fn free_name(conn: &mut db::Conn, model_id: &str, file_name: &str) -> Result<String> {
    let stem = std::path::Path::new(file_name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut base: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .take(56)
        .collect();
    if base.is_empty() {
        base = "anchor".into();
    }
    let mut candidate = base.clone();
    for n in 2.. {
        if db::anchors::get_by_name(conn, model_id, &candidate)
            .await?
            .is_none()
        {
            break;
        }
        candidate = format!("{base}-{n}");
    }
    Ok(candidate)
}

async fn write_source(path: &std::path::Path, bytes: &[u8]) -> anyhow::Result<()> {
    use anyhow::Context;
    if let Some(dir) = path.parent() {
        tokio::fs::create_dir_all(dir)
            .await
            .with_context(|| format!("cannot create {}", dir.display()))?;
    }
    tokio::fs::write(path, bytes)
        .await
        .with_context(|| format!("cannot write {}", path.display()))
}
