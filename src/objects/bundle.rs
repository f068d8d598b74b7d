//! Model bundles: a model directory's files as one object, so a worker on any machine can
//! fetch a model by its digest instead of sharing a file system with the process that
//! trained or registered it.
//!
//! A bundle is `aortagen-model-bundle/1\n` followed, for each regular top-level file in
//! name order (hidden files and subdirectories such as the training input left out), by
//! the name's length (u32, little-endian), the name, the content's length (u64) and the
//! content. The same files always give the same bytes, hence the same digest.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use anyhow::{Context, bail, ensure};

use super::Objects;
use crate::db::models::ModelRow;

const MAGIC: &[u8] = b"aortagen-model-bundle/1\n";

/// The files of `dir` that make up the model, in name order.
fn model_files(dir: &Path) -> anyhow::Result<Vec<(String, PathBuf)>> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))? {
        let entry = entry?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if entry.file_type()?.is_file() && !name.starts_with('.') {
            files.push((name, entry.path()));
        }
    }
    files.sort();
    Ok(files)
}

/// The bundle of the model in `dir`.
pub fn pack(dir: &Path) -> anyhow::Result<Vec<u8>> {
    let mut files = Vec::new();
    for (name, path) in model_files(dir)? {
        let bytes =
            std::fs::read(&path).with_context(|| format!("cannot read {}", path.display()))?;
        files.push((name, bytes));
    }
    Ok(pack_files(&files))
}

/// The bundle of named files (sorted here, so any order gives the same bytes).
pub fn pack_files<B: AsRef<[u8]>>(files: &[(String, B)]) -> Vec<u8> {
    let mut sorted: Vec<&(String, B)> = files.iter().collect();
    sorted.sort_by(|a, b| a.0.cmp(&b.0));
    let mut out = MAGIC.to_vec();
    for (name, bytes) in sorted {
        let bytes = bytes.as_ref();
        out.extend_from_slice(&(name.len() as u32).to_le_bytes());
        out.extend_from_slice(name.as_bytes());
        out.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
        out.extend_from_slice(bytes);
    }
    out
}

/// The files of a bundle, refusing anything malformed (truncated, unsafe names).
pub fn files(bundle: &[u8]) -> anyhow::Result<Vec<(String, &[u8])>> {
    let mut rest = bundle
        .strip_prefix(MAGIC)
        .context("not a model bundle (wrong header)")?;
    fn take<'a>(rest: &mut &'a [u8], n: usize) -> anyhow::Result<&'a [u8]> {
        ensure!(rest.len() >= n, "the model bundle is truncated");
        let (head, tail) = rest.split_at(n);
        *rest = tail;
        Ok(head)
    }
    let mut out: Vec<(String, &[u8])> = Vec::new();
    while !rest.is_empty() {
        let name_len = u32::from_le_bytes(take(&mut rest, 4)?.try_into()?) as usize;
        let name = std::str::from_utf8(take(&mut rest, name_len)?)
            .context("a file name in the model bundle is not UTF-8")?
            .to_owned();
        let safe = !name.is_empty() && !name.starts_with('.') && !name.contains(['/', '\\', '\0']);
        if !safe {
            bail!("the model bundle names an unsafe file {name:?}");
        }
        let len = u64::from_le_bytes(take(&mut rest, 8)?.try_into()?);
        let content = take(&mut rest, usize::try_from(len)?)?;
        if out.last().is_some_and(|(last, _)| *last >= name) {
            bail!("the model bundle's files are not in name order at {name:?}");
        }
        out.push((name, content));
    }
    Ok(out)
}

/// Writes a bundle's files into `dir` (created; it must not hold other files).
pub fn unpack(bundle: &[u8], dir: &Path) -> anyhow::Result<()> {
    let files = files(bundle)?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    for (name, content) in files {
        std::fs::write(dir.join(&name), content)
            .with_context(|| format!("cannot write {}", dir.join(&name).display()))?;
    }
    Ok(())
}

/// Stores the bundle of the model in `dir` and returns its digest; None when `dir` holds
/// no model files (an engine that keeps nothing on disk).
pub async fn publish(objects: &Objects, dir: &Path) -> anyhow::Result<Option<String>> {
    let owned = dir.to_path_buf();
    let bundle = tokio::task::spawn_blocking(move || -> anyhow::Result<Option<Vec<u8>>> {
        if !owned.is_dir() || model_files(&owned)?.is_empty() {
            return Ok(None);
        }
        pack(&owned).map(Some)
    })
    .await??;
    let Some(bundle) = bundle else {
        return Ok(None);
    };
    let digest = objects.put(&bundle).await?;
    remember(&digest, dir);
    Ok(Some(digest))
}

