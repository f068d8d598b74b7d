//! The `anchor` table: latents fitted to uploaded meshes for a frozen model. A row is created
//! with its `fit` job and completed (latent, Chamfer, transform) when the job succeeds.

use serde::Serialize;

use super::states::AnchorStatus;

/// An anchor row (the latent decoded from its blob).
#[derive(Debug, Clone, Serialize, sqlx::FromRow)]
pub struct AnchorRow {
    /// Primary key.
    pub anchor_id: i64,
    /// Model it was fitted for.
    pub model_id: String,
    /// Its fit job.
    pub job_id: i64,
    /// Unique per model.
    pub name: String,
    /// Where it stands.
    pub status: AnchorStatus,
    /// Uploaded file name.
    pub source_name: String,
    /// Where the uploaded bytes are kept for the job.
    pub source_path: String,
    /// Adam steps.
    pub iterations: i64,
    /// Fit seed.
    pub seed: i64,
    /// Little-endian f32 latent, once ready.
    #[serde(skip)]
    pub latent: Option<Vec<u8>>,
    /// Reconstruction Chamfer distance, once ready.
    pub chamfer: Option<f64>,
    /// Transform centre x.
    pub centre_x: Option<f64>,
    /// Transform centre y.
    pub centre_y: Option<f64>,
    /// Transform centre z.
    pub centre_z: Option<f64>,
    /// Transform scale.
    pub radius: Option<f64>,
    /// Why the fit failed.
    pub error: Option<String>,
    /// Creation time.
    pub created_at: String,
}

impl AnchorRow {
    /// The latent values, when fitted.
    pub fn latent_values(&self) -> Option<Vec<f32>> {
        self.latent.as_deref().map(super::latent_values)
    }

    /// The unit-ball transform, when fitted.
    pub fn transform(&self) -> Option<crate::geometry::normalize::UnitBallTransform> {
        Some(crate::geometry::normalize::UnitBallTransform {
            centre: [self.centre_x?, self.centre_y?, self.centre_z?],
            radius: self.radius?,
        })
    }
}

/// The selected columns, as a literal so queries stay static strings.
macro_rules! select_anchor {
    ($rest:literal) => {
        concat!(
            "select anchor_id, model_id, job_id, name, status, source_name, source_path,
                 iterations, seed, latent, chamfer, centre_x, centre_y, centre_z, radius, error,
                 created_at from anchor ",
            $rest
        )
    };
}

/// What a fit request stores before its job runs.
#[derive(Debug, Clone)]
pub struct NewAnchor<'a> {
    /// Its id, allocated in the same transaction ([`next_id`]).
    pub anchor_id: i64,
    /// Model id.
    pub model_id: &'a str,
    /// The fit job.
    pub job_id: i64,
    /// Name (unique per model).
    pub name: &'a str,
    /// Uploaded file name.
    pub source_name: &'a str,
    /// Where the bytes are kept.
    pub source_path: &'a str,
    /// Adam steps.
    pub iterations: i64,
    /// Seed.
    pub seed: i64,
}

/// Inserts a `fitting` anchor inside the caller's transaction; returns its id.
pub async fn insert(conn: &mut super::Conn, a: &NewAnchor<'_>) -> sqlx::Result<()> {
    sqlx::query(
        "insert into anchor (anchor_id, model_id, job_id, name, source_name, source_path,
             iterations, seed)
         values ($1, $2, $3, $4, $5, $6, $7, $8)",
    )
    .bind(a.anchor_id)
    .bind(a.model_id)
    .bind(a.job_id)
    .bind(a.name)
    .bind(a.source_name)
    .bind(a.source_path)
    .bind(a.iterations)
    .bind(a.seed)
    .execute(conn)
    .await?;
    Ok(())
}

/// Allocates the next anchor's id (never one a deleted anchor had, see [`super::ids`])
/// inside the caller's write transaction, known before the fit job that refers to it.
pub async fn next_id(conn: &mut super::Conn) -> sqlx::Result<i64> {
    super::ids::allocate(conn, super::ids::IdKind::Anchor).await
}

