//! The `shape_thumbnail` table: PNG previews of shapes, cached after their first rendering.

/// The cached picture of `shape_id` drawn from the mesh with digest `mesh_sha256` at
/// `size` pixels, if there is one.
pub async fn get(
    pool: &super::Pool,
    shape_id: i64,
    mesh_sha256: &str,
    size: u32,
) -> sqlx::Result<Option<Vec<u8>>> {
    sqlx::query_scalar(
        "select png from shape_thumbnail where shape_id = $1 and mesh_sha256 = $2 and size = $3",
    )
    .bind(shape_id)
    .bind(mesh_sha256)
    .bind(i64::from(size))
    .fetch_optional(pool)
    .await
}

/// Stores (or replaces) the picture of `shape_id`.
pub async fn put(
    pool: &super::Pool,
    shape_id: i64,
    mesh_sha256: &str,
    size: u32,
    png: &[u8],
) -> sqlx::Result<()> {
    sqlx::query(
        "insert into shape_thumbnail (shape_id, mesh_sha256, size, png) values ($1, $2, $3, $4)
         on conflict (shape_id) do update set mesh_sha256 = excluded.mesh_sha256,
             size = excluded.size, png = excluded.png,
             created_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')",
    )
    .bind(shape_id)
    .bind(mesh_sha256)
    .bind(i64::from(size))
    .bind(png)
    .execute(pool)
    .await?;
    Ok(())
}

/// Number of cached pictures.
pub async fn count(pool: &super::Pool) -> sqlx::Result<i64> {
    sqlx::query_scalar("select count(*) from shape_thumbnail")
        .fetch_one(pool)
        .await
}
