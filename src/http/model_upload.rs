//! `POST /v1/models`: upload training meshes (multipart, or a zip archive) and train a new
//! model as a job.
//! Every file is parsed and validated before anything is stored; a bad one is a 422 that
//! names it.

use axum::Json;
use axum::body::Bytes;
use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::{StatusCode, header};
use axum::response::IntoResponse;
use serde::Serialize;

use super::AppState;
use super::error::{ApiError, Problem, Result};
use super::extractors::ApiQuery;
use super::upload_archive::{ArchiveLimits, Unpacked, looks_like_zip, unpack};
use crate::db;
use crate::db::states::ModelStatus;
use crate::engine::TrainingSpec;
use crate::formats::{MeshFormat, read_mesh_bytes};
use crate::geometry::TriMesh;
use crate::jobs::Job;
use crate::jobs::training::TrainingPayload;
use crate::sdf::training::config::Preset;

/// Most epochs a training request may ask for (the paper preset's count).
pub const MAX_EPOCHS: u64 = 5000;

/// Accepted upload (documentation of the multipart form).
#[derive(Debug, utoipa::ToSchema)]
#[allow(dead_code)]
pub struct ModelUpload {
    /// Id for the new model: 1–64 of `a-z 0-9 - _` (default: `model-<timestamp>`).
    id: Option<String>,
    /// Training seed.
    seed: Option<u64>,
    /// Epochs to train, 1–5000 (default: the CPU preset's 240).
    epochs: Option<u64>,
    /// Meshes to keep out of training, chosen from the seed (at least two must remain):
    /// the held-out shapes are fitted with the network frozen after training, and both
    /// sets become the model's reference populations `training` and `heldout`.
    holdout: Option<u64>,
    /// Two or more mesh files (STL, OBJ, PLY, GLB, glTF), one part each, named `files`; a
    /// part that is a zip archive counts as the mesh files inside it.
    #[schema(value_type = Vec<String>, format = Binary)]
    files: Vec<Vec<u8>>,
}

/// The accepted training request.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct TrainingAccepted {
    /// The new model's id (status `training` until the job ends).
    pub model_id: String,
    /// The training job.
    pub job_id: i64,
    /// Number of training meshes.
    pub shapes: usize,
}

/// Trains a new model from uploaded meshes; answers 202 with the training job. The meshes
/// come as multipart parts (a part may be a zip archive of meshes) or as one zip archive
/// body (`application/zip`, deflate or stored) with `id`, `seed` and `epochs` in the query.
#[utoipa::path(post, path = "/v1/models", tag = "models",
    params(UploadQuery),
    request_body(content(
        (ModelUpload = "multipart/form-data"),
        (Vec<u8> = "application/zip")
    )),
    responses((status = 202, body = TrainingAccepted),
              (status = 400, body = Problem, content_type = "application/problem+json", description = "Malformed multipart body"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Id taken"),
              (status = 413, body = Problem, content_type = "application/problem+json"),
              (status = 415, body = Problem, content_type = "application/problem+json"),
              (status = 422, body = Problem, content_type = "application/problem+json", description = "A file is not a usable mesh"),
              (status = 429, body = Problem, content_type = "application/problem+json")))]
