//! Validation of cohorts against real populations (DESIGN §8) in the service.
//!
//! * Reference populations of a model: `POST /v1/models/{id}/references` uploads real
//!   patients as meshes (mm; multipart parts or zip archives, the rules of training
//!   uploads) or as a measurements table (CSV, mm; SIMCor's column names accepted). A
//!   model's `training` shapes, and its `heldout` shapes when it was trained with a
//!   holdout, are references too, without an upload.
//! * `POST /v1/cohorts/{id}/validations` queues a `validation` job comparing a finished
//!   cohort with a reference (shape level: MMD, COV, 1-NNA, DCR; measurement level: KS,
//!   Wasserstein, SIMCor's density band test, TOST, Mahalanobis, Spearman) under the
//!   request's acceptance criteria; `GET /v1/validations/{id}` gives its status, verdict and
//!   report, `/report.html` the page with plots and the credibility dossier.

use axum::Json;
use axum::body::Bytes;
use axum::extract::{FromRequest, Multipart, Path, Request, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::anchors::check_name;
use super::error::{ApiError, Problem, Result};
use super::extractors::{ApiJson, ApiQuery, bounded, parse_id};
use super::model_upload::{body_error, is_zip_body, read_valid_mesh, unpack_blocking};
use super::upload_archive::{ArchiveLimits, Unpacked, looks_like_zip};
use crate::db::states::{JobStatus, ModelStatus};
use crate::db::{self, references::ReferenceRow, validations::ValidationRow};
use crate::jobs::Job;
use crate::jobs::validation::{ValidationPayload, ValidationSettings};
use crate::stats::bootstrap::{DEFAULT_DISCOUNT, DEFAULT_RESAMPLES, Discount};
use crate::validation::report::ValidationReport;
use crate::validation::{AcceptanceCriteria, InputError, Verdict};

/// Most surface samples per shape a validation may ask for.
pub const MAX_POINTS: u64 = 100_000;
/// Most equal-size subsets of 1-NNA, MMD and COV.
pub const MAX_SUBSETS: u64 = 10_000;
/// Most bootstrap resamples of the density-band test.
pub const MAX_RESAMPLES: u64 = 100_000;
/// Fewest shapes (or table rows) a reference needs: every statistic compares spreads.
pub const MIN_REFERENCE_SHAPES: usize = 2;

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(create_reference, list_references))
        .routes(routes!(get_reference, delete_reference))
        .routes(routes!(create_validation, list_validations))
        .routes(routes!(get_validation, delete_validation))
        .routes(routes!(validation_report_html))
}

impl From<InputError> for ApiError {
    fn from(e: InputError) -> Self {
        ApiError::invalid(e.field, e.rule, e.message)
    }
}

/// Accepted reference upload (documentation of the multipart form).
#[derive(Debug, utoipa::ToSchema)]
#[allow(dead_code)]
pub struct ReferenceUpload {
    /// Name, unique per model: 1–64 of `A-Z a-z 0-9 - _ .` (`training` and `heldout` are
    /// the model's own).
    name: String,
    /// Patient meshes in mm (STL, OBJ, PLY, GLB, glTF), one part each, named `files`; a part
    /// that is a zip archive counts as the meshes inside it. At least 2.
    #[schema(value_type = Vec<String>, format = Binary)]
    files: Option<Vec<Vec<u8>>>,
    /// Or one measurements table (CSV, `,` or `;` separated, one row per patient, lengths
    /// in mm; the columns of docs/MEASUREMENTS.md or SIMCor's `D_an`, `D_sinus`, `D_stj`,
    /// `H_sinus`, …). At least 2 rows.
    #[schema(value_type = String, format = Binary)]
    table: Option<Vec<u8>>,
}

/// Query parameters of a raw (zip or CSV) reference body.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ReferenceQuery {
    /// Name (see the form field).
    pub name: Option<String>,
}

/// A table column accepted but not compared.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct IgnoredColumn {
    /// The column as written in the table.
    pub column: String,
    /// Why it is not compared.
    pub reason: String,
}

/// URLs of a reference's related resources.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ReferenceLinks {
    /// This reference (absent for a model's own).
    #[serde(rename = "self", skip_serializing_if = "Option::is_none")]
    pub this: Option<String>,
    /// Its model.
    pub model: String,
}

