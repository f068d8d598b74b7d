//! The `model_refit` and `refit_shape` tables: a model's training shapes fitted once more
//! with the network frozen, as a new patient is fitted, by a `refit` job of one task per
//! shape. A density sampler asked for `"latents": "refitted"` draws from them once every
//! training shape has its row (see [`crate::sdf::store::refits`] for why).

use crate::engine::FittedAnchor;
use crate::geometry::normalize::UnitBallTransform;
use crate::sdf::store::refits::RefittedLatents;

/// A model's refit: its settings and the job fitting what is still missing.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct RefitRow {
    /// The model.
    pub model_id: String,
    /// The current job (a retry queues a new one).
    pub job_id: i64,
    /// Adam steps of every fit.
    pub iterations: i64,
    /// Seed of shape 0's fit; shape i uses seed + 2 i.
    pub seed: i64,
    /// When the refit was first requested.
    pub created_at: String,
}

/// One re-fitted training shape.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct RefitShapeRow {
    /// The training shape's index.
    pub shape_index: i64,
    /// Little-endian f32 latent.
    pub latent: Vec<u8>,
    /// Reconstruction Chamfer distance (unit-ball coordinates).
    pub chamfer: f64,
    /// Transform centre x.
    pub centre_x: f64,
    /// Transform centre y.
    pub centre_y: f64,
    /// Transform centre z.
    pub centre_z: f64,
    /// Transform scale.
    pub radius: f64,
}

impl RefitShapeRow {
    /// The latent values.
    pub fn latent_values(&self) -> Vec<f32> {
        super::latent_values(&self.latent)
    }

    /// The unit-ball transform of the fitted shape.
    pub fn transform(&self) -> UnitBallTransform {
        UnitBallTransform {
            centre: [self.centre_x, self.centre_y, self.centre_z],
            radius: self.radius,
        }
    }
}

/// The model's refit, if one was requested.
pub async fn get<'e>(
    pool: impl super::Executor<'e>,
    model_id: &str,
) -> sqlx::Result<Option<RefitRow>> {
    sqlx::query_as(
        "select model_id, job_id, iterations, seed, created_at from model_refit
         where model_id = $1",
    )
    .bind(model_id)
    .fetch_optional(pool)
    .await
}

/// Records a model's refit with its first job (inside the submitting transaction).
pub async fn insert(
    conn: &mut super::Conn,
    model_id: &str,
    job_id: i64,
    iterations: i64,
    seed: i64,
) -> sqlx::Result<()> {
    sqlx::query(
        "insert into model_refit (model_id, job_id, iterations, seed) values ($1, $2, $3, $4)",
    )
    .bind(model_id)
    .bind(job_id)
    .bind(iterations)
    .bind(seed)
    .execute(conn)
    .await?;
    Ok(())
}

/// Hands the refit to a new job (a retry of one that failed or was cancelled).
pub async fn set_job(conn: &mut super::Conn, model_id: &str, job_id: i64) -> sqlx::Result<()> {
    sqlx::query("update model_refit set job_id = $1 where model_id = $2")
        .bind(job_id)
        .bind(model_id)
        .execute(conn)
        .await?;
    Ok(())
}

/// Stores training shape `shape_index`'s fit (inside its task's transaction); a second
/// store of the same shape keeps the first.
pub async fn insert_shape(
    conn: &mut super::Conn,
    model_id: &str,
    shape_index: i64,
    fitted: &FittedAnchor,
) -> sqlx::Result<()> {
    let blob = super::latent_blob(&fitted.latent);
    sqlx::query(
        "insert into refit_shape (model_id, shape_index, latent, chamfer, centre_x, centre_y,
             centre_z, radius)
         values ($1, $2, $3, $4, $5, $6, $7, $8)
         on conflict (model_id, shape_index) do nothing",
    )
    .bind(model_id)
    .bind(shape_index)
    .bind(blob)
    .bind(fitted.chamfer)
    .bind(fitted.transform.centre[0])
    .bind(fitted.transform.centre[1])
    .bind(fitted.transform.centre[2])
    .bind(fitted.transform.radius)
    .execute(conn)
    .await?;
    Ok(())
}

/// The model's re-fitted shapes so far, by index.
pub async fn shapes<'e>(
    pool: impl super::Executor<'e>,
    model_id: &str,
) -> sqlx::Result<Vec<RefitShapeRow>> {
    sqlx::query_as(
        "select shape_index, latent, chamfer, centre_x, centre_y, centre_z, radius
         from refit_shape where model_id = $1 order by shape_index",
    )
    .bind(model_id)
    .fetch_all(pool)
    .await
}

/// How many of the model's training shapes are re-fitted.
pub async fn shape_count<'e>(pool: impl super::Executor<'e>, model_id: &str) -> sqlx::Result<i64> {
    sqlx::query_scalar("select count(*) from refit_shape where model_id = $1")
        .bind(model_id)
        .fetch_one(pool)
        .await
}

/// The re-fitted latents and transforms of all `count` training shapes in index order, or
/// none while any is missing.
pub async fn latents(
    pool: &super::Pool,
    model_id: &str,
    count: usize,
) -> sqlx::Result<Option<RefittedLatents>> {
    let rows = shapes(pool, model_id).await?;
    let complete = rows.len() == count
        && rows
            .iter()
            .enumerate()
            .all(|(i, r)| r.shape_index == i as i64);
    Ok(complete.then(|| {
        rows.iter()
            .map(|r| (r.latent_values(), r.transform()))
            .unzip()
    }))
}
