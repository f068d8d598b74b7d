//! Where the service's immutable objects live: generated meshes and model bundles, named by
//! the SHA-256 of their bytes. `AORTAGEN_BLOB_STORE=db` (the default) keeps them in the
//! database's `blob` table, `file:///dir` in a directory and `s3://bucket/prefix` in an
//! S3-compatible bucket ([`external`]). The rows that name them (a shape's `mesh_sha256`, a
//! model's `digest`) are written after them, and objects no row names are swept after a
//! grace period. Every read checks the bytes against their name, so a corrupt or tampered
//! object is refused, never served.

pub mod bundle;
pub mod external;

use std::collections::HashSet;

use anyhow::Context;

pub use external::{BlobStoreUrl, ExternalStore, StoreUnavailable};

use crate::db::{self, shapes::MeshRef};
use crate::digest::sha256_hex;
use crate::geometry::normalize::UnitBallTransform;

/// A shape's mesh bytes with the row that names them.
#[derive(Debug, Clone)]
pub struct StoredMesh {
    /// The shape's row: id, mesh name, transform to mm.
    pub row: MeshRef,
    /// The encoded unit-ball mesh.
    pub mesh: Vec<u8>,
}

impl StoredMesh {
    /// The unit ball → mm transform.
    pub fn transform(&self) -> UnitBallTransform {
        UnitBallTransform {
            centre: [self.row.centre_x, self.row.centre_y, self.row.centre_z],
            radius: self.row.radius,
        }
    }
}

/// The object store of a deployment.
#[derive(Clone)]
pub enum Objects {
    /// The database's `blob` table.
    Database(db::Pool),
    /// A directory or an S3-compatible bucket.
    External(ExternalStore),
}

/// Why an object could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ObjectError {
    /// The stored bytes do not hash to the object's name.
    #[error("object {0} is corrupt: its bytes do not match its SHA-256")]
    Corrupt(String),
    /// The store refused.
    #[error(transparent)]
    Store(#[from] anyhow::Error),
}

impl Objects {
    /// The store `url` names, beside the database `pool`.
    pub fn open(url: &BlobStoreUrl, pool: &db::Pool) -> anyhow::Result<Self> {
        Ok(match url {
            BlobStoreUrl::Database => Self::Database(pool.clone()),
            other => Self::External(ExternalStore::open(other)?),
        })
    }

    /// Stores `bytes` (a no-op when the object exists) and returns its name.
    pub async fn put(&self, bytes: &[u8]) -> anyhow::Result<String> {
        let sha = sha256_hex(bytes);
        match self {
            Self::Database(pool) => db::blobs::put(pool, &sha, bytes)
                .await
                .context("cannot store an object")?,
            Self::External(store) => store
                .put(&sha, bytes::Bytes::copy_from_slice(bytes))
                .await
                .context("cannot store an object")?,
        }
        Ok(sha)
    }

    /// The bytes of object `sha256`, checked against its name; None when it does not exist.
    pub async fn get(&self, sha256: &str) -> Result<Option<Vec<u8>>, ObjectError> {
        let bytes = match self {
            Self::Database(pool) => db::blobs::get(pool, sha256)
                .await
                .context("cannot read an object")?,
            Self::External(store) => store
                .get(sha256)
                .await
                .context("cannot read an object")?
                .map(Vec::from),
        };
        match bytes {
            Some(b) if sha256_hex(&b) != sha256 => Err(ObjectError::Corrupt(sha256.to_owned())),
            other => Ok(other),
        }
    }

    /// The bytes of object `sha256`, which a row names: its absence is an error.
    pub async fn require(&self, sha256: &str) -> anyhow::Result<Vec<u8>> {
        self.get(sha256)
            .await?
            .with_context(|| format!("object {sha256} is missing from the store"))
    }

    /// A shape's mesh: its row's transform and the object it names; None when there is no
    /// such shape.
    pub async fn shape_mesh(
        &self,
        pool: &db::Pool,
        shape_id: i64,
    ) -> anyhow::Result<Option<StoredMesh>> {
        let Some(row) = db::shapes::get_mesh(pool, shape_id).await? else {
            return Ok(None);
        };
        Ok(Some(self.load(row).await?))
    }

    /// The mesh a row names, with the row's transform.
    pub async fn load(&self, row: MeshRef) -> anyhow::Result<StoredMesh> {
        let mesh = self
            .require(&row.mesh_sha256)
            .await
            .with_context(|| format!("the mesh of shape {}", row.shape_id))?;
        Ok(StoredMesh { row, mesh })
    }

    /// Deletes objects no row names that are older than `grace`; returns how many.
    pub async fn sweep(&self, pool: &db::Pool, grace: std::time::Duration) -> anyhow::Result<u64> {
        let before = rfc3339_ago(grace);
        match self {
            Self::Database(_) => Ok(db::blobs::sweep_unreferenced(pool, &before).await?),
            Self::External(store) => {
                // Names listed before the store is: an object written after this read has
                // a row younger than the grace period, or none yet, and is spared.
                let keep: HashSet<String> =
                    db::blobs::referenced(pool).await?.into_iter().collect();
                Ok(store.sweep(&keep, grace).await?)
            }
        }
    }
}

/// The UTC time `ago` before now, as the database's timestamps write it.
fn rfc3339_ago(ago: std::time::Duration) -> String {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    let t = now.saturating_sub(ago);
    let (secs, millis) = (t.as_secs() as i64, t.subsec_millis());
    let days = secs.div_euclid(86_400);
    let rem = secs.rem_euclid(86_400);
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{millis:03}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// The proleptic Gregorian date of a day count since 1970-01-01 (H. Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn day_counts_become_calendar_dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(19_723), (2024, 1, 1));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        assert_eq!(civil_from_days(20_792), (2026, 12, 5));
        assert_eq!(civil_from_days(-1), (1969, 12, 31));
    }
}
