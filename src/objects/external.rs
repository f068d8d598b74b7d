//! Objects outside the database: a directory (`file:///dir`) or an S3-compatible bucket
//! (`s3://bucket/prefix`), through the `object_store` crate. Keys are content addresses,
//! `<prefix>/sha256/<first two hex digits>/<sha256>`, so a write of an existing object
//! writes the same bytes and concurrent writers cannot disagree.

use std::collections::HashSet;
use std::fmt;
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use bytes::Bytes;
use futures_util::TryStreamExt;
use object_store::path::Path as Key;
use object_store::{ObjectStore, ObjectStoreExt, PutPayload};

/// Where a deployment keeps its objects (`AORTAGEN_BLOB_STORE`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BlobStoreUrl {
    /// `db`: the database's `blob` table (the default).
    Database,
    /// `file:///dir`: a local or mounted directory.
    Directory(std::path::PathBuf),
    /// `s3://bucket/prefix`: an S3-compatible bucket, configured by the usual `AWS_*`
    /// variables (`AWS_ENDPOINT_URL`, `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`,
    /// `AWS_REGION`, `AWS_ALLOW_HTTP`).
    S3 {
        /// The bucket.
        bucket: String,
        /// The key prefix inside it (may be empty).
        prefix: String,
    },
}

impl FromStr for BlobStoreUrl {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim();
        if s == "db" {
            return Ok(Self::Database);
        }
        if let Some(path) = s.strip_prefix("file://") {
            if !path.starts_with('/') {
                return Err(format!(
                    "`{s}`: a file store needs an absolute path, as in file:///var/lib/aortagen/objects"
                ));
            }
            return Ok(Self::Directory(path.into()));
        }
        if let Some(rest) = s.strip_prefix("s3://") {
            let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
            if bucket.is_empty() {
                return Err(format!(
                    "`{s}`: an S3 store names its bucket, as in s3://bucket/prefix"
                ));
            }
            return Ok(Self::S3 {
                bucket: bucket.to_owned(),
                prefix: prefix.trim_matches('/').to_owned(),
            });
        }
        Err(format!(
            "`{s}` is not a blob store: use db, file:///DIR or s3://BUCKET/PREFIX"
        ))
    }
}

impl fmt::Display for BlobStoreUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Database => f.write_str("db"),
            Self::Directory(dir) => write!(f, "file://{}", dir.display()),
            Self::S3 { bucket, prefix } if prefix.is_empty() => write!(f, "s3://{bucket}"),
            Self::S3 { bucket, prefix } => write!(f, "s3://{bucket}/{prefix}"),
        }
    }
}

pub use crate::db::ObjectStoreFault as StoreUnavailable;

/// A directory or bucket holding content-addressed objects.
#[derive(Clone)]
pub struct ExternalStore {
    store: Arc<dyn ObjectStore>,
    prefix: String,
    url: BlobStoreUrl,
}

impl fmt::Debug for ExternalStore {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ExternalStore({})", self.url)
    }
}

impl ExternalStore {
    /// Opens the store `url` names (`db` is not external: an error).
    pub fn open(url: &BlobStoreUrl) -> anyhow::Result<Self> {
        let (store, prefix): (Arc<dyn ObjectStore>, String) = match url {
            BlobStoreUrl::Database => anyhow::bail!("the database is not an external store"),
            BlobStoreUrl::Directory(dir) => {
                std::fs::create_dir_all(dir).with_context(|| {
                    format!("cannot create the object directory {}", dir.display())
                })?;
                let store = object_store::local::LocalFileSystem::new_with_prefix(dir)
                    .with_context(|| {
                        format!("cannot open the object directory {}", dir.display())
                    })?;
                (Arc::new(store), String::new())
            }
            BlobStoreUrl::S3 { bucket, prefix } => {
                let store = object_store::aws::AmazonS3Builder::from_env()
                    .with_bucket_name(bucket)
                    .build()
                    .with_context(|| format!("cannot configure the S3 store {url}"))?;
                (Arc::new(store), prefix.clone())
            }
        };
        Ok(Self {
            store,
            prefix,
            url: url.clone(),
        })
    }

    /// The store's URL.
    pub fn url(&self) -> &BlobStoreUrl {
        &self.url
    }

    fn key(&self, sha256: &str) -> Key {
        let fan = sha256.get(..2).unwrap_or("__");
        if self.prefix.is_empty() {
            Key::from(format!("sha256/{fan}/{sha256}"))
        } else {
            Key::from(format!("{}/sha256/{fan}/{sha256}", self.prefix))
        }
    }

    fn objects_root(&self) -> Key {
        if self.prefix.is_empty() {
            Key::from("sha256")
        } else {
            Key::from(format!("{}/sha256", self.prefix))
        }
    }

