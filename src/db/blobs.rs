//! The `blob` table: the content-addressed object store of `AORTAGEN_BLOB_STORE=db`, one
//! row per distinct object named by the hex SHA-256 of its bytes. Rows of other tables name
//! objects (a shape its mesh); an object is written before the row that names it, and
//! objects no row names are swept after a grace period.

/// Stores an object unless one of that name exists (the bytes are then the same).
pub async fn put<'e>(ex: impl super::Executor<'e>, sha256: &str, bytes: &[u8]) -> sqlx::Result<()> {
    sqlx::query("insert into blob (sha256, bytes) values ($1, $2) on conflict (sha256) do nothing")
        .bind(sha256)
        .bind(bytes)
        .execute(ex)
        .await?;
    Ok(())
}

/// An object's bytes, or None.
pub async fn get(pool: &super::Pool, sha256: &str) -> sqlx::Result<Option<Vec<u8>>> {
    sqlx::query_scalar("select bytes from blob where sha256 = $1")
        .bind(sha256)
        .fetch_optional(pool)
        .await
}

/// Whether an object exists.
pub async fn exists(pool: &super::Pool, sha256: &str) -> sqlx::Result<bool> {
    let n: i64 = sqlx::query_scalar("select count(*) from blob where sha256 = $1")
        .bind(sha256)
        .fetch_one(pool)
        .await?;
    Ok(n > 0)
}

/// Deletes the objects no shape, model, reference population or training/fit job (its
/// inputs) names that were written before `before` (RFC 3339, the grace period's start): objects whose rows were deleted, or whose writer died before its
/// row. Returns how many.
pub async fn sweep_unreferenced(pool: &super::Pool, before: &str) -> sqlx::Result<u64> {
    Ok(sqlx::query(
        "delete from blob where created_at < $1
             and not exists (select 1 from shape s where s.mesh_sha256 = blob.sha256)
             and not exists (select 1 from model m where m.digest = blob.sha256)
             and not exists (select 1 from reference_population r
                                 where r.object_sha256 = blob.sha256)
             and not exists (select 1 from job j where j.kind <> 'cohort'
                                 and j.payload like '%' || blob.sha256 || '%')",
    )
    .bind(before)
    .execute(pool)
    .await?
    .rows_affected())
}

/// The names of every object a row refers to (what a sweep of an external store keeps):
/// meshes, model bundles, reference populations, and the inputs training and fit jobs name
/// in their payloads.
pub async fn referenced(pool: &super::Pool) -> sqlx::Result<Vec<String>> {
    let mut names: Vec<String> = sqlx::query_scalar(
        "select distinct mesh_sha256 from shape
         union select distinct digest from model where digest is not null
         union select distinct object_sha256 from reference_population",
    )
    .fetch_all(pool)
    .await?;
    let payloads: Vec<String> =
        sqlx::query_scalar("select payload from job where kind <> 'cohort'")
            .fetch_all(pool)
            .await?;
    for payload in &payloads {
        names.extend(sha256_names_in(payload));
    }
    Ok(names)
}

/// Every run of exactly 64 lowercase hex digits in `text` (the names objects have).
fn sha256_names_in(text: &str) -> impl Iterator<Item = String> + '_ {
    text.split(|c: char| !matches!(c, '0'..='9' | 'a'..='f'))
        .filter(|run| run.len() == 64)
        .map(str::to_owned)
}

#[cfg(test)]
mod tests {
    #[test]
    fn object_names_are_found_in_a_payload() {
        let a = "0123456789abcdef".repeat(4);
        let payload = format!(
            r#"{{"input_digest":"{a}","seed":12,"x":"{}"}}"#,
            "f".repeat(65)
        );
        let found: Vec<String> = super::sha256_names_in(&payload).collect();
        assert_eq!(found, [a]);
    }
}
