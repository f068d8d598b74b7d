//! `POST /v1/models`: upload training meshes (multipart) and train a new model as a job.
//! Every file is parsed and validated before anything is stored; a bad one is a 422 that
//! names it.

use axum::Json;
use axum::extract::{Multipart, State};
use axum::http::{StatusCode, header};
use axum::response::IntoResponse;
use serde::Serialize;

use super::AppState;
use super::error::{ApiError, Problem, Result};
use crate::db;
use crate::formats::{MeshFormat, read_mesh_bytes};
use crate::jobs::engine::TrainingSpec;
use crate::jobs::training::TrainingPayload;

/// Accepted upload (documentation of the multipart form).
#[derive(Debug, utoipa::ToSchema)]
#[allow(dead_code)]
pub struct ModelUpload {
    /// Id for the new model: 1–64 of `a-z 0-9 - _` (default: `model-<timestamp>`).
    id: Option<String>,
    /// Training seed.
    seed: Option<u64>,
    /// Two or more mesh files (STL, OBJ, PLY, GLB, glTF), one part each, named `files`.
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

/// Trains a new model from uploaded meshes; answers 202 with the training job.
#[utoipa::path(post, path = "/v1/models", tag = "models",
    request_body(content = ModelUpload, content_type = "multipart/form-data"),
    responses((status = 202, body = TrainingAccepted),
              (status = 400, body = Problem, content_type = "application/problem+json", description = "Malformed multipart body"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Id taken"),
              (status = 413, body = Problem, content_type = "application/problem+json"),
              (status = 415, body = Problem, content_type = "application/problem+json"),
              (status = 422, body = Problem, content_type = "application/problem+json", description = "A file is not a usable mesh"),
              (status = 429, body = Problem, content_type = "application/problem+json")))]
pub(super) async fn create_model(
    State(state): State<AppState>,
    multipart: std::result::Result<Multipart, axum::extract::multipart::MultipartRejection>,
) -> Result<impl IntoResponse> {
    let mut multipart = multipart.map_err(|e| ApiError::UnsupportedMediaType {
        expected: "multipart/form-data",
        got: e.body_text(),
    })?;
    let limit = state.config.max_upload_bytes;
    let (mut id, mut seed, mut files) = (None, 0u64, Vec::<(String, Vec<u8>)>::new());
    while let Some(field) = multipart
        .next_field()
        .await
        .map_err(|e| upload_error(e, limit))?
    {
        let name = field.name().unwrap_or("").to_owned();
        let file_name = field.file_name().map(str::to_owned);
        let bytes = field.bytes().await.map_err(|e| upload_error(e, limit))?;
        match name.as_str() {
            "id" => id = Some(String::from_utf8_lossy(&bytes).trim().to_owned()),
            "seed" => {
                seed = String::from_utf8_lossy(&bytes)
                    .trim()
                    .parse()
                    .map_err(|_| {
                        ApiError::invalid("seed", "type", "must be a non-negative integer")
                    })?
            }
            "files" | "file" => {
                let file_name = file_name.unwrap_or_else(|| format!("file-{}", files.len()));
                files.push((file_name, bytes.to_vec()));
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
    let model_id =
        id.unwrap_or_else(|| format!("model-{}", std::process::id() ^ rand::random::<u32>()));
    check_model_id(&model_id)?;
    if files.len() < 2 {
        let msg = format!("at least 2 mesh files are needed, got {}", files.len());
        return Err(ApiError::invalid("files", "count", msg));
    }
    let checked = files.clone();
    tokio::task::spawn_blocking(move || validate_meshes(&checked))
        .await
        .map_err(anyhow::Error::from)??;

    let model_dir = state.config.models_dir.join(&model_id);
    let input_dir = model_dir.join("input");
    let mut tx = state.pool.begin_with(db::BEGIN_WRITE).await?;
    if db::models::get(&state.pool, &model_id).await?.is_some() {
        return Err(ApiError::Conflict(format!(
            "model {model_id:?} already exists"
        )));
    }
    let pending = db::jobs::count_pending(&mut *tx).await?;
    if pending >= state.config.max_queue {
        return Err(ApiError::QueueFull {
            pending,
            retry_after: state.config.retry_after_secs,
        });
    }
    write_inputs(&input_dir, &files).await?;
    let dir = model_dir.to_string_lossy();
    db::models::insert_if_absent(
        &mut tx,
        &model_id,
        &dir,
        &serde_json::Value::Null,
        "training",
    )
    .await?;
    let payload = TrainingPayload {
        model_id: model_id.clone(),
        spec: TrainingSpec {
            input_dir,
            model_dir: model_dir.clone(),
            seed,
        },
    };
    let payload = serde_json::to_value(payload).map_err(anyhow::Error::from)?;
    let job_id = db::jobs::enqueue(&mut tx, "training", &payload, 1).await?;
    tx.commit().await?;
    state.job_wake.notify_one();
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

fn upload_error(e: axum::extract::multipart::MultipartError, limit: usize) -> ApiError {
    if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::PayloadTooLarge { limit }
    } else {
        ApiError::BadRequest {
            field: None,
            message: format!("unreadable multipart body: {}", e.body_text()),
        }
    }
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

/// Parses and validates every file; the first failure names its file.
fn validate_meshes(files: &[(String, Vec<u8>)]) -> Result<()> {
    for (name, bytes) in files {
        let field = format!("files[{name}]");
        let format: MeshFormat = std::path::Path::new(name)
            .extension()
            .and_then(|e| e.to_str())
            .and_then(|e| e.parse().ok())
            .or_else(|| MeshFormat::sniff(bytes))
            .ok_or_else(|| {
                ApiError::invalid(&field, "format", format!("{name}: unknown mesh format"))
            })?;
        let mesh = read_mesh_bytes(bytes, format, name)
            .map_err(|e| ApiError::invalid(&field, "mesh", e.to_string()))?;
        mesh.validate()
            .map_err(|e| ApiError::invalid(&field, "mesh", format!("{name}: {e}")))?;
    }
    Ok(())
}

async fn write_inputs(dir: &std::path::Path, files: &[(String, Vec<u8>)]) -> anyhow::Result<()> {
    use anyhow::Context;
    tokio::fs::create_dir_all(dir)
        .await
        .with_context(|| format!("cannot create {}", dir.display()))?;
    for (i, (name, bytes)) in files.iter().enumerate() {
        // Only the extension of the client's name is kept: no path from the client reaches the disk.
        let ext = std::path::Path::new(name)
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("mesh");
        let path = dir.join(format!("{i:04}.{}", ext.to_ascii_lowercase()));
        tokio::fs::write(&path, bytes)
            .await
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