    fn unavailable(&self, source: object_store::Error) -> StoreUnavailable {
        StoreUnavailable {
            store: self.url.to_string(),
            source: Box::new(source),
        }
    }

    /// Writes object `sha256` unless it is there already.
    pub async fn put(&self, sha256: &str, bytes: Bytes) -> Result<(), StoreUnavailable> {
        let key = self.key(sha256);
        match self.store.head(&key).await {
            Ok(_) => return Ok(()),
            Err(object_store::Error::NotFound { .. }) => {}
            Err(e) => return Err(self.unavailable(e)),
        }
        self.store
            .put(&key, PutPayload::from_bytes(bytes))
            .await
            .map(drop)
            .map_err(|e| self.unavailable(e))
    }

    /// The bytes of object `sha256` as stored (unchecked), or None.
    pub async fn get(&self, sha256: &str) -> Result<Option<Bytes>, StoreUnavailable> {
        let got = match self.store.get(&self.key(sha256)).await {
            Ok(got) => got,
            Err(object_store::Error::NotFound { .. }) => return Ok(None),
            Err(e) => return Err(self.unavailable(e)),
        };
        got.bytes().await.map(Some).map_err(|e| self.unavailable(e))
    }

    /// Deletes the objects not in `keep` last written more than `grace` ago; returns how
    /// many. The grace period spares objects whose rows are still being written.
    pub async fn sweep(
        &self,
        keep: &HashSet<String>,
        grace: Duration,
    ) -> Result<u64, StoreUnavailable> {
        let cutoff = epoch_millis_ago(grace);
        let listed: Vec<object_store::ObjectMeta> = self
            .store
            .list(Some(&self.objects_root()))
            .try_collect()
            .await
            .map_err(|e| self.unavailable(e))?;
        let mut deleted = 0;
        for meta in listed {
            let Some(name) = meta.location.filename() else {
                continue;
            };
            let stale = meta.last_modified.timestamp_millis() < cutoff;
            if stale && !keep.contains(name) {
                match self.store.delete(&meta.location).await {
                    Ok(()) | Err(object_store::Error::NotFound { .. }) => deleted += 1,
                    Err(e) => return Err(self.unavailable(e)),
                }
            }
        }
        Ok(deleted)
    }
}

/// Milliseconds since the epoch `ago` before now.
fn epoch_millis_ago(ago: Duration) -> i64 {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    now.saturating_sub(ago).as_millis() as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn store_urls_parse_and_print_back() {
        for text in [
            "db",
            "file:///var/lib/objects",
            "s3://meshes",
            "s3://meshes/site/a",
        ] {
            let url: BlobStoreUrl = text.parse().unwrap();
            assert_eq!(url.to_string(), text);
        }
        assert_eq!(
            "s3://meshes/site/".parse::<BlobStoreUrl>().unwrap(),
            BlobStoreUrl::S3 {
                bucket: "meshes".into(),
                prefix: "site".into()
            }
        );
    }

    #[test]
    fn malformed_store_urls_say_what_is_expected() {
        let relative = "file://objects".parse::<BlobStoreUrl>().unwrap_err();
        assert!(relative.contains("absolute path"), "{relative}");
        let bucketless = "s3:///prefix".parse::<BlobStoreUrl>().unwrap_err();
        assert!(bucketless.contains("names its bucket"), "{bucketless}");
        let unknown = "gs://bucket".parse::<BlobStoreUrl>().unwrap_err();
        assert!(unknown.contains("db, file:///DIR or s3://"), "{unknown}");
    }

    #[tokio::test]
    async fn a_directory_store_keeps_puts_reads_them_back_and_sweeps_only_stale_orphans() {
        let dir = tempfile::tempdir().unwrap();
        let store = ExternalStore::open(&BlobStoreUrl::Directory(dir.path().into())).unwrap();
        let (a, b) = ("a".repeat(64), "b".repeat(64));
        store.put(&a, Bytes::from_static(b"first")).await.unwrap();
        store.put(&b, Bytes::from_static(b"second")).await.unwrap();
        // A second write of an existing object keeps it.
        store.put(&a, Bytes::from_static(b"first")).await.unwrap();
        assert_eq!(store.get(&a).await.unwrap().unwrap(), &b"first"[..]);
        assert!(store.get(&"c".repeat(64)).await.unwrap().is_none());
        assert!(dir.path().join("sha256/aa").join(&a).is_file());

        let keep = HashSet::from([a.clone()]);
        // Within the grace period nothing goes.
        assert_eq!(
            store.sweep(&keep, Duration::from_secs(3600)).await.unwrap(),
            0
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
        assert_eq!(store.sweep(&keep, Duration::ZERO).await.unwrap(), 1);
        assert!(store.get(&a).await.unwrap().is_some());
        assert!(store.get(&b).await.unwrap().is_none());
    }
}
