//! The `cohort_metric` table: a cohort's pairwise Chamfer distances and their summary; and
//! the `cohort_pair` table, where the metrics tasks leave their pairs until the last one
//! assembles them.

/// Stored pairwise metrics of one cohort.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct CohortMetricRow {
    /// Owning cohort.
    pub cohort_id: i64,
    /// The distances as JSON: the matrix (an array of rows) when every pair was computed,
    /// else `{"shapes": n, "pairs": [[i, j, d], …]}`.
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
    distances: &impl serde::Serialize,
    summary: &serde_json::Value,
) -> sqlx::Result<()> {
    let matrix = serde_json::to_string(distances).expect("finite distances serialise");
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

/// Stores computed pair distances `(i, j, d)` of a cohort (shape indices); a pair already
/// stored keeps its value (a task run again computes the same).
pub async fn insert_pairs(
    conn: &mut super::Conn,
    cohort_id: i64,
    pairs: &[(u32, u32, f64)],
) -> sqlx::Result<()> {
    // Bounded statements: four parameters a pair, well under SQLite's limit.
    for chunk in pairs.chunks(500) {
        let mut sql =
            String::from("insert into cohort_pair (cohort_id, shape_a, shape_b, chamfer) values ");
        for k in 0..chunk.len() {
            let p = 4 * k;
            if k > 0 {
                sql.push_str(", ");
            }
            sql.push_str(&format!("(${}, ${}, ${}, ${})", p + 1, p + 2, p + 3, p + 4));
        }
        sql.push_str(" on conflict (cohort_id, shape_a, shape_b) do nothing");
        let mut query = sqlx::query(sqlx::AssertSqlSafe(sql));
        for &(i, j, d) in chunk {
            query = query
                .bind(cohort_id)
                .bind(i64::from(i))
                .bind(i64::from(j))
                .bind(d);
        }
        query.execute(&mut *conn).await?;
    }
    Ok(())
}

/// A cohort's stored pair distances, ordered by `(i, j)`.
pub async fn stored_pairs(
    conn: &mut super::Conn,
    cohort_id: i64,
) -> sqlx::Result<Vec<(u32, u32, f64)>> {
    let rows: Vec<(i64, i64, f64)> = sqlx::query_as(
        "select shape_a, shape_b, chamfer from cohort_pair where cohort_id = $1
         order by shape_a, shape_b",
    )
    .bind(cohort_id)
    .fetch_all(conn)
    .await?;
    Ok(rows
        .into_iter()
        .map(|(i, j, d)| (i as u32, j as u32, d))
        .collect())
}

/// The pairs `(i, j)` stored for a cohort so far.
pub async fn stored_pair_keys(pool: &super::Pool, cohort_id: i64) -> sqlx::Result<Vec<(u32, u32)>> {
    let rows: Vec<(i64, i64)> =
        sqlx::query_as("select shape_a, shape_b from cohort_pair where cohort_id = $1")
            .bind(cohort_id)
            .fetch_all(pool)
            .await?;
    Ok(rows
        .into_iter()
        .map(|(i, j)| (i as u32, j as u32))
        .collect())
}

/// Drops a cohort's pair distances (once they are assembled into its metrics).
pub async fn delete_pairs(conn: &mut super::Conn, cohort_id: i64) -> sqlx::Result<()> {
    sqlx::query("delete from cohort_pair where cohort_id = $1")
        .bind(cohort_id)
        .execute(conn)
        .await?;
    Ok(())
}