/// Makes sure `dir` holds the files of bundle `digest`, fetching them from the store when
/// this machine lacks the directory (a job's inputs uploaded to another machine's API).
pub async fn ensure_unpacked(objects: &Objects, digest: &str, dir: &Path) -> anyhow::Result<()> {
    if dir.is_dir() {
        return Ok(());
    }
    let bundle = objects.require(digest).await?;
    let target = dir.to_path_buf();
    tokio::task::spawn_blocking(move || place_unpacked(&bundle, &target)).await??;
    tracing::info!(%digest, dir = %dir.display(), "inputs fetched from the object store");
    Ok(())
}

/// Writes the file `sha256` names to `path` unless it exists, fetching it from the store.
pub async fn ensure_file(objects: &Objects, sha256: &str, path: &Path) -> anyhow::Result<()> {
    if path.is_file() {
        return Ok(());
    }
    let bytes = objects.require(sha256).await?;
    let target = path.to_path_buf();
    tokio::task::spawn_blocking(move || -> anyhow::Result<()> {
        if let Some(parent) = target.parent() {
            std::fs::create_dir_all(parent)?;
        }
        let staging = target.with_extension(format!("partial-{}", std::process::id()));
        std::fs::write(&staging, &bytes)?;
        std::fs::rename(&staging, &target)
            .with_context(|| format!("cannot place {}", target.display()))
    })
    .await??;
    tracing::info!(%sha256, path = %path.display(), "input fetched from the object store");
    Ok(())
}

