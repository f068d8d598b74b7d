//! The `cohort` table. A cohort's state and progress are its job's, so reads join `job`.

use std::collections::BTreeMap;

use super::Json;

use super::states::JobStatus;
use crate::cohort::targets::TargetRange;
use crate::cohort::{
    CohortFields, CohortRequest, RequestError, RequestLimits, SamplerFields, Selection, Weighting,
};

/// A new cohort row: a parsed request and how it arrived.
#[derive(Debug, Clone)]
pub struct NewCohort<'a> {
    /// Its id, allocated in the same transaction ([`next_id`]).
    pub cohort_id: i64,
    /// Model to sample from.
    pub model_id: &'a str,
    /// Job that generates it.
    pub job_id: i64,
    /// The request (anchors by id).
    pub request: &'a CohortRequest<i64>,
    /// Client-chosen retry key.
    pub idempotency_key: Option<&'a str>,
    /// Hash of the canonical request.
    pub request_hash: &'a str,
}

/// A cohort with its job's state, its request's fields typed as stored.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct CohortRow {
    /// Primary key.
    pub cohort_id: i64,
    /// Model it is drawn from.
    pub model_id: String,
    /// Its job.
    pub job_id: i64,
    /// Number of shapes requested.
    pub count: i64,
    /// Arity.
    pub arity: i64,
    /// Weighting strategy.
    pub weighting: Weighting,
    /// Explicit weights, if any.
    pub weights: Option<Json<Vec<f64>>>,
    /// Seed used.
    pub seed: i64,
    /// Resolution.
    pub resolution: i64,
    /// Latent noise in training standard deviations.
    pub latent_noise: f64,
    /// Selection strategy of the mixed latents.
    pub selection: Selection,
    /// Smallest accepted Chamfer distance to a training shape.
    pub min_novelty: Option<f64>,
    /// Redraws over the stored shapes.
    pub redraws_total: i64,
    /// Target ranges of anatomical measurements, if any.
    pub targets: Option<Json<BTreeMap<String, TargetRange>>>,
    /// Most candidates per shape when targets are set.
    pub max_candidates: Option<i64>,
    /// Candidates drawn over the stored shapes (targeted cohorts).
    pub candidates_total: i64,
    /// Stored shapes that miss a target (the closest candidate was kept).
    pub targets_not_met: i64,
    /// Hash of the request (idempotency checks).
    pub request_hash: String,
    /// The job's status.
    pub status: JobStatus,
    /// Shapes committed so far.
    pub shapes_done: i64,
    /// The job's error, when failed.
    pub error: Option<String>,
    /// Creation time.
    pub created_at: String,
    /// When work started.
    pub started_at: Option<String>,
    /// When work ended.
    pub finished_at: Option<String>,
    /// Anchor ids forced into every shape (from `cohort_anchor`), if any.
    pub anchors: Option<Json<Vec<i64>>>,
    /// The density sampler, if any (null: convex combinations).
    pub sampler: Option<Json<SamplerFields>>,
}

impl CohortRow {
    /// The request the row stores, parsed by the rules it was accepted under.
    pub fn request(&self) -> Result<CohortRequest<i64>, RequestError> {
        let fields = CohortFields {
            count: self.count,
            arity: Some(self.arity),
            weights: self.weights.as_ref().map(|w| w.0.clone()),
            weighting: Some(self.weighting),
            seed: Some(self.seed as u64),
            resolution: Some(self.resolution),
            latent_noise: Some(self.latent_noise),
            selection: Some(self.selection),
            min_novelty: self.min_novelty,
            targets: self.targets.as_ref().map(|t| t.0.clone()),
            max_candidates: self.max_candidates,
            anchors: self.anchors.as_ref().map(|a| a.0.clone()),
            sampler: self.sampler.as_ref().map(|s| s.0.clone()),
        };
        CohortRequest::parse(fields, RequestLimits::NONE, || self.seed as u64)
    }
}