// The schema of the `serde_json::Value` fields that name a reference.
/// Names a reference population: an uploaded reference's id (a number), or `training` /
/// `heldout`, the model's own shapes.
#[derive(Debug, Serialize, utoipa::ToSchema)]
#[serde(untagged)]
pub enum ReferenceName {
    /// An uploaded reference's id.
    Uploaded(i64),
    /// `training` or `heldout`.
    Own(String),
}

/// A reference population.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ReferenceView {
    /// What a validation's `reference` names: an uploaded reference's id (a number), or
    /// `training` / `heldout`.
    #[schema(value_type = ReferenceName)]
    pub id: serde_json::Value,
    /// Model whose cohorts it validates.
    pub model_id: String,
    /// Unique per model.
    pub name: String,
    /// `meshes` or `measurements` (uploaded), `training` or `heldout` (the model's own).
    pub kind: String,
    /// Shapes or table rows.
    pub shapes: i64,
    /// Whether the shape level can be computed against it (it has surfaces).
    pub has_surfaces: bool,
    /// SHA-256 of the stored content (uploaded references).
    pub sha256: Option<String>,
    /// Table columns accepted but not compared.
    pub ignored_columns: Vec<IgnoredColumn>,
    /// Upload time (UTC, RFC 3339; absent for the model's own).
    pub created_at: Option<String>,
    /// Related resources.
    pub links: ReferenceLinks,
}

impl ReferenceView {
    fn from_row(row: ReferenceRow) -> Self {
        Self {
            id: serde_json::json!(row.reference_id),
            links: ReferenceLinks {
                this: Some(format!("/v1/references/{}", row.reference_id)),
                model: format!("/v1/models/{}", row.model_id),
            },
            has_surfaces: row.kind == "meshes",
            model_id: row.model_id,
            name: row.name,
            kind: row.kind,
            shapes: row.shapes,
            sha256: Some(row.object_sha256),
            ignored_columns: row
                .ignored
                .0
                .into_iter()
                .map(|(column, reason)| IgnoredColumn { column, reason })
                .collect(),
            created_at: Some(row.created_at),
        }
    }

    fn own(model_id: &str, kind: &str, shapes: usize) -> Self {
        Self {
            id: serde_json::json!(kind),
            model_id: model_id.to_owned(),
            name: kind.to_owned(),
            kind: kind.to_owned(),
            shapes: shapes as i64,
            has_surfaces: true,
            sha256: None,
            ignored_columns: Vec::new(),
            created_at: None,
            links: ReferenceLinks {
                this: None,
                model: format!("/v1/models/{model_id}"),
            },
        }
    }
}

/// The content of a reference upload, validated.
enum ReferenceContent {
    /// `(stored name, canonical mesh bytes)` in upload order.
    Meshes(Vec<(String, Vec<u8>)>),
    /// The table's text, its rows and the columns not compared.
    Table {
        text: String,
        rows: usize,
        ignored: Vec<(String, String)>,
    },
}

/// Uploads a real population as a reference for a model's cohorts: patient meshes in mm
/// (multipart parts `files`, zip archives accepted, or one zip body) or a measurements table
/// (multipart part `table`, or a `text/csv` body). Every mesh and every table cell is
/// checked before anything is stored; the answer is 201 with the reference.
#[utoipa::path(post, path = "/v1/models/{id}/references", tag = "validation",
    params(("id" = String, Path, description = "Model id"), ReferenceQuery),
    request_body(content(
        (ReferenceUpload = "multipart/form-data"),
        (Vec<u8> = "application/zip"),
        (String = "text/csv")
    )),
    responses((status = 201, body = ReferenceView),
              (status = 400, body = Problem, content_type = "application/problem+json", description = "Malformed body"),
              (status = 404, body = Problem, content_type = "application/problem+json", description = "Unknown model"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Name taken"),
              (status = 413, body = Problem, content_type = "application/problem+json"),
              (status = 415, body = Problem, content_type = "application/problem+json"),
              (status = 422, body = Problem, content_type = "application/problem+json", description = "Not a usable mesh, a table column or cell that breaks a rule (named), or too few shapes")))]
