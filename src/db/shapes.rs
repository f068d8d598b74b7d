//! The `shape` table: generated shapes with provenance, measures and the stored mesh.

use super::Json;

use crate::anatomy::shape::ShapeAnatomy;
use crate::cohort::Selection;

/// A shape to commit (with its mesh blob) in the job's per-shape transaction.
#[derive(Debug, Clone)]
pub struct NewShape<'a> {
    /// Owning cohort.
    pub cohort_id: i64,
    /// Position within the cohort.
    pub shape_index: i64,
    /// Training shapes mixed.
    pub training_indices: &'a [usize],
    /// Their weights.
    pub weights: &'a [f64],
    /// Per-shape seed.
    pub seed: i64,
    /// Marching-cubes resolution.
    pub resolution: i64,
    /// Crate version that generated it.
    pub software_version: &'a str,
    /// Vertex count.
    pub vertex_count: i64,
    /// Triangle count.
    pub triangle_count: i64,
    /// Surface area in mm².
    pub area_mm2: f64,
    /// Enclosed volume in mm³.
    pub volume_mm3: f64,
    /// Unit-ball → mm centre.
    pub centre: [f64; 3],
    /// Unit-ball → mm scale.
    pub radius: f64,
    /// Hex SHA-256 of the encoded unit-ball mesh, stored in the object store beforehand.
    pub mesh_sha256: &'a str,
    /// Latent noise it was drawn with.
    pub latent_noise: f64,
    /// Selection strategy it was drawn with.
    pub selection: Selection,
    /// Which draw was kept.
    pub attempt: i64,
    /// Draws rejected as too close to a training shape.
    pub redraws: i64,
    /// Chamfer distance to the nearest training shape.
    pub novelty_cd: Option<f64>,
    /// Index of that training shape.
    pub nearest_training_index: Option<i64>,
    /// Whether the cohort's min_novelty is met (true when there is none).
    pub novelty_met: Option<bool>,
    /// Anatomical measurements, when they succeeded.
    pub anatomy: Option<&'a ShapeAnatomy>,
    /// Why the measurements failed.
    pub anatomy_error: Option<&'a str>,
    /// Candidates drawn (targeted cohorts).
    pub candidates: Option<i64>,
    /// Whether the kept shape meets every target (targeted cohorts).
    pub targets_met: Option<bool>,
}

/// A shape's metadata (everything but the mesh bytes).
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct ShapeRow {
    /// Primary key.
    pub shape_id: i64,
    /// Owning cohort.
    pub cohort_id: i64,
    /// Model of the owning cohort.
    pub model_id: String,
    /// Position within the cohort.
    pub shape_index: i64,
    /// Training indices mixed.
    pub training_indices: Json<Vec<usize>>,
    /// Their weights, then the anchors'.
    pub weights: Json<Vec<f64>>,
    /// Per-shape seed.
    pub seed: i64,
    /// Resolution.
    pub resolution: i64,
    /// Generating crate version.
    pub software_version: String,
    /// Vertex count.
    pub vertex_count: i64,
    /// Triangle count.
    pub triangle_count: i64,
    /// Area in mm².
    pub area_mm2: f64,
    /// Volume in mm³.
    pub volume_mm3: f64,
    /// Transform centre x.
    pub centre_x: f64,
    /// Transform centre y.
    pub centre_y: f64,
    /// Transform centre z.
    pub centre_z: f64,
    /// Transform scale.
    pub radius: f64,
    /// Hex SHA-256 of the stored mesh.
    pub mesh_sha256: String,
    /// Latent noise it was drawn with.
    pub latent_noise: f64,
    /// Selection strategy it was drawn with.
    pub selection: Selection,
    /// Which draw was kept.
    pub attempt: i64,
    /// Draws rejected as too close to a training shape.
    pub redraws: i64,
    /// Chamfer distance to the nearest training shape.
    pub novelty_cd: Option<f64>,
    /// Index of that training shape.
    pub nearest_training_index: Option<i64>,
    /// Whether the cohort's min_novelty is met.
    pub novelty_met: Option<super::Flag>,
    /// Anatomical measurements.
    pub anatomy: Option<Json<ShapeAnatomy>>,
    /// Why the measurements failed.
    pub anatomy_error: Option<String>,
    /// Candidates drawn (targeted cohorts).
    pub candidates: Option<i64>,
    /// Whether the kept shape meets every target (targeted cohorts).
    pub targets_met: Option<super::Flag>,
    /// Commit time.
    pub created_at: String,
    /// Anchors mixed (ids from `shape_anchor`, in mixture order), if any.
    pub anchor_ids: Option<Json<Vec<i64>>>,
    /// Their names, in the same order.
    pub anchor_names: Option<Json<Vec<String>>>,
    /// The owning cohort's seed.
    pub cohort_seed: i64,
    /// The owning cohort's density sampler, if any (its defaults filled in).
    pub sampler: Option<Json<crate::cohort::SamplerFields>>,
}