/// Records a successful fit.
pub async fn set_fitted<'e>(
    pool: impl super::Executor<'e>,
    anchor_id: i64,
    latent: &[f32],
    chamfer: f64,
    transform: &crate::geometry::normalize::UnitBallTransform,
) -> sqlx::Result<()> {
    let blob = super::latent_blob(latent);
    sqlx::query(
        "update anchor set status = 'ready', latent = $1, chamfer = $2, centre_x = $3,
             centre_y = $4, centre_z = $5, radius = $6, error = null,
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where anchor_id = $7",
    )
    .bind(blob)
    .bind(chamfer)
    .bind(transform.centre[0])
    .bind(transform.centre[1])
    .bind(transform.centre[2])
    .bind(transform.radius)
    .bind(anchor_id)
    .execute(pool)
    .await?;
    Ok(())
}

/// Records a fit that did not succeed.
pub async fn set_failed<'e>(
    pool: impl super::Executor<'e>,
    anchor_id: i64,
    error: &str,
) -> sqlx::Result<()> {
    sqlx::query(
        "update anchor set status = 'failed', error = $1,
             updated_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')
         where anchor_id = $2",
    )
    .bind(error)
    .bind(anchor_id)
    .execute(pool)
    .await?;
    Ok(())
}

/// One anchor by id.
pub async fn get(pool: &super::Pool, anchor_id: i64) -> sqlx::Result<Option<AnchorRow>> {
    sqlx::query_as(select_anchor!("where anchor_id = $1"))
        .bind(anchor_id)
        .fetch_optional(pool)
        .await
}

/// One anchor by model and name.
pub async fn get_by_name(
    conn: &mut super::Conn,
    model_id: &str,
    name: &str,
) -> sqlx::Result<Option<AnchorRow>> {
    sqlx::query_as(select_anchor!("where model_id = $1 and name = $2"))
        .bind(model_id)
        .bind(name)
        .fetch_optional(conn)
        .await
}

/// A model's anchors, oldest first.
pub async fn list_for_model(pool: &super::Pool, model_id: &str) -> sqlx::Result<Vec<AnchorRow>> {
    sqlx::query_as(select_anchor!("where model_id = $1 order by anchor_id"))
        .bind(model_id)
        .fetch_all(pool)
        .await
}

/// Cohorts whose request names the anchor.
pub async fn cohort_count(pool: &super::Pool, anchor_id: i64) -> sqlx::Result<i64> {
    sqlx::query_scalar("select count(distinct cohort_id) from cohort_anchor where anchor_id = $1")
        .bind(anchor_id)
        .fetch_one(pool)
        .await
}

/// Records the anchors a cohort forces into every shape (inside its creating transaction).
pub async fn set_cohort_anchors(
    conn: &mut super::Conn,
    cohort_id: i64,
    anchor_ids: &[i64],
) -> sqlx::Result<()> {
    for (position, &anchor_id) in anchor_ids.iter().enumerate() {
        sqlx::query(
            "insert into cohort_anchor (cohort_id, position, anchor_id) values ($1, $2, $3)",
        )
        .bind(cohort_id)
        .bind(position as i64)
        .bind(anchor_id)
        .execute(&mut *conn)
        .await?;
    }
    Ok(())
}

/// Records the anchors a stored shape mixed (inside the shape's transaction).
pub async fn set_shape_anchors(
    conn: &mut super::Conn,
    shape_id: i64,
    anchor_ids: &[i64],
) -> sqlx::Result<()> {
    for (position, &anchor_id) in anchor_ids.iter().enumerate() {
        sqlx::query("insert into shape_anchor (shape_id, position, anchor_id) values ($1, $2, $3)")
            .bind(shape_id)
            .bind(position as i64)
            .bind(anchor_id)
            .execute(&mut *conn)
            .await?;
    }
    Ok(())
}

/// Removes an anchor; false when it did not exist.
pub async fn delete(pool: &super::Pool, anchor_id: i64) -> sqlx::Result<bool> {
    let done = sqlx::query("delete from anchor where anchor_id = $1")
        .bind(anchor_id)
        .execute(pool)
        .await?;
    Ok(done.rows_affected() == 1)
}