async fn create_reference(
    State(state): State<AppState>,
    Path(model_id): Path<String>,
    ApiQuery(query): ApiQuery<ReferenceQuery>,
    request: Request,
) -> Result<Response> {
    db::models::get(&state.pool, &model_id)
        .await?
        .ok_or_else(|| ApiError::not_found("model", &model_id))?;
    let (name, content) = read_reference_upload(&state, query, request).await?;
    let name = name.ok_or_else(|| ApiError::invalid("name", "required", "a name is required"))?;
    check_name(&name)?;
    if matches!(name.as_str(), "training" | "heldout") {
        let msg = format!("{name:?} is the model's own reference; choose another name");
        return Err(ApiError::invalid("name", "reserved", msg));
    }
    let (kind, shapes, object, ignored) = match content {
        ReferenceContent::Meshes(meshes) => {
            let count = meshes.len();
            let bundle = crate::objects::bundle::pack_files(&meshes);
            ("meshes", count, bundle, Vec::new())
        }
        ReferenceContent::Table {
            text,
            rows,
            ignored,
        } => ("measurements", rows, text.into_bytes(), ignored),
    };
    let object_sha256 = state.jobs.objects.put(&object).await?;
    let mut tx = db::begin_write(&state.pool).await?;
    if db::references::name_taken(&mut tx, &model_id, &name).await? {
        return Err(ApiError::Conflict(format!(
            "model {model_id:?} already has a reference named {name:?}"
        )));
    }
    let reference_id = db::references::insert(
        &mut tx,
        &db::references::NewReference {
            model_id: &model_id,
            name: &name,
            kind,
            shapes: shapes as i64,
            object_sha256: &object_sha256,
            ignored: &ignored,
        },
    )
    .await?;
    let row = db::references::get(&mut *tx, reference_id)
        .await?
        .ok_or_else(|| anyhow::anyhow!("the new reference {reference_id} is missing"))?;
    tx.commit().await?;
    tracing::info!(model_id, reference_id, kind, shapes, "reference stored");
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, format!("/v1/references/{reference_id}"))],
        Json(ReferenceView::from_row(row)),
    )
        .into_response())
}

