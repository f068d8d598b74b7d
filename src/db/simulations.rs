//! The `shape_simulation` table: a shape's simulation mesh per set of options (the capped
//! labelled surface with its summary), or why none could be made, kept so the pipeline
//! runs once per shape and options.

/// What the pipeline gave for one shape and set of options.
#[derive(Debug, Clone, PartialEq)]
pub enum SimulationOutcome {
    /// The stored surface: mesh blob, face-id blob, summary JSON.
    Ready {
        /// Mesh blob of the capped surface.
        mesh: Vec<u8>,
        /// Face id per triangle, `u32` little endian.
        face_ids: Vec<u8>,
        /// Summary JSON.
        summary: String,
    },
    /// No simulation mesh: why, and the parameter to change when one is to blame.
    Failed {
        /// The sentence.
        error: String,
        /// The parameter (`openings` when the shape itself is at fault).
        field: String,
    },
}

/// A row as read: the outcome with what it was made from.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationRow {
    /// The outcome.
    pub outcome: SimulationOutcome,
    /// SHA-256 of the shape mesh it was made from.
    pub mesh_sha256: String,
    /// Software version that made it.
    pub software_version: String,
    /// Seconds the pipeline took.
    pub seconds: f64,
}

#[derive(sqlx::FromRow)]
struct RawRow {
    mesh: Option<Vec<u8>>,
    face_ids: Option<Vec<u8>>,
    summary: Option<String>,
    error: Option<String>,
    error_field: Option<String>,
    mesh_sha256: String,
    software_version: String,
    seconds: f64,
}

impl RawRow {
    fn into_row(self) -> SimulationRow {
        let outcome = match (self.mesh, self.face_ids, self.summary) {
            (Some(mesh), Some(face_ids), Some(summary)) => SimulationOutcome::Ready {
                mesh,
                face_ids,
                summary,
            },
            // The schema's check keeps a row either complete or failed.
            _ => SimulationOutcome::Failed {
                error: self.error.unwrap_or_default(),
                field: self.error_field.unwrap_or_else(|| "openings".into()),
            },
        };
        SimulationRow {
            outcome,
            mesh_sha256: self.mesh_sha256,
            software_version: self.software_version,
            seconds: self.seconds,
        }
    }
}

/// The stored outcome for a shape and options, whatever it was made from.
pub async fn get(
    pool: &super::Pool,
    shape_id: i64,
    options: &str,
) -> sqlx::Result<Option<SimulationRow>> {
    let raw: Option<RawRow> = sqlx::query_as(
        "select mesh, face_ids, summary, error, error_field, mesh_sha256, software_version,
             seconds
         from shape_simulation where shape_id = $1 and options = $2",
    )
    .bind(shape_id)
    .bind(options)
    .fetch_optional(pool)
    .await?;
    Ok(raw.map(RawRow::into_row))
}

/// Stores (or replaces) the outcome for a shape and options.
pub async fn put(
    pool: &super::Pool,
    shape_id: i64,
    options: &str,
    row: &SimulationRow,
) -> sqlx::Result<()> {
    let (mesh, face_ids, summary, error, field) = match &row.outcome {
        SimulationOutcome::Ready {
            mesh,
            face_ids,
            summary,
        } => (Some(mesh), Some(face_ids), Some(summary), None, None),
        SimulationOutcome::Failed { error, field } => (None, None, None, Some(error), Some(field)),
    };
    sqlx::query(
        "insert into shape_simulation (shape_id, options, mesh_sha256, software_version, mesh,
             face_ids, summary, error, error_field, seconds)
         values ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10)
         on conflict (shape_id, options) do update set mesh_sha256 = excluded.mesh_sha256,
             software_version = excluded.software_version, mesh = excluded.mesh,
             face_ids = excluded.face_ids, summary = excluded.summary, error = excluded.error,
             error_field = excluded.error_field, seconds = excluded.seconds,
             created_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')",
    )
    .bind(shape_id)
    .bind(options)
    .bind(&row.mesh_sha256)
    .bind(&row.software_version)
    .bind(mesh)
    .bind(face_ids)
    .bind(summary)
    .bind(error)
    .bind(field)
    .bind(row.seconds)
    .execute(pool)
    .await?;
    Ok(())
}

/// Rows stored (for /metrics and tests).
pub async fn count(pool: &super::Pool) -> sqlx::Result<i64> {
    sqlx::query_scalar("select count(*) from shape_simulation")
        .fetch_one(pool)
        .await
}
