//! The `reference_population` table: real populations a model's cohorts are validated
//! against (uploaded patient meshes or a measurements table). The content itself is an
//! object (a bundle of meshes, or the table's text) named by `object_sha256`.

use serde::Serialize;

use super::Json;

/// A reference row.
#[derive(Debug, Clone, Serialize, sqlx::FromRow)]
pub struct ReferenceRow {
    /// Primary key.
    pub reference_id: i64,
    /// Model whose cohorts it validates.
    pub model_id: String,
    /// Unique per model.
    pub name: String,
    /// `meshes` or `measurements`.
    pub kind: String,
    /// Shapes (meshes) or rows (table).
    pub shapes: i64,
    /// The stored content.
    pub object_sha256: String,
    /// Table columns accepted but not compared: `[column, why]`.
    pub ignored: Json<Vec<(String, String)>>,
    /// Creation time.
    pub created_at: String,
}

/// What an upload stores.
#[derive(Debug, Clone)]
pub struct NewReference<'a> {
    /// Model id.
    pub model_id: &'a str,
    /// Name, unique per model.
    pub name: &'a str,
    /// `meshes` or `measurements`.
    pub kind: &'a str,
    /// Shapes or rows.
    pub shapes: i64,
    /// The stored content.
    pub object_sha256: &'a str,
    /// Columns not compared.
    pub ignored: &'a [(String, String)],
}

macro_rules! select_reference {
    ($rest:literal) => {
        concat!(
            "select reference_id, model_id, name, kind, shapes, object_sha256, ignored,
                 created_at from reference_population ",
            $rest
        )
    };
}

/// Inserts a reference inside the caller's write transaction; returns its id (never one a
/// deleted reference had).
pub async fn insert(conn: &mut super::Conn, r: &NewReference<'_>) -> sqlx::Result<i64> {
    let id = super::ids::allocate(conn, super::ids::IdKind::Reference).await?;
    sqlx::query(
        "insert into reference_population (reference_id, model_id, name, kind, shapes,
             object_sha256, ignored)
         values ($1, $2, $3, $4, $5, $6, $7)",
    )
    .bind(id)
    .bind(r.model_id)
    .bind(r.name)
    .bind(r.kind)
    .bind(r.shapes)
    .bind(r.object_sha256)
    .bind(serde_json::to_string(r.ignored).expect("pairs of strings serialise"))
    .execute(conn)
    .await?;
    Ok(id)
}

/// One reference by id.
pub async fn get<'e>(
    ex: impl super::Executor<'e>,
    reference_id: i64,
) -> sqlx::Result<Option<ReferenceRow>> {
    sqlx::query_as(select_reference!("where reference_id = $1"))
        .bind(reference_id)
        .fetch_optional(ex)
        .await
}

/// Whether the model has a reference of that name.
pub async fn name_taken(conn: &mut super::Conn, model_id: &str, name: &str) -> sqlx::Result<bool> {
    let n: i64 = sqlx::query_scalar(
        "select count(*) from reference_population where model_id = $1 and name = $2",
    )
    .bind(model_id)
    .bind(name)
    .fetch_one(conn)
    .await?;
    Ok(n > 0)
}

/// A model's references, oldest first.
pub async fn list_for_model(pool: &super::Pool, model_id: &str) -> sqlx::Result<Vec<ReferenceRow>> {
    sqlx::query_as(select_reference!(
        "where model_id = $1 order by reference_id"
    ))
    .bind(model_id)
    .fetch_all(pool)
    .await
}

/// Validations that name the reference.
pub async fn validation_count(conn: &mut super::Conn, reference_id: i64) -> sqlx::Result<i64> {
    sqlx::query_scalar("select count(*) from validation where reference_id = $1")
        .bind(reference_id)
        .fetch_one(conn)
        .await
}

/// Deletes a reference; returns whether it existed.
pub async fn delete(conn: &mut super::Conn, reference_id: i64) -> sqlx::Result<bool> {
    let done = sqlx::query("delete from reference_population where reference_id = $1")
        .bind(reference_id)
        .execute(conn)
        .await?;
    Ok(done.rows_affected() == 1)
}