/// Reads a reference upload from a multipart form, a zip body or a CSV body, and checks its
/// content off the executor.
async fn read_reference_upload(
    state: &AppState,
    query: ReferenceQuery,
    request: Request,
) -> Result<(Option<String>, ReferenceContent)> {
    let limit = state.config.max_upload_bytes;
    let archive_limits = ArchiveLimits {
        entries: state.config.max_archive_entries,
        bytes: state.config.max_archive_bytes,
    };
    let mut name = query.name;
    let mut meshes = Unpacked::default();
    let mut table: Option<Bytes> = None;
    let content_type = request
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .map(|t| t.trim().to_ascii_lowercase())
        .unwrap_or_default();
    if is_zip_body(request.headers()) {
        let body = Bytes::from_request(request, state)
            .await
            .map_err(|e| body_error(e.status(), e.body_text(), limit))?;
        meshes = unpack_blocking("upload.zip".into(), body, archive_limits, meshes).await?;
    } else if content_type.starts_with("text/csv") {
        let body = Bytes::from_request(request, state)
            .await
            .map_err(|e| body_error(e.status(), e.body_text(), limit))?;
        table = Some(body);
    } else {
        let mut form = Multipart::from_request(request, state).await.map_err(|e| {
            ApiError::UnsupportedMediaType {
                expected: "multipart/form-data, application/zip or text/csv",
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
                "table" => {
                    if table.is_some() {
                        let msg = "one table per reference";
                        return Err(ApiError::invalid("table", "count", msg));
                    }
                    table = Some(bytes);
                }
                "files" | "file" => {
                    let file_name =
                        file_name.unwrap_or_else(|| format!("file-{}", meshes.files.len()));
                    if looks_like_zip(Some(&file_name), &bytes) {
                        meshes = unpack_blocking(file_name, bytes, archive_limits, meshes).await?;
                    } else {
                        meshes.files.push((file_name, Vec::from(bytes)));
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
    let label = name.clone().unwrap_or_default();
    let content = tokio::task::spawn_blocking(move || match table {
        Some(_) if !meshes.files.is_empty() => Err(ApiError::invalid(
            "table",
            "exclusive",
            "a reference is either meshes (`files`) or one measurements table (`table`), not both",
        )),
        Some(bytes) => check_table(&label, &bytes),
        None => check_meshes(meshes.files),
    })
    .await
    .map_err(anyhow::Error::from)??;
    Ok((name, content))
}

/// A measurements table: UTF-8, every column known (or reported as not compared), every
/// cell a number in mm, at least two rows.
fn check_table(label: &str, bytes: &[u8]) -> Result<ReferenceContent> {
    let text = std::str::from_utf8(bytes)
        .map_err(|e| ApiError::invalid("table", "encoding", format!("not UTF-8 text: {e}")))?;
    let table = crate::validation::table::parse_table(label, text)?;
    let rows = table.population.len();
    if rows < MIN_REFERENCE_SHAPES {
        let msg = format!("at least {MIN_REFERENCE_SHAPES} rows are needed, got {rows}");
        return Err(ApiError::invalid("table", "count", msg));
    }
    Ok(ReferenceContent::Table {
        text: text.to_owned(),
        rows,
        ignored: table.ignored,
    })
}

/// Patient meshes: each parsed and checked like a training upload, kept in the canonical
/// encoding under its upload position and file name.
fn check_meshes(files: Vec<(String, Vec<u8>)>) -> Result<ReferenceContent> {
    if files.len() < MIN_REFERENCE_SHAPES {
        let msg = format!(
            "at least {MIN_REFERENCE_SHAPES} meshes (or a `table`) are needed, got {}",
            files.len()
        );
        return Err(ApiError::invalid("files", "count", msg));
    }
    let mut meshes = Vec::with_capacity(files.len());
    for (i, (name, bytes)) in files.into_iter().enumerate() {
        let (_, mesh) = read_valid_mesh(&format!("files[{name}]"), &name, &bytes)?;
        let base = name.rsplit('/').next().unwrap_or(&name);
        meshes.push((
            format!("{i:04}-{base}"),
            crate::formats::mesh_blob::encode(&mesh),
        ));
    }
    Ok(ReferenceContent::Meshes(meshes))
}

/// A model's reference populations: its own (`training`, and `heldout` when it was trained
/// with a holdout) first, then the uploaded ones, oldest first.
#[utoipa::path(get, path = "/v1/models/{id}/references", tag = "validation",
    params(("id" = String, Path, description = "Model id")),
    responses((status = 200, body = Vec<ReferenceView>),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn list_references(
    State(state): State<AppState>,
    Path(model_id): Path<String>,
) -> Result<Json<Vec<ReferenceView>>> {
    let model = db::models::get(&state.pool, &model_id)
        .await?
        .ok_or_else(|| ApiError::not_found("model", &model_id))?;
    let mut views = Vec::new();
    if let Some((training, heldout)) = own_reference_sizes(&state, &model).await? {
        views.push(ReferenceView::own(&model_id, "training", training));
        if heldout > 0 {
            views.push(ReferenceView::own(&model_id, "heldout", heldout));
        }
    }
    for row in db::references::list_for_model(&state.pool, &model_id).await? {
        views.push(ReferenceView::from_row(row));
    }
    Ok(Json(views))
}

/// The sizes of a ready model's training and held-out sets, from its manifest; None while
/// it is not ready or when it has no manifest.
async fn own_reference_sizes(
    state: &AppState,
    model: &db::models::ModelRow,
) -> Result<Option<(usize, usize)>> {
    if model.status != ModelStatus::Ready {
        return Ok(None);
    }
    let dir = state.jobs.model_dir(model).await?;
    let read = tokio::task::spawn_blocking(move || crate::sdf::store::read_manifest(&dir))
        .await
        .map_err(anyhow::Error::from)?;
    // A model registered without a manifest (no recorded training data) has none of its own.
    let Ok(manifest) = read else {
        return Ok(None);
    };
    let heldout = manifest.data.holdout.as_ref().map_or(0, |h| h.shapes.len());
    Ok(Some((manifest.transforms().len(), heldout)))
}

/// One uploaded reference.
#[utoipa::path(get, path = "/v1/references/{id}", tag = "validation",
    params(("id" = i64, Path, description = "Reference id")),
    responses((status = 200, body = ReferenceView),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn get_reference(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<ReferenceView>> {
    let reference_id = parse_id("reference", &id)?;
    let row = db::references::get(&state.pool, reference_id)
        .await?
        .ok_or_else(|| ApiError::not_found("reference", &id))?;
    Ok(Json(ReferenceView::from_row(row)))
}

/// Deletes an uploaded reference. Refused while a validation names it (delete those
/// first: their reports cite it).
#[utoipa::path(delete, path = "/v1/references/{id}", tag = "validation",
    params(("id" = i64, Path, description = "Reference id")),
    responses((status = 204, description = "Deleted"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Validations name it")))]
async fn delete_reference(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode> {
    let reference_id = parse_id("reference", &id)?;
    let mut tx = db::begin_write(&state.pool).await?;
    let used = db::references::validation_count(&mut tx, reference_id).await?;
    if used > 0 {
        return Err(ApiError::Conflict(format!(
            "reference {id} is named by {used} validation(s); delete them first"
        )));
    }
    if !db::references::delete(&mut tx, reference_id).await? {
        return Err(ApiError::not_found("reference", &id));
    }
    tx.commit().await?;
    Ok(StatusCode::NO_CONTENT)
}

/// A validation request.
#[derive(Debug, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateValidation {
    /// The reference: `heldout` (the model's held-out shapes: new patients), `training`, or
    /// an uploaded reference's id.
    #[schema(value_type = ReferenceName, example = json!("heldout"))]
    pub reference: serde_json::Value,
    /// Acceptance criteria, every one optional, e.g. `{"nna_max": 0.6, "ks_p_min": 0.05,
    /// "tost_margin_mm": {"annulus_mm": 1.0}}`.
    #[serde(default)]
    pub criteria: Option<AcceptanceCriteria>,
    /// The trial's context of use, for the dossier.
    pub context_of_use: Option<String>,
    /// The question of interest, for the dossier.
    pub question_of_interest: Option<String>,
    /// Surface samples per shape for the Chamfer distances, 1–100000 (default 10000).
    #[schema(minimum = 1, maximum = 100000)]
    pub points: Option<u64>,
    /// Equal-size subsets of 1-NNA, MMD and COV, 1–10000 (default 200).
    #[schema(minimum = 1, maximum = 10000)]
    pub subsets: Option<u64>,
    /// Bootstrap resamples of SIMCor's density-band test, 1–100000 (default 2000).
    #[schema(minimum = 1, maximum = 100000)]
    pub resamples: Option<u64>,
    /// Its uncertainty discount α (default a fixed 0.8).
    pub discount: Option<Discount>,
    /// Seed of the samplings, subsets and resamples (default 0).
    pub seed: Option<u64>,
}

/// URLs of a validation's related resources.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ValidationLinks {
    /// This validation.
    #[serde(rename = "self")]
    pub this: String,
    /// Its job (progress counts Chamfer distances).
    pub job: String,
    /// The validated cohort.
    pub cohort: String,
    /// The HTML report, once computed.
    pub report_html: String,
}

/// A validation: where its job stands, and its verdict and report once computed.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ValidationView {
    /// Validation id.
    pub id: i64,
    /// The validated cohort.
    pub cohort_id: i64,
    /// `heldout`, `training` or the uploaded reference's id.
    #[schema(value_type = ReferenceName)]
    pub reference: serde_json::Value,
    /// queued | running | succeeded | failed | cancelled (its job's status).
    pub status: JobStatus,
    /// Its job.
    pub job_id: i64,
    /// Chamfer distances done and in all (known once the job has read its populations).
    pub progress: ValidationProgress,
    /// pass | fail | inconclusive, once computed.
    pub verdict: Option<Verdict>,
    /// Why the job failed.
    pub error: Option<String>,
    /// The request with its defaults.
    #[schema(value_type = Object)]
    pub request: serde_json::Value,
    /// The report (`GET /v1/validations/{id}` only, once computed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub report: Option<ValidationReport>,
    /// Creation time (UTC, RFC 3339).
    pub created_at: String,
    /// Related resources.
    pub links: ValidationLinks,
}

/// Units of work of a validation job.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ValidationProgress {
    /// Done.
    pub done: i64,
    /// In all (0 until known).
    pub total: i64,
}

impl ValidationView {
    fn new(row: ValidationRow, job: Option<db::jobs::JobRow>, with_report: bool) -> Result<Self> {
        let id = row.validation_id;
        let report: Option<ValidationReport> = match (&row.report, with_report) {
            (Some(text), true) => Some(serde_json::from_str(text).map_err(anyhow::Error::from)?),
            _ => None,
        };
        let verdict = row
            .verdict
            .as_deref()
            .and_then(|v| serde_json::from_value(serde_json::json!(v)).ok());
        let reference = match row.reference_id {
            Some(r) => serde_json::json!(r),
            None => serde_json::json!(row.reference),
        };
        Ok(Self {
            id,
            cohort_id: row.cohort_id,
            reference,
            status: job.as_ref().map_or(JobStatus::Failed, |j| j.status),
            job_id: row.job_id,
            progress: ValidationProgress {
                done: job.as_ref().map_or(0, |j| j.progress_done),
                total: job.as_ref().map_or(0, |j| j.progress_total),
            },
            verdict,
            error: job.and_then(|j| j.error),
            request: serde_json::from_str(&row.request).unwrap_or(serde_json::Value::Null),
            report,
            created_at: row.created_at,
            links: ValidationLinks {
                this: format!("/v1/validations/{id}"),
                job: format!("/v1/jobs/{}", row.job_id),
                cohort: format!("/v1/cohorts/{}", row.cohort_id),
                report_html: format!("/v1/validations/{id}/report.html"),
            },
        })
    }
}

/// Queues the validation of a finished cohort against a reference population; answers 202
/// with the validation, whose job's progress counts Chamfer distances. The report is
/// stored when the job succeeds.
#[utoipa::path(post, path = "/v1/cohorts/{id}/validations", tag = "validation",
    params(("id" = i64, Path, description = "Cohort id")),
    request_body = CreateValidation,
    responses((status = 202, body = ValidationView),
              (status = 400, body = Problem, content_type = "application/problem+json", description = "Malformed JSON"),
              (status = 404, body = Problem, content_type = "application/problem+json", description = "Unknown cohort"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "The cohort has not succeeded"),
              (status = 415, body = Problem, content_type = "application/problem+json", description = "The body is not `application/json`"),
              (status = 422, body = Problem, content_type = "application/problem+json", description = "A field breaks a rule: an unknown reference or one of another model, `heldout` for a model without a holdout, a criterion out of range (named, e.g. `criteria.nna_max`), or `points` over the work budget (Chamfer distances × points, `--max-validation-work`)"),
              (status = 429, body = Problem, content_type = "application/problem+json", description = "Queue full; see Retry-After")))]
async fn create_validation(
    State(state): State<AppState>,
    Path(id): Path<String>,
    ApiJson(body): ApiJson<CreateValidation>,
) -> Result<Response> {
    let cohort_id = parse_id("cohort", &id)?;
    let cohort = super::cohorts::load(&state, cohort_id, &id).await?;
    let criteria = body.criteria.unwrap_or_default();
    criteria.clone().check()?;
    let points = bounded(
        "points",
        body.points,
        MAX_POINTS,
        crate::validation::shapes::DEFAULT_POINTS as u64,
    )?;
    let subsets = bounded(
        "subsets",
        body.subsets,
        MAX_SUBSETS,
        crate::shape_metrics::nna::DEFAULT_SUBSETS as u64,
    )?;
    let resamples = bounded(
        "resamples",
        body.resamples,
        MAX_RESAMPLES,
        DEFAULT_RESAMPLES as u64,
    )?;
    let discount = body.discount.unwrap_or(Discount::Fixed(DEFAULT_DISCOUNT));
    if let Discount::Fixed(a) = discount
        && !(a.is_finite() && a > 0.0)
    {
        let msg = format!("a fixed discount must be a finite number > 0, got {a}");
        return Err(ApiError::invalid("discount.value", "range", msg));
    }
    if cohort.status != JobStatus::Succeeded {
        return Err(ApiError::Conflict(format!(
            "cohort {cohort_id} is {}; only a succeeded cohort can be validated",
            cohort.status
        )));
    }
    let chosen = check_reference(&state, &cohort.model_id, &body.reference).await?;
    check_work(
        &chosen,
        cohort.count as usize,
        points,
        state.config.max_validation_work,
    )?;
    let (reference, reference_id) = (chosen.stored, chosen.id);
    let settings = ValidationSettings {
        reference: reference.clone(),
        criteria,
        context_of_use: body.context_of_use,
        question_of_interest: body.question_of_interest,
        points,
        subsets,
        resamples,
        discount,
        seed: body.seed.unwrap_or(0),
    };
    let request = serde_json::to_string(&settings).map_err(anyhow::Error::from)?;
    let mut submission = state.queue.begin().await?;
    let validation_id = db::validations::next_id(submission.conn()).await?;
    let job = Job::Validation(ValidationPayload { validation_id });
    let job_id = submission.enqueue(&job, 0).await?;
    db::validations::insert(
        submission.conn(),
        &db::validations::NewValidation {
            validation_id,
            cohort_id,
            reference: &reference,
            reference_id,
            request: &request,
            job_id,
        },
    )
    .await?;
    submission.commit().await?;
    tracing::info!(
        cohort_id,
        validation_id,
        job_id,
        reference,
        "validation queued"
    );
    let row = db::validations::get(&state.pool, validation_id)
        .await?
        .ok_or_else(|| anyhow::anyhow!("the new validation {validation_id} is missing"))?;
    let job = db::jobs::get(&state.pool, job_id).await?;
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, format!("/v1/validations/{validation_id}"))],
        Json(ValidationView::new(row, job, false)?),
    )
        .into_response())
}

/// The reference a request names, checked against the cohort's model.
struct ChosenReference {
    /// `heldout`, `training`, or the uploaded reference's id as text.
    stored: String,
    /// The uploaded reference's id.
    id: Option<i64>,
    /// Its shapes with surfaces (none for a table: no shape level).
    surfaces: usize,
    /// The model's training and held-out set sizes, when its manifest records them.
    own: Option<(usize, usize)>,
}

async fn check_reference(
    state: &AppState,
    model_id: &str,
    value: &serde_json::Value,
) -> Result<ChosenReference> {
    let model = db::models::get(&state.pool, model_id)
        .await?
        .ok_or_else(|| ApiError::not_found("model", model_id))?;
    let own = own_reference_sizes(state, &model).await?;
    match value {
        serde_json::Value::String(s) if s == "training" || s == "heldout" => {
            let msg = match own {
                None => format!(
                    "model {model_id:?} has no recorded training data; name an uploaded \
                     reference"
                ),
                Some((_, 0)) if s == "heldout" => format!(
                    "model {model_id:?} was trained without a holdout; name `training` or an \
                     uploaded reference"
                ),
                Some((training, heldout)) => {
                    return Ok(ChosenReference {
                        stored: s.clone(),
                        id: None,
                        surfaces: if s == "training" { training } else { heldout },
                        own,
                    });
                }
            };
            Err(ApiError::invalid("reference", "exists", msg))
        }
        serde_json::Value::Number(n) => {
            let id = n.as_i64().filter(|id| *id > 0).ok_or_else(|| {
                ApiError::invalid("reference", "type", format!("{n} is not a reference id"))
            })?;
            let row = db::references::get(&state.pool, id).await?.ok_or_else(|| {
                let msg = format!("reference {id} does not exist");
                ApiError::invalid("reference", "exists", msg)
            })?;
            if row.model_id != model_id {
                let msg = format!(
                    "reference {id} belongs to model {:?}, not the cohort's {model_id:?}",
                    row.model_id
                );
                return Err(ApiError::invalid("reference", "same-model", msg));
            }
            let surfaces = match row.kind.as_str() {
                "meshes" => row.shapes as usize,
                _ => 0,
            };
            Ok(ChosenReference {
                stored: id.to_string(),
                id: Some(id),
                surfaces,
                own,
            })
        }
        other => {
            let msg = format!(
                "must be \"heldout\", \"training\" or an uploaded reference's id, got {other}"
            );
            Err(ApiError::invalid("reference", "type", msg))
        }
    }
}

/// The shape-level work budget: Chamfer distances × surface points per shape, named on
/// `points` (the knob a user turns; a table reference has no shape level).
fn check_work(chosen: &ChosenReference, cohort: usize, points: usize, max: u64) -> Result<()> {
    if chosen.surfaces == 0 {
        return Ok(());
    }
    let (training, heldout) = chosen.own.unwrap_or((0, 0));
    let is_training = chosen.stored == "training";
    let newcomers = if is_training { heldout } else { 0 };
    let pairs = crate::validation::shapes::chamfer_pairs(
        cohort,
        chosen.surfaces,
        training,
        newcomers,
        is_training,
    );
    let work = pairs.saturating_mul(points as u64);
    if work <= max {
        return Ok(());
    }
    let most = max / pairs.max(1);
    let msg = format!(
        "a validation's shape-level work must not exceed {max} (Chamfer distances × points), \
         got {pairs} distances × {points} points = {work}; with this cohort and reference \
         at most {most} points"
    );
    Err(ApiError::invalid("points", "budget", msg))
}

/// A cohort's validations, oldest first (without their reports).
#[utoipa::path(get, path = "/v1/cohorts/{id}/validations", tag = "validation",
    params(("id" = i64, Path, description = "Cohort id")),
    responses((status = 200, body = Vec<ValidationView>),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn list_validations(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<Vec<ValidationView>>> {
    let cohort_id = parse_id("cohort", &id)?;
    super::cohorts::load(&state, cohort_id, &id).await?;
    let mut views = Vec::new();
    for row in db::validations::list_for_cohort(&state.pool, cohort_id).await? {
        let job = db::jobs::get(&state.pool, row.job_id).await?;
        views.push(ValidationView::new(row, job, false)?);
    }
    Ok(Json(views))
}

async fn load_validation(state: &AppState, id: &str) -> Result<ValidationRow> {
    let validation_id = parse_id("validation", id)?;
    db::validations::get(&state.pool, validation_id)
        .await?
        .ok_or_else(|| ApiError::not_found("validation", id))
}

/// One validation: its job's status and progress, and once computed its verdict and the
/// whole report (dossier, shape level, measurement level, checks).
#[utoipa::path(get, path = "/v1/validations/{id}", tag = "validation",
    params(("id" = i64, Path, description = "Validation id")),
    responses((status = 200, body = ValidationView),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn get_validation(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<ValidationView>> {
    let row = load_validation(&state, &id).await?;
    let job = db::jobs::get(&state.pool, row.job_id).await?;
    Ok(Json(ValidationView::new(row, job, true)?))
}

/// The validation report as an HTML page: figures, overlaid histograms, the checks and the
/// credibility dossier. 409 until the job has succeeded.
#[utoipa::path(get, path = "/v1/validations/{id}/report.html", tag = "validation",
    params(("id" = i64, Path, description = "Validation id")),
    responses((status = 200, content_type = "text/html", body = String),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Not computed yet")))]
async fn validation_report_html(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response> {
    let row = load_validation(&state, &id).await?;
    let Some(text) = row.report else {
        let job = db::jobs::get(&state.pool, row.job_id).await?;
        let status = job.map_or(JobStatus::Failed, |j| j.status);
        return Err(ApiError::Conflict(format!(
            "validation {id} is {status}; its report exists once it has succeeded"
        )));
    };
    let report: ValidationReport = serde_json::from_str(&text).map_err(anyhow::Error::from)?;
    let page =
        tokio::task::spawn_blocking(move || crate::report::validation::validation_html(&report))
            .await
            .map_err(anyhow::Error::from)?;
    Ok(([(header::CONTENT_TYPE, "text/html; charset=utf-8")], page).into_response())
}

/// Deletes a validation and its report. Refused while its job is queued or running (cancel
/// it with `POST /v1/jobs/{id}/cancel` first).
#[utoipa::path(delete, path = "/v1/validations/{id}", tag = "validation",
    params(("id" = i64, Path, description = "Validation id")),
    responses((status = 204, description = "Deleted"),
              (status = 404, body = Problem, content_type = "application/problem+json"),
              (status = 409, body = Problem, content_type = "application/problem+json", description = "Its job is queued or running")))]
async fn delete_validation(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode> {
    let row = load_validation(&state, &id).await?;
    let job = db::jobs::get(&state.pool, row.job_id).await?;
    if job.as_ref().is_some_and(|j| j.status.is_pending()) {
        return Err(ApiError::Conflict(format!(
            "validation {id} is still running (job {}); cancel it first",
            row.job_id
        )));
    }
    let mut tx = db::begin_write(&state.pool).await?;
    db::validations::delete(&mut tx, row.validation_id).await?;
    db::jobs::delete(&mut tx, row.job_id).await?;
    tx.commit().await?;
    Ok(StatusCode::NO_CONTENT)
}
