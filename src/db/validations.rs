//! The `validation` table: a cohort validated against a reference population by a
//! one-task `validation` job; the report is stored when the job succeeds.

use serde::Serialize;

/// A validation row.
#[derive(Debug, Clone, Serialize, sqlx::FromRow)]
pub struct ValidationRow {
    /// Primary key.
    pub validation_id: i64,
    /// The validated cohort.
    pub cohort_id: i64,
    /// `heldout`, `training` or a reference id.
    pub reference: String,
    /// The reference population's id, when it is an uploaded one.
    pub reference_id: Option<i64>,
    /// The request with its defaults (JSON).
    pub request: String,
    /// Its job.
    pub job_id: i64,
    /// The report (JSON), once computed.
    pub report: Option<String>,
    /// The overall verdict, once computed.
    pub verdict: Option<String>,
    /// Creation time.
    pub created_at: String,
}

/// What a validation request stores before its job runs.
#[derive(Debug, Clone)]
pub struct NewValidation<'a> {
    /// Its id ([`next_id`]).
    pub validation_id: i64,
    /// The cohort.
    pub cohort_id: i64,
    /// `heldout`, `training` or a reference id.
    pub reference: &'a str,
    /// The uploaded reference's id, if any.
    pub reference_id: Option<i64>,
    /// The request (JSON).
    pub request: &'a str,
    /// Its job.
    pub job_id: i64,
}

macro_rules! select_validation {
    ($rest:literal) => {
        concat!(
            "select validation_id, cohort_id, reference, reference_id, request, job_id, report,
                 verdict, created_at from validation ",
            $rest
        )
    };
}

/// Allocates a validation id inside the caller's write transaction, known before its job.
pub async fn next_id(conn: &mut super::Conn) -> sqlx::Result<i64> {
    super::ids::allocate(conn, super::ids::IdKind::Validation).await
}

/// Inserts a validation inside the caller's transaction.
pub async fn insert(conn: &mut super::Conn, v: &NewValidation<'_>) -> sqlx::Result<()> {
    sqlx::query(
        "insert into validation (validation_id, cohort_id, reference, reference_id, request,
             job_id)
         values ($1, $2, $3, $4, $5, $6)",
    )
    .bind(v.validation_id)
    .bind(v.cohort_id)
    .bind(v.reference)
    .bind(v.reference_id)
    .bind(v.request)
    .bind(v.job_id)
    .execute(conn)
    .await?;
    Ok(())
}

/// One validation by id.
pub async fn get<'e>(
    ex: impl super::Executor<'e>,
    validation_id: i64,
) -> sqlx::Result<Option<ValidationRow>> {
    sqlx::query_as(select_validation!("where validation_id = $1"))
        .bind(validation_id)
        .fetch_optional(ex)
        .await
}

/// A cohort's validations, oldest first.
pub async fn list_for_cohort(
    pool: &super::Pool,
    cohort_id: i64,
) -> sqlx::Result<Vec<ValidationRow>> {
    sqlx::query_as(select_validation!(
        "where cohort_id = $1 order by validation_id"
    ))
    .bind(cohort_id)
    .fetch_all(pool)
    .await
}

/// Stores the report and its verdict.
pub async fn set_report(
    conn: &mut super::Conn,
    validation_id: i64,
    report: &str,
    verdict: &str,
) -> sqlx::Result<()> {
    sqlx::query("update validation set report = $1, verdict = $2 where validation_id = $3")
        .bind(report)
        .bind(verdict)
        .bind(validation_id)
        .execute(conn)
        .await?;
    Ok(())
}

/// The jobs of a cohort's validations (deleted with the cohort).
pub async fn job_ids_for_cohort(conn: &mut super::Conn, cohort_id: i64) -> sqlx::Result<Vec<i64>> {
    sqlx::query_scalar("select job_id from validation where cohort_id = $1")
        .bind(cohort_id)
        .fetch_all(conn)
        .await
}

/// Deletes a validation; returns whether it existed.
pub async fn delete(conn: &mut super::Conn, validation_id: i64) -> sqlx::Result<bool> {
    let done = sqlx::query("delete from validation where validation_id = $1")
        .bind(validation_id)
        .execute(conn)
        .await?;
    Ok(done.rows_affected() == 1)
}
