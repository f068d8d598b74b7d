//! The `cohort_metric` table: a cohort's pairwise Chamfer matrix and its summary.

/// Stored pairwise metrics of one cohort.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct CohortMetricRow {
    /// Owning cohort.
    pub cohort_id: i64,
    /// JSON array of rows.
    pub matrix: String,
    /// JSON summary statistics.
    pub summary: String,
    /// When computed.
    pub created_at: String,
}

/// Stores (or replaces) a cohort's metrics.
pub async fn upsert<'e>(
    pool: impl super::Executor<'e>,
    cohort_id: i64,
    matrix: &[Vec<f64>],
    summary: &serde_json::Value,
) -> sqlx::Result<()> {
    let matrix = serde_json::to_string(matrix).expect("finite matrices serialise");
    sqlx::query(
        "insert into cohort_metric (cohort_id, matrix, summary) values ($1, $2, $3)
         on conflict (cohort_id) do update set matrix = excluded.matrix,
             summary = excluded.summary, updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')",
    )
    .bind(cohort_id)
    .bind(matrix)
    .bind(summary.to_string())
    .execute(pool)
    .await?;
    Ok(())
}

/// A cohort's metrics, if computed.
pub async fn get(pool: &super::Pool, cohort_id: i64) -> sqlx::Result<Option<CohortMetricRow>> {
    sqlx::query_as(
        "select cohort_id, matrix, summary, created_at from cohort_metric where cohort_id = $1",
    )
    .bind(cohort_id)
    .fetch_optional(pool)
    .await
}