pub(super) async fn create_model(
    State(state): State<AppState>,
    ApiQuery(query): ApiQuery<UploadQuery>,
    request: Request,
) -> Result<impl IntoResponse> {
    let limit = state.config.max_upload_bytes;
    let archive_limits = ArchiveLimits {
        entries: state.config.max_archive_entries,
        bytes: state.config.max_archive_bytes,
    };
    let (mut id, mut seed, mut epochs) = (query.id, query.seed.unwrap_or(0), query.epochs);
    let mut holdout = query.holdout;
    // Plain files and archive members in upload order, with what the archives expanded to.
    let mut upload = Unpacked::default();
    if is_zip_body(request.headers()) {
        let body = Bytes::from_request(request, &state)
            .await
            .map_err(|e| body_error(e.status(), e.body_text(), limit))?;
        upload = unpack_blocking(BODY_ARCHIVE.into(), body, archive_limits, upload).await?;
    } else {
        let mut multipart = Multipart::from_request(request, &state)
            .await
            .map_err(|e| ApiError::UnsupportedMediaType {
                expected: "multipart/form-data or application/zip",
                got: e.body_text(),
            })?;
        while let Some(field) = multipart
            .next_field()
            .await
            .map_err(|e| body_error(e.status(), e.body_text(), limit))?
        {
            let name = field.name().unwrap_or("").to_owned();
            let file_name = field.file_name().map(str::to_owned);
            let bytes = field
                .bytes()
                .await
                .map_err(|e| body_error(e.status(), e.body_text(), limit))?;
            match name.as_str() {
                "id" => id = Some(String::from_utf8_lossy(&bytes).trim().to_owned()),
                "seed" => seed = parse_number("seed", &bytes)?,
                "epochs" => epochs = Some(parse_number("epochs", &bytes)?),
                "holdout" => holdout = Some(parse_number("holdout", &bytes)?),
                "files" | "file" => {
                    let file_name =
                        file_name.unwrap_or_else(|| format!("file-{}", upload.files.len()));
                    if looks_like_zip(Some(&file_name), &bytes) {
                        upload = unpack_blocking(file_name, bytes, archive_limits, upload).await?;
                    } else {
                        upload.files.push((file_name, Vec::from(bytes)));
                    }
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
    }
    if let Some(e) = epochs
        && !(1..=MAX_EPOCHS).contains(&e)
    {
        let msg = format!("must be an integer from 1 to {MAX_EPOCHS}");
        return Err(ApiError::invalid("epochs", "range", msg));
    }
    let model_id =
        id.unwrap_or_else(|| format!("model-{}", std::process::id() ^ rand::random::<u32>()));
    check_model_id(&model_id)?;
    let files = upload.files;
    if files.len() < 2 {
        let msg = format!("at least 2 mesh files are needed, got {}", files.len());
        return Err(ApiError::invalid("files", "count", msg));
    }
    let holdout = check_holdout(holdout, files.len())?;
    // Moved to the validating thread and back: the files are held once, not copied.
    let (files, formats) = tokio::task::spawn_blocking(move || {
        let formats = validate_meshes(&files)?;
        Ok::<_, ApiError>((files, formats))
    })
    .await
    .map_err(anyhow::Error::from)??;

    let model_dir = state.config.storage.models_dir.join(&model_id);
    let input_dir = model_dir.join("input");
    // Kept in the object store too, for a worker on another machine; written before the
    // submission's transaction, which holds SQLite's one write lock.
    let named: Vec<(String, &[u8])> = files
        .iter()
        .zip(&formats)
        .enumerate()
        .map(|(i, ((_, bytes), format))| (input_file_name(i, *format), bytes.as_slice()))
        .collect();
    let input_digest = Some(
        state
            .jobs
            .objects
            .put(&crate::objects::bundle::pack_files(&named))
            .await?,
    );
    let mut submission = state.queue.begin().await?;
    if db::models::get(&state.pool, &model_id).await?.is_some() {
        return Err(ApiError::Conflict(format!(
            "model {model_id:?} already exists"
        )));
    }
    // Whatever is under this id's directory without a row (a deleted model's inputs,
    // checkpoints or weights, an interrupted upload) must not become part of this model.
    clear_leftovers(&model_dir).await?;
    write_inputs(&input_dir, &files, &formats).await?;
    let job = Job::Training(TrainingPayload {
        model_id: model_id.clone(),
        spec: TrainingSpec {
            input_dir: input_dir.clone(),
            model_dir: model_dir.clone(),
            seed,
            epochs,
            holdout,
            input_digest,
        },
    });
    let total_epochs = epochs.unwrap_or_else(|| Preset::Cpu.setup(seed).training.epochs);
    let job_id = submission.enqueue(&job, total_epochs as i64).await?;
    let dir = model_dir.to_string_lossy();
    db::models::insert_if_absent(
        submission.conn(),
        &model_id,
        &dir,
        None,
        ModelStatus::Training,
    )
    .await?;
    submission.commit().await?;
    let body = TrainingAccepted {
        model_id: model_id.clone(),
        job_id,
        shapes: files.len(),
    };
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, format!("/v1/jobs/{job_id}"))],
        Json(body),
    ))
}

/// Fewest meshes a `holdout` may keep out of training.
pub const MIN_HOLDOUT: u64 = 1;

/// The held-out count within `1..=files − 2` (two meshes must remain to train on).
fn check_holdout(holdout: Option<u64>, files: usize) -> Result<Option<usize>> {
    let Some(k) = holdout else {
        return Ok(None);
    };
    let most = files.saturating_sub(2);
    if k < MIN_HOLDOUT || k as usize > most {
        let msg = format!(
            "must hold out {MIN_HOLDOUT} to {most} of the {files} meshes (at least 2 must \
             remain to train on), got {k}"
        );
        return Err(ApiError::invalid("holdout", "range", msg));
    }
    Ok(Some(k as usize))
}

/// Name of an archive sent as the whole body, in messages.
const BODY_ARCHIVE: &str = "upload.zip";

/// Query parameters: the form fields, for a zip body (form fields override them).
#[derive(Debug, serde::Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct UploadQuery {
    /// Id for the new model (see the form field).
    pub id: Option<String>,
    /// Training seed.
    pub seed: Option<u64>,
    /// Epochs to train, 1–5000.
    pub epochs: Option<u64>,
    /// Meshes to keep out of training (see the form field).
    pub holdout: Option<u64>,
}