/// Where a shape's mesh is and the transform to mm.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct MeshRef {
    /// Shape id.
    pub shape_id: i64,
    /// Hex SHA-256 of the encoded unit-ball mesh: its name in the object store.
    pub mesh_sha256: String,
    /// Transform centre x.
    pub centre_x: f64,
    /// Transform centre y.
    pub centre_y: f64,
    /// Transform centre z.
    pub centre_z: f64,
    /// Transform scale.
    pub radius: f64,
}

const SELECT: &str = "select s.shape_id, s.cohort_id, c.model_id, s.shape_index,
        s.training_indices, s.weights, s.seed, s.resolution, s.software_version,
        s.vertex_count, s.triangle_count, s.area_mm2, s.volume_mm3,
        s.centre_x, s.centre_y, s.centre_z, s.radius, s.mesh_sha256, s.latent_noise,
        s.selection, s.attempt, s.redraws, s.novelty_cd, s.nearest_training_index,
        s.novelty_met, s.anatomy, s.anatomy_error, s.candidates, s.targets_met, s.created_at,
        (select json_group_array(a.anchor_id order by a.position) from shape_anchor a
            where a.shape_id = s.shape_id having count(*) > 0) as anchor_ids,
        (select json_group_array(n.name order by a.position) from shape_anchor a
            join anchor n on n.anchor_id = a.anchor_id
            where a.shape_id = s.shape_id having count(*) > 0) as anchor_names,
        c.seed as cohort_seed, c.sampler
    from shape s join cohort c on c.cohort_id = s.cohort_id";

/// Inserts a shape inside the caller's transaction.
pub async fn insert(conn: &mut super::Conn, s: &NewShape<'_>) -> sqlx::Result<i64> {
    let shape_id = super::ids::allocate(&mut *conn, super::ids::IdKind::Shape).await?;
    sqlx::query_scalar(
        "insert into shape (shape_id, cohort_id, shape_index, training_indices, weights, seed, resolution,
             software_version, vertex_count, triangle_count, area_mm2, volume_mm3,
             centre_x, centre_y, centre_z, radius, mesh_sha256, latent_noise, selection,
             attempt, redraws, novelty_cd, nearest_training_index, novelty_met, anatomy,
             anatomy_error, candidates, targets_met)
         values ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16, $17, $18,
             $19, $20, $21, $22, $23, $24, $25, $26, $27, $28)
         returning shape_id",
    )
    .bind(shape_id)
    .bind(s.cohort_id)
    .bind(s.shape_index)
    .bind(Json(s.training_indices))
    .bind(Json(s.weights))
    .bind(s.seed)
    .bind(s.resolution)
    .bind(s.software_version)
    .bind(s.vertex_count)
    .bind(s.triangle_count)
    .bind(s.area_mm2)
    .bind(s.volume_mm3)
    .bind(s.centre[0])
    .bind(s.centre[1])
    .bind(s.centre[2])
    .bind(s.radius)
    .bind(s.mesh_sha256)
    .bind(s.latent_noise)
    .bind(s.selection)
    .bind(s.attempt)
    .bind(s.redraws)
    .bind(super::NullableDouble(s.novelty_cd))
    .bind(s.nearest_training_index)
    .bind(s.novelty_met.map(super::Flag))
    .bind(s.anatomy.map(Json))
    .bind(s.anatomy_error)
    .bind(s.candidates)
    .bind(s.targets_met.map(super::Flag))
    .fetch_one(conn)
    .await
}