/// Unpacks `bundle` beside `target` and renames it into place, so a reader never sees half
/// of it; a copy another process of this machine placed first is kept.
fn place_unpacked(bundle: &[u8], target: &Path) -> anyhow::Result<()> {
    if let Some(parent) = target.parent() {
        std::fs::create_dir_all(parent)?;
    }
    let staging = target.with_extension(format!("partial-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&staging);
    unpack(bundle, &staging)?;
    match std::fs::rename(&staging, target) {
        Ok(()) => Ok(()),
        Err(_) if target.is_dir() => {
            let _ = std::fs::remove_dir_all(&staging);
            Ok(())
        }
        Err(e) => Err(e).with_context(|| format!("cannot place {}", target.display())),
    }
}

/// Directories of this machine checked to hold the bundle of a digest, as (digest, dir):
/// several directories may hold one model (copies of it registered under other ids).
fn verified() -> &'static Mutex<HashSet<(String, PathBuf)>> {
    static VERIFIED: OnceLock<Mutex<HashSet<(String, PathBuf)>>> = OnceLock::new();
    VERIFIED.get_or_init(Default::default)
}

fn remember(digest: &str, dir: &Path) {
    verified()
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .insert((digest.to_owned(), dir.to_path_buf()));
}

/// Whether `dir` was checked to hold bundle `digest` and is still there.
fn known(digest: &str, dir: &Path) -> bool {
    dir.is_dir()
        && verified()
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .contains(&(digest.to_owned(), dir.to_path_buf()))
}

/// The directory on this machine holding `model`'s files: its registered directory when it
/// is here with the published files, else a copy fetched by digest (checked against it)
/// into `cache_dir/<digest>`. A model without a digest is loaded from where it was
/// registered, as on one machine.
pub async fn local_model_dir(
    objects: &Objects,
    cache_dir: &Path,
    model: &ModelRow,
) -> anyhow::Result<PathBuf> {
    let registered = PathBuf::from(&model.dir_path);
    let Some(digest) = model.digest.clone() else {
        return Ok(registered);
    };
    let cached = cache_dir.join(&digest);
    if let Some(dir) = [&registered, &cached]
        .into_iter()
        .find(|d| known(&digest, d))
    {
        return Ok(dir.clone());
    }
    let (check_digest, check_registered, check_cached) =
        (digest.clone(), registered.clone(), cached.clone());
    let local = tokio::task::spawn_blocking(move || {
        let holds = |dir: &Path| {
            dir.is_dir() && pack(dir).is_ok_and(|b| crate::digest::sha256_hex(&b) == check_digest)
        };
        [check_registered, check_cached]
            .into_iter()
            .find(|d| holds(d))
    })
    .await?;
    if let Some(dir) = local {
        remember(&digest, &dir);
        return Ok(dir);
    }
    let bundle = objects
        .require(&digest)
        .await
        .with_context(|| format!("cannot fetch model {:?}", model.model_id))?;
    let target = cached.clone();
    tokio::task::spawn_blocking(move || place_unpacked(&bundle, &target)).await??;
    tracing::info!(model_id = %model.model_id, %digest, dir = %cached.display(), "model fetched from the object store");
    remember(&digest, &cached);
    Ok(cached)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model_dir() -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("weights.bpk"), [1u8, 2, 3, 250]).unwrap();
        std::fs::write(dir.path().join("manifest.json"), b"{\"a\": 1}").unwrap();
        std::fs::write(dir.path().join(".weights.bpk.tmp"), b"partial").unwrap();
        std::fs::create_dir(dir.path().join("input")).unwrap();
        std::fs::write(dir.path().join("input/0000.ply"), b"ply").unwrap();
        dir
    }

    #[test]
    fn a_bundle_round_trips_the_model_files_and_nothing_else() {
        let from = model_dir();
        let bundle = pack(from.path()).unwrap();
        assert_eq!(bundle, pack(from.path()).unwrap(), "deterministic");
        let names: Vec<String> = files(&bundle).unwrap().into_iter().map(|f| f.0).collect();
        assert_eq!(names, ["manifest.json", "weights.bpk"]);
        let to = tempfile::tempdir().unwrap();
        unpack(&bundle, &to.path().join("m")).unwrap();
        assert_eq!(
            std::fs::read(to.path().join("m/weights.bpk")).unwrap(),
            [1, 2, 3, 250]
        );
        assert_eq!(pack(&to.path().join("m")).unwrap(), bundle);
    }

    #[test]
    fn malformed_bundles_are_refused_with_the_reason() {
        let bundle = pack(model_dir().path()).unwrap();
        let truncated = files(&bundle[..bundle.len() - 1]).unwrap_err();
        assert!(truncated.to_string().contains("truncated"), "{truncated}");
        assert!(files(b"something else").is_err());
        let mut escaping = MAGIC.to_vec();
        escaping.extend_from_slice(&5u32.to_le_bytes());
        escaping.extend_from_slice(b"../x1");
        escaping.extend_from_slice(&0u64.to_le_bytes());
        let unsafe_name = files(&escaping).unwrap_err();
        assert!(unsafe_name.to_string().contains("unsafe"), "{unsafe_name}");
    }

    #[tokio::test]
    async fn a_machine_without_the_files_fetches_the_model_by_digest() {
        let store_dir = tempfile::tempdir().unwrap();
        let url = super::super::BlobStoreUrl::Directory(store_dir.path().into());
        let objects = Objects::External(super::super::ExternalStore::open(&url).unwrap());
        let from = model_dir();
        let digest = publish(&objects, from.path()).await.unwrap().unwrap();
        let row = ModelRow {
            model_id: "m".into(),
            dir_path: "/nonexistent/elsewhere/m".into(),
            manifest: crate::db::Json(None),
            status: crate::db::states::ModelStatus::Ready,
            created_at: String::new(),
            digest: Some(digest.clone()),
        };
        // Not the publisher's directory: this test's digest must not be known here yet.
        verified().lock().unwrap().retain(|(d, _)| *d != digest);
        let cache = tempfile::tempdir().unwrap();
        let dir = local_model_dir(&objects, cache.path(), &row).await.unwrap();
        assert_eq!(dir, cache.path().join(&digest));
        assert_eq!(
            std::fs::read(dir.join("manifest.json")).unwrap(),
            b"{\"a\": 1}"
        );

        // A tampered object is refused, not loaded.
        verified().lock().unwrap().clear();
        std::fs::remove_dir_all(&dir).unwrap();
        let key = store_dir
            .path()
            .join("sha256")
            .join(&digest[..2])
            .join(&digest);
        std::fs::write(&key, b"aortagen-model-bundle/1\n").unwrap();
        let err = local_model_dir(&objects, cache.path(), &row)
            .await
            .unwrap_err();
        assert!(format!("{err:#}").contains("corrupt"), "{err:#}");
    }
}
