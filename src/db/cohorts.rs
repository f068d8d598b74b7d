//! The `cohort` table. A cohort's state and progress are its job's, so reads join `job`.

use sqlx::{SqliteConnection, SqlitePool};

/// What a new cohort row holds (already validated).
#[derive(Debug, Clone)]
pub struct NewCohort<'a> {
    /// Model to sample from.
    pub model_id: &'a str,
    /// Job that generates it.
    pub job_id: i64,
    /// Number of shapes.
    pub count: i64,
    /// Training shapes mixed per generated shape.
    pub arity: i64,
    /// `equal` or `dirichlet`.
    pub weighting: &'a str,
    /// Explicit weights, when given.
    pub weights: Option<&'a [f64]>,
    /// Seed actually used.
    pub seed: i64,
    /// Marching-cubes resolution.
    pub resolution: i64,
    /// Latent noise in training standard deviations.
    pub latent_noise: f64,
    /// `uniform` or `spread`.
    pub selection: &'a str,
    /// Smallest accepted Chamfer distance to a training shape.
    pub min_novelty: Option<f64>,
    /// Target ranges of anatomical measurements (JSON), if any.
    pub targets: Option<&'a str>,
    /// Most candidates per shape when targets are set.
    pub max_candidates: Option<i64>,
    /// Client-chosen retry key.
    pub idempotency_key: Option<&'a str>,
    /// Hash of the canonical request.
    pub request_hash: &'a str,
}

/// A cohort with its job's state.
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
    pub weighting: String,
    /// Explicit weights (JSON), if any.
    pub weights: Option<String>,
    /// Seed used.
    pub seed: i64,
    /// Resolution.
    pub resolution: i64,
    /// Latent noise in training standard deviations.
    pub latent_noise: f64,
    /// Selection strategy of the mixed latents.
    pub selection: String,
    /// Smallest accepted Chamfer distance to a training shape.
    pub min_novelty: Option<f64>,
    /// Redraws over the stored shapes.
    pub redraws_total: i64,
    /// Target ranges of anatomical measurements (JSON), if any.
    pub targets: Option<String>,
    /// Most candidates per shape when targets are set.
    pub max_candidates: Option<i64>,
    /// Candidates drawn over the stored shapes (targeted cohorts).
    pub candidates_total: i64,
    /// Stored shapes that miss a target (the closest candidate was kept).
    pub targets_not_met: i64,
    /// Hash of the request (idempotency checks).
    pub request_hash: String,
    /// The job's status.
    pub status: String,
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
    /// Anchor ids forced into every shape (JSON array from `cohort_anchor`), if any.
    pub anchors: Option<String>,
}

const SELECT: &str = "select c.cohort_id, c.model_id, c.job_id, c.count, c.arity, c.weighting,
        c.weights, c.seed, c.resolution, c.latent_noise, c.selection, c.min_novelty,
        (select coalesce(sum(s.redraws), 0) from shape s where s.cohort_id = c.cohort_id)
            as redraws_total,
        c.targets, c.max_candidates,
        (select coalesce(sum(s.candidates), 0) from shape s where s.cohort_id = c.cohort_id)
            as candidates_total,
        (select count(*) from shape s where s.cohort_id = c.cohort_id and s.targets_met = 0)
            as targets_not_met,
        c.request_hash, j.status,
        (select count(*) from shape s where s.cohort_id = c.cohort_id) as shapes_done,
        j.error, c.created_at, j.started_at, j.finished_at,
        (select json_group_array(anchor_id) from (select anchor_id from cohort_anchor a
            where a.cohort_id = c.cohort_id order by a.position) having count(*) > 0)
            as anchors
    from cohort c join job j on j.job_id = c.job_id";

/// Inserts a cohort inside the caller's transaction and returns its id.
pub async fn insert(conn: &mut SqliteConnection, c: &NewCohort<'_>) -> sqlx::Result<i64> {
    let weights = c
        .weights
        .map(|w| serde_json::to_string(w).expect("f64 slices serialise"));
    sqlx::query_scalar(
        "insert into cohort (model_id, job_id, count, arity, weighting, weights, seed,
             resolution, latent_noise, selection, min_novelty, idempotency_key, request_hash,
             targets, max_candidates)
         values (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) returning cohort_id",
    )
    .bind(c.model_id)
    .bind(c.job_id)
    .bind(c.count)
    .bind(c.arity)
    .bind(c.weighting)
    .bind(weights)
    .bind(c.seed)
    .bind(c.resolution)
    .bind(c.latent_noise)
    .bind(c.selection)
    .bind(c.min_novelty)
    .bind(c.idempotency_key)
    .bind(c.request_hash)
    .bind(c.targets)
    .bind(c.max_candidates)
    .fetch_one(conn)
    .await
}

/// One cohort by id.
pub async fn get(pool: &SqlitePool, cohort_id: i64) -> sqlx::Result<Option<CohortRow>> {
    let sql = sqlx::AssertSqlSafe(format!("{SELECT} where c.cohort_id = ?"));
    sqlx::query_as(sql)
        .bind(cohort_id)
        .fetch_optional(pool)
        .await
}

/// The cohort created under an idempotency key, if any.
pub async fn find_by_idempotency_key(
    conn: &mut SqliteConnection,
    key: &str,
) -> sqlx::Result<Option<CohortRow>> {
    let sql = sqlx::AssertSqlSafe(format!("{SELECT} where c.idempotency_key = ?"));
    sqlx::query_as(sql).bind(key).fetch_optional(conn).await
}

/// A page of cohorts, newest first, optionally filtered by model and status.
pub async fn list(
    pool: &SqlitePool,
    model_id: Option<&str>,
    status: Option<&str>,
    limit: i64,
    offset: i64,
) -> sqlx::Result<Vec<CohortRow>> {
    let sql = sqlx::AssertSqlSafe(format!(
        "{SELECT} where (?1 is null or c.model_id = ?1) and (?2 is null or j.status = ?2)
         order by c.cohort_id desc limit ?3 offset ?4"
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
pub async fn delete(conn: &mut SqliteConnection, cohort_id: i64) -> sqlx::Result<bool> {
    let done = sqlx::query("delete from cohort where cohort_id = ?")
        .bind(cohort_id)
        .execute(conn)
        .await?;
    Ok(done.rows_affected() == 1)
}