/// Shape indices already committed for a cohort (a resumed job skips them).
pub async fn existing_indices(pool: &super::Pool, cohort_id: i64) -> sqlx::Result<Vec<i64>> {
    sqlx::query_scalar("select shape_index from shape where cohort_id = $1 order by shape_index")
        .bind(cohort_id)
        .fetch_all(pool)
        .await
}

/// A page of a cohort's shapes in index order.
pub async fn list_for_cohort(
    pool: &super::Pool,
    cohort_id: i64,
    limit: i64,
    offset: i64,
) -> sqlx::Result<Vec<ShapeRow>> {
    let sql = sqlx::AssertSqlSafe(format!(
        "{SELECT} where s.cohort_id = $1 order by s.shape_index limit $2 offset $3"
    ));
    sqlx::query_as(sql)
        .bind(cohort_id)
        .bind(limit)
        .bind(offset)
        .fetch_all(pool)
        .await
}

/// One shape's metadata.
pub async fn get(pool: &super::Pool, shape_id: i64) -> sqlx::Result<Option<ShapeRow>> {
    let sql = sqlx::AssertSqlSafe(format!("{SELECT} where s.shape_id = $1"));
    sqlx::query_as(sql)
        .bind(shape_id)
        .fetch_optional(pool)
        .await
}

/// One shape's mesh name and transform.
pub async fn get_mesh(pool: &super::Pool, shape_id: i64) -> sqlx::Result<Option<MeshRef>> {
    sqlx::query_as(
        "select shape_id, mesh_sha256, centre_x, centre_y, centre_z, radius
         from shape where shape_id = $1",
    )
    .bind(shape_id)
    .fetch_optional(pool)
    .await
}

/// A shape's mesh reference with its index in the cohort.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct IndexedMeshRef {
    /// Index of the shape in its cohort.
    pub shape_index: i64,
    /// Its mesh.
    #[sqlx(flatten)]
    pub mesh: MeshRef,
}

/// All of a cohort's mesh names and transforms in index order (for the pairwise metrics).
pub async fn cohort_meshes(
    pool: &super::Pool,
    cohort_id: i64,
) -> sqlx::Result<Vec<IndexedMeshRef>> {
    sqlx::query_as(
        "select shape_index, shape_id, mesh_sha256, centre_x, centre_y, centre_z, radius
         from shape where cohort_id = $1 order by shape_index",
    )
    .bind(cohort_id)
    .fetch_all(pool)
    .await
}

/// A cohort's shape ids in index order (the rows of its pairwise matrix), without
/// reading their meshes.
pub async fn cohort_shape_ids(pool: &super::Pool, cohort_id: i64) -> sqlx::Result<Vec<i64>> {
    sqlx::query_scalar("select shape_id from shape where cohort_id = $1 order by shape_index")
        .bind(cohort_id)
        .fetch_all(pool)
        .await
}

/// Mean, min and max of area and volume over a cohort's shapes.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct MeasureSummary {
    /// Shapes counted.
    pub n: i64,
    /// Mean area (mm²).
    pub area_mean: Option<f64>,
    /// Smallest area.
    pub area_min: Option<f64>,
    /// Largest area.
    pub area_max: Option<f64>,
    /// Mean volume (mm³).
    pub volume_mean: Option<f64>,
    /// Smallest volume.
    pub volume_min: Option<f64>,
    /// Largest volume.
    pub volume_max: Option<f64>,
}