pub(super) fn is_zip_body(headers: &axum::http::HeaderMap) -> bool {
    headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.split(';').next())
        .is_some_and(|t| {
            let t = t.trim();
            t.eq_ignore_ascii_case("application/zip")
                || t.eq_ignore_ascii_case("application/x-zip-compressed")
        })
}

pub(super) fn body_error(status: StatusCode, text: String, limit: usize) -> ApiError {
    if status == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::PayloadTooLarge { limit }
    } else {
        ApiError::BadRequest {
            field: None,
            message: format!("unreadable request body: {text}"),
        }
    }
}

pub(super) fn parse_number(field: &'static str, bytes: &[u8]) -> Result<u64> {
    String::from_utf8_lossy(bytes)
        .trim()
        .parse()
        .map_err(|_| ApiError::invalid(field, "type", "must be a non-negative integer"))
}

/// Unpacks an archive into the request's `unpacked` files off the executor (decompression
/// is CPU work), within what the request's earlier archives left of the bound.
pub(super) async fn unpack_blocking(
    name: String,
    bytes: Bytes,
    limits: ArchiveLimits,
    mut unpacked: Unpacked,
) -> Result<Unpacked> {
    tokio::task::spawn_blocking(move || {
        unpack(&name, &bytes, limits, &mut unpacked)?;
        Ok(unpacked)
    })
    .await
    .map_err(anyhow::Error::from)?
}

fn check_model_id(id: &str) -> Result<()> {
    let ok = (1..=64).contains(&id.len())
        && id
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-' || b == b'_');
    if ok {
        Ok(())
    } else {
        Err(ApiError::invalid(
            "id",
            "format",
            "must be 1–64 characters of a-z, 0-9, '-' or '_'",
        ))
    }
}

/// Parses and validates every file; the first failure names its file. Returns each file's
/// format as it was read.
fn validate_meshes(files: &[(String, Vec<u8>)]) -> Result<Vec<MeshFormat>> {
    files
        .iter()
        .map(|(name, bytes)| validate_mesh(&format!("files[{name}]"), name, bytes))
        .collect()
}

/// Parses and validates one uploaded mesh (format from the extension, else sniffed) and
/// returns the format it was read as, under which it must be stored: a file accepted by
/// sniffing has no extension (or an unknown one) that a reader could go by. A failure is a
/// 422 on `field` naming the reason.
pub(super) fn validate_mesh(field: &str, name: &str, bytes: &[u8]) -> Result<MeshFormat> {
    read_valid_mesh(field, name, bytes).map(|(format, _)| format)
}

/// [`validate_mesh`], keeping the mesh it read.
pub(super) fn read_valid_mesh(
    field: &str,
    name: &str,
    bytes: &[u8],
) -> Result<(MeshFormat, TriMesh)> {
    let format = mesh_format(name, bytes).ok_or_else(|| {
        ApiError::invalid(field, "format", format!("{name}: unknown mesh format"))
    })?;
    let mesh: TriMesh = read_mesh_bytes(bytes, format, name)
        .map_err(|e| ApiError::invalid(field, "mesh", e.to_string()))?;
    mesh.validate()
        .map_err(|e| ApiError::invalid(field, "mesh", format!("{name}: {e}")))?;
    Ok((format, mesh))
}

/// The mesh format a file name's extension names, else the one its bytes announce.
fn mesh_format(name: &str, bytes: &[u8]) -> Option<MeshFormat> {
    std::path::Path::new(name)
        .extension()
        .and_then(|e| e.to_str())
        .and_then(|e| e.parse().ok())
        .or_else(|| MeshFormat::sniff(bytes))
}

/// Writes each file as `NNNN.<ext>` with the extension of the format validation read it as
/// (training reads a directory by extension), so no name or path from the client reaches
/// the disk.
/// The name the `i`-th uploaded mesh is stored under: its index and the format validation
/// read it as (no name from the client reaches the disk).
fn input_file_name(i: usize, format: MeshFormat) -> String {
    format!("{i:04}.{}", format.extension())
}

/// Removes a directory left under a model id that has no row.
async fn clear_leftovers(model_dir: &std::path::Path) -> anyhow::Result<()> {
    use anyhow::Context;
    match tokio::fs::remove_dir_all(model_dir).await {
        Ok(()) => {
            tracing::info!(dir = %model_dir.display(), "files left under a free model id removed");
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e).with_context(|| format!("cannot clear {}", model_dir.display())),
    }
}

async fn write_inputs(
    dir: &std::path::Path,
    files: &[(String, Vec<u8>)],
    formats: &[MeshFormat],
) -> anyhow::Result<()> {
    use anyhow::Context;
    tokio::fs::create_dir_all(dir)
        .await
        .with_context(|| format!("cannot create {}", dir.display()))?;
    for (i, ((_, bytes), format)) in files.iter().zip(formats).enumerate() {
        let path = dir.join(input_file_name(i, *format));
        tokio::fs::write(&path, bytes)
            .await
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
