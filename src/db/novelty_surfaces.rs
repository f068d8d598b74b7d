//! The `novelty_surface` table: each training shape of a model as reconstructed at a
//! resolution, the surfaces cohorts measure novelty against. Stored one by one as they are
//! computed, so the setup survives restarts and is computed once per model and resolution.

use sqlx::SqlitePool;

/// The stored surfaces of `model_id` at `resolution`: (training index, mesh blob).
pub async fn stored(
    pool: &SqlitePool,
    model_id: &str,
    resolution: usize,
) -> sqlx::Result<Vec<(i64, Vec<u8>)>> {
    sqlx::query_as(
        "select shape_index, mesh from novelty_surface
         where model_id = ? and resolution = ? order by shape_index",
    )
    .bind(model_id)
    .bind(resolution as i64)
    .fetch_all(pool)
    .await
}

/// Stores one surface computed by `job_id` and counts it as a setup step of that job, in
/// one transaction; a surface stored already is kept (and not counted).
pub async fn store(
    pool: &SqlitePool,
    job_id: i64,
    model_id: &str,
    resolution: usize,
    shape_index: usize,
    mesh: &[u8],
) -> sqlx::Result<()> {
    let mut tx = pool.begin_with(super::BEGIN_WRITE).await?;
    let inserted = sqlx::query(
        "insert into novelty_surface (model_id, resolution, shape_index, mesh)
         values (?, ?, ?, ?) on conflict do nothing",
    )
    .bind(model_id)
    .bind(resolution as i64)
    .bind(shape_index as i64)
    .bind(mesh)
    .execute(&mut *tx)
    .await?
    .rows_affected();
    if inserted == 1 {
        sqlx::query(
            "update job set setup_done = setup_done + 1,
                 updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
             where job_id = ?",
        )
        .bind(job_id)
        .execute(&mut *tx)
        .await?;
    }
    tx.commit().await
}
