//! The `novelty_surface` table: each training shape of a model as reconstructed at a
//! resolution, the surfaces cohorts measure novelty against. Stored one by one as they are
//! computed, so the setup survives restarts and is computed once per model and resolution.

/// The stored surfaces of `model_id` at `resolution`: (training index, mesh blob).
pub async fn stored(
    pool: &super::Pool,
    model_id: &str,
    resolution: usize,
) -> sqlx::Result<Vec<(i64, Vec<u8>)>> {
    sqlx::query_as(
        "select shape_index, mesh from novelty_surface
         where model_id = $1 and resolution = $2 order by shape_index",
    )
    .bind(model_id)
    .bind(resolution as i64)
    .fetch_all(pool)
    .await
}

/// The training indices stored for `model_id` at `resolution`.
pub async fn stored_indices(
    pool: &super::Pool,
    model_id: &str,
    resolution: usize,
) -> sqlx::Result<Vec<i64>> {
    sqlx::query_scalar(
        "select shape_index from novelty_surface
         where model_id = $1 and resolution = $2 order by shape_index",
    )
    .bind(model_id)
    .bind(resolution as i64)
    .fetch_all(pool)
    .await
}

/// One training surface of a model at a resolution.
#[derive(Debug, Clone, Copy)]
pub struct Surface<'a> {
    /// The model.
    pub model_id: &'a str,
    /// The resolution it was reconstructed at.
    pub resolution: usize,
    /// The training shape's index.
    pub shape_index: usize,
    /// The unit-ball mesh, encoded.
    pub mesh: &'a [u8],
}

/// Stores one surface computed by `job_id` and counts it as a setup step of that job,
/// inside the caller's transaction; a surface stored already is kept (and not counted).
pub async fn store(conn: &mut super::Conn, job_id: i64, surface: &Surface<'_>) -> sqlx::Result<()> {
    let inserted = sqlx::query(
        "insert into novelty_surface (model_id, resolution, shape_index, mesh)
         values ($1, $2, $3, $4) on conflict do nothing",
    )
    .bind(surface.model_id)
    .bind(surface.resolution as i64)
    .bind(surface.shape_index as i64)
    .bind(surface.mesh)
    .execute(&mut *conn)
    .await?
    .rows_affected();
    if inserted == 1 {
        sqlx::query(
            "update job set setup_done = setup_done + 1,
                 updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
             where job_id = $1",
        )
        .bind(job_id)
        .execute(conn)
        .await?;
    }
    Ok(())
}
