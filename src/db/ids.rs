//! Ids that are never reused. Taking one above the largest id present would hand a deleted
//! newest job, cohort, shape or anchor's id, and the URLs built on it, to the next one: a
//! client or cache holding the old resource (meshes are served as immutable) would then be
//! served another's. Every id is taken from `id_high_water`, whose mark per resource only
//! goes up, inside the inserting transaction.

/// A resource whose ids are allocated here.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IdKind {
    /// `job.job_id`.
    Job,
    /// `cohort.cohort_id`.
    Cohort,
    /// `shape.shape_id`.
    Shape,
    /// `anchor.anchor_id`.
    Anchor,
    /// `reference_population.reference_id`.
    Reference,
    /// `validation.validation_id`.
    Validation,
}

/// The allocating statement for one table: one above both the mark and the table's largest
/// id (so a row inserted with an explicit id can never be handed out twice either).
macro_rules! allocate_sql {
    ($resource:literal, $table:literal, $column:literal) => {
        concat!(
            "insert into id_high_water (resource, last_id) values ('",
            $resource,
            "', (select coalesce(max(",
            $column,
            "), 0) + 1 from ",
            $table,
            ")) on conflict (resource) do update set last_id =
                 case when id_high_water.last_id + 1 > excluded.last_id
                      then id_high_water.last_id + 1 else excluded.last_id end
             returning last_id"
        )
    };
}

impl IdKind {
    fn allocate_sql(self) -> &'static str {
        match self {
            Self::Job => allocate_sql!("job", "job", "job_id"),
            Self::Cohort => allocate_sql!("cohort", "cohort", "cohort_id"),
            Self::Shape => allocate_sql!("shape", "shape", "shape_id"),
            Self::Anchor => allocate_sql!("anchor", "anchor", "anchor_id"),
            Self::Reference => {
                allocate_sql!("reference", "reference_population", "reference_id")
            }
            Self::Validation => allocate_sql!("validation", "validation", "validation_id"),
        }
    }
}

/// A new id for `kind`, never handed out before. Call it inside the write transaction that
/// inserts the row: a rollback returns the id with everything else.
pub async fn allocate(conn: &mut super::Conn, kind: IdKind) -> sqlx::Result<i64> {
    sqlx::query_scalar(kind.allocate_sql())
        .fetch_one(conn)
        .await
}