const SELECT: &str = "select c.cohort_id, c.model_id, c.job_id, c.count, c.arity, c.weighting,
        c.weights, c.seed, c.resolution, c.latent_noise, c.selection, c.min_novelty,
        (select cast(coalesce(sum(s.redraws), 0) as bigint) from shape s
            where s.cohort_id = c.cohort_id)
            as redraws_total,
        c.targets, c.max_candidates,
        (select cast(coalesce(sum(s.candidates), 0) as bigint) from shape s
            where s.cohort_id = c.cohort_id)
            as candidates_total,
        (select count(*) from shape s where s.cohort_id = c.cohort_id and s.targets_met = 0)
            as targets_not_met,
        c.request_hash, j.status,
        (select count(*) from shape s where s.cohort_id = c.cohort_id) as shapes_done,
        j.error, c.created_at, j.started_at, j.finished_at,
        (select json_group_array(a.anchor_id order by a.position) from cohort_anchor a
            where a.cohort_id = c.cohort_id having count(*) > 0) as anchors,
        c.sampler
    from cohort c join job j on j.job_id = c.job_id";

/// Allocates the next cohort's id (never one a deleted cohort had, see [`super::ids`])
/// inside the caller's write transaction, known before the job that refers to it.
pub async fn next_id(conn: &mut super::Conn) -> sqlx::Result<i64> {
    super::ids::allocate(conn, super::ids::IdKind::Cohort).await
}

/// Inserts a cohort inside the caller's transaction.
pub async fn insert(conn: &mut super::Conn, c: &NewCohort<'_>) -> sqlx::Result<()> {
    let r = c.request;
    let targets = r.targets.as_ref().map(|t| Json(t.targets.to_map()));
    sqlx::query(
        "insert into cohort (cohort_id, model_id, job_id, count, arity, weighting, weights,
             seed, resolution, latent_noise, selection, min_novelty, idempotency_key,
             request_hash, targets, max_candidates, sampler)
         values ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16, $17)",
    )
    .bind(c.cohort_id)
    .bind(c.model_id)
    .bind(c.job_id)
    .bind(i64::from(r.count))
    .bind(r.arity as i64)
    .bind(r.weights.weighting())
    .bind(r.weights.fixed().map(|w| Json(w.to_vec())))
    .bind(r.seed as i64)
    .bind(r.resolution as i64)
    .bind(r.latent_noise)
    .bind(r.selection)
    .bind(super::NullableDouble(r.min_novelty))
    .bind(c.idempotency_key)
    .bind(c.request_hash)
    .bind(targets)
    .bind(r.targets.as_ref().map(|t| i64::from(t.max_candidates)))
    .bind(r.sampler.recorded().map(Json))
    .execute(&mut *conn)
    .await?;
    if !r.anchors.is_empty() {
        super::anchors::set_cohort_anchors(conn, c.cohort_id, &r.anchors).await?;
    }
    Ok(())
}

/// One cohort by id.
pub async fn get(pool: &super::Pool, cohort_id: i64) -> sqlx::Result<Option<CohortRow>> {
    let sql = sqlx::AssertSqlSafe(format!("{SELECT} where c.cohort_id = $1"));
    sqlx::query_as(sql)
        .bind(cohort_id)
        .fetch_optional(pool)
        .await
}

/// The cohort created under an idempotency key, if any.
pub async fn find_by_idempotency_key(
    conn: &mut super::Conn,
    key: &str,
) -> sqlx::Result<Option<CohortRow>> {
    let sql = sqlx::AssertSqlSafe(format!("{SELECT} where c.idempotency_key = $1"));
    sqlx::query_as(sql).bind(key).fetch_optional(conn).await
}

/// A page of cohorts, newest first, optionally filtered by model and status.
pub async fn list(
    pool: &super::Pool,
    model_id: Option<&str>,
    status: Option<JobStatus>,
    limit: i64,
    offset: i64,
) -> sqlx::Result<Vec<CohortRow>> {
    let sql = sqlx::AssertSqlSafe(format!(
        "{SELECT} where ($1 is null or c.model_id = $1) and ($2 is null or j.status = $2)
         order by c.cohort_id desc limit $3 offset $4"
    ));
    sqlx::query_as(sql)
        .bind(model_id)
        .bind(status)
        .bind(limit)
        .bind(offset)
        .fetch_all(pool)
        .await
}

/// Deletes a cohort (its shapes and metrics cascade) inside the caller's transaction.
pub async fn delete(conn: &mut super::Conn, cohort_id: i64) -> sqlx::Result<bool> {
    let done = sqlx::query("delete from cohort where cohort_id = $1")
        .bind(cohort_id)
        .execute(conn)
        .await?;
    Ok(done.rows_affected() == 1)
}