/// Summary of the cohort's committed shapes.
pub async fn measure_summary(pool: &super::Pool, cohort_id: i64) -> sqlx::Result<MeasureSummary> {
    sqlx::query_as(
        "select count(*) as n, avg(area_mm2) as area_mean, min(area_mm2) as area_min,
             max(area_mm2) as area_max, avg(volume_mm3) as volume_mean,
             min(volume_mm3) as volume_min, max(volume_mm3) as volume_max
         from shape where cohort_id = $1",
    )
    .bind(cohort_id)
    .fetch_one(pool)
    .await
}

/// A shape's novelty and anatomy, for the cohort's science summaries.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct ScienceRow {
    /// Shape id.
    pub shape_id: i64,
    /// Chamfer distance to the nearest training shape.
    pub novelty_cd: Option<f64>,
    /// Index of that training shape.
    pub nearest_training_index: Option<i64>,
    /// Whether the cohort's min_novelty is met.
    pub novelty_met: Option<super::Flag>,
    /// Draws rejected as too close to a training shape.
    pub redraws: i64,
    /// Anatomical measurements.
    pub anatomy: Option<Json<ShapeAnatomy>>,
    /// Candidates drawn (targeted cohorts).
    pub candidates: Option<i64>,
    /// Whether the kept shape meets every target (targeted cohorts).
    pub targets_met: Option<super::Flag>,
}

/// Novelty and anatomy of a cohort's shapes in index order.
pub async fn cohort_science(pool: &super::Pool, cohort_id: i64) -> sqlx::Result<Vec<ScienceRow>> {
    sqlx::query_as(
        "select shape_id, novelty_cd, nearest_training_index, novelty_met, redraws, anatomy,
             candidates, targets_met
         from shape where cohort_id = $1 order by shape_index",
    )
    .bind(cohort_id)
    .fetch_all(pool)
    .await
}

/// Shapes stored for a cohort.
pub async fn count_for_cohort<'e>(
    ex: impl super::Executor<'e>,
    cohort_id: i64,
) -> sqlx::Result<i64> {
    sqlx::query_scalar("select count(*) from shape where cohort_id = $1")
        .bind(cohort_id)
        .fetch_one(ex)
        .await
}

/// Total shapes stored (for /metrics).
pub async fn count_all(pool: &super::Pool) -> sqlx::Result<i64> {
    sqlx::query_scalar("select count(*) from shape")
        .fetch_one(pool)
        .await
}

/// A stored shape's measurements and where its mesh is, for measuring it again.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct MeasuredShape {
    /// Where its mesh is (and its id).
    #[sqlx(flatten)]
    pub mesh: MeshRef,
    /// Anatomical measurements (none when they failed).
    pub anatomy: Option<Json<ShapeAnatomy>>,
}

/// Up to `limit` shapes with ids above `after`, in id order, with their measurements.
pub async fn measurements_after(
    pool: &super::Pool,
    after: i64,
    limit: i64,
) -> sqlx::Result<Vec<MeasuredShape>> {
    sqlx::query_as(
        "select shape_id, mesh_sha256, centre_x, centre_y, centre_z, radius, anatomy
         from shape where shape_id > $1 order by shape_id limit $2",
    )
    .bind(after)
    .bind(limit)
    .fetch_all(pool)
    .await
}

/// Replaces a shape's measurements, or the reason they failed; false when the shape is gone.
pub async fn set_anatomy<'e>(
    ex: impl super::Executor<'e>,
    shape_id: i64,
    anatomy: Result<&ShapeAnatomy, &str>,
) -> sqlx::Result<bool> {
    let done = sqlx::query("update shape set anatomy = $1, anatomy_error = $2 where shape_id = $3")
        .bind(anatomy.ok().map(Json))
        .bind(anatomy.err())
        .bind(shape_id)
        .execute(ex)
        .await?;
    Ok(done.rows_affected() == 1)
}
