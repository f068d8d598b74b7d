//! On-disk cache of a [`PreparedDataset`], so a rerun or a resume does not resample.
//!
//! The file name carries a SHA-256 of everything that determines the samples (the meshes'
//! names, vertices and triangles, the sampling settings and this file layout's version), so a
//! changed input simply misses the cache. The body is little-endian and ends with its own
//! SHA-256: a truncated or damaged cache is detected, reported in the log and rebuilt.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail, ensure};
use sha2::{Digest, Sha256};

use crate::geometry::TriMesh;
use crate::geometry::normalize::UnitBallTransform;
use crate::sdf::data::{PreparedDataset, PreparedShape, SamplingSettings, prepare_shapes};

const MAGIC: &[u8; 8] = b"AGSDFDS\0";
const LAYOUT_VERSION: u32 = 1;

/// Hex SHA-256 of the inputs that determine a prepared dataset.
pub fn dataset_key(meshes: &[(String, TriMesh)], settings: &SamplingSettings) -> String {
    let mut h = Sha256::new();
    h.update(MAGIC);
    h.update(LAYOUT_VERSION.to_le_bytes());
    for v in [
        settings.points_per_shape as u64,
        settings.knn_k as u64,
        settings.seed,
    ] {
        h.update(v.to_le_bytes());
    }
    h.update((meshes.len() as u64).to_le_bytes());
    for (name, mesh) in meshes {
        h.update((name.len() as u64).to_le_bytes());
        h.update(name.as_bytes());
        h.update((mesh.positions.len() as u64).to_le_bytes());
        for p in &mesh.positions {
            p.iter().for_each(|c| h.update(c.to_le_bytes()));
        }
        h.update((mesh.triangles.len() as u64).to_le_bytes());
        for t in &mesh.triangles {
            t.iter().for_each(|c| h.update(c.to_le_bytes()));
        }
    }
    crate::digest::hex(&h.finalize())
}

/// Loads the prepared dataset from `cache_dir` when a valid cache for these inputs exists,
/// otherwise prepares it and writes the cache. Returns the dataset and its key.
pub fn prepare_cached(
    meshes: &[(String, TriMesh)],
    settings: &SamplingSettings,
    cache_dir: Option<&Path>,
) -> anyhow::Result<(PreparedDataset, String)> {
    let key = dataset_key(meshes, settings);
    let path = cache_dir.map(|d| cache_path(d, &key));
    if let Some(path) = path.as_deref().filter(|p| p.exists()) {
        match read_cache(path) {
            Ok(ds) if ds.settings == *settings && ds.shapes.len() == meshes.len() => {
                tracing::info!(path = %path.display(), "using the cached training samples");
                return Ok((ds, key));
            }
            Ok(_) => tracing::warn!(path = %path.display(), "cache does not match; resampling"),
            Err(e) => {
                tracing::warn!(path = %path.display(), error = %e, "unusable cache; resampling")
            }
        }
    }
    let shapes = prepare_shapes(meshes, settings)?;
    let ds = PreparedDataset {
        shapes,
        settings: *settings,
    };
    if let Some(path) = path {
        write_cache(&path, &ds)?;
    }
    Ok((ds, key))
}

/// The cache file of a dataset key inside `dir`.
pub fn cache_path(dir: &Path, key: &str) -> PathBuf {
    dir.join(format!("samples-{}.bin", &key[..16.min(key.len())]))
}

/// Writes the dataset atomically (temporary file, then rename).
pub fn write_cache(path: &Path, ds: &PreparedDataset) -> anyhow::Result<()> {
    let mut body: Vec<u8> = Vec::new();
    body.extend_from_slice(MAGIC);
    body.extend_from_slice(&LAYOUT_VERSION.to_le_bytes());
    let s = &ds.settings;
    for v in [
        s.points_per_shape as u64,
        s.knn_k as u64,
        s.seed,
        ds.shapes.len() as u64,
    ] {
        body.extend_from_slice(&v.to_le_bytes());
    }
    for shape in &ds.shapes {
        body.extend_from_slice(&(shape.name.len() as u64).to_le_bytes());
        body.extend_from_slice(shape.name.as_bytes());
        let t = &shape.transform;
        for v in [t.centre[0], t.centre[1], t.centre[2], t.radius] {
            body.extend_from_slice(&v.to_le_bytes());
        }
        body.extend_from_slice(&(shape.points.len() as u64).to_le_bytes());
        for v in shape.points.iter().chain(&shape.normals).flatten() {
            body.extend_from_slice(&v.to_le_bytes());
        }
        for v in &shape.sigma {
            body.extend_from_slice(&v.to_le_bytes());
        }
    }
    let digest = Sha256::digest(&body);
    let tmp = path.with_extension("bin.tmp");
    let mut file = std::fs::File::create(&tmp)
        .with_context(|| format!("cannot write the sample cache {}", tmp.display()))?;
    file.write_all(&body)?;
    file.write_all(&digest)?;
    file.sync_all()?;
    std::fs::rename(&tmp, path)
        .with_context(|| format!("cannot move the sample cache to {}", path.display()))?;
    Ok(())
}

/// Reads a cache file written by [`write_cache`], checking its layout and checksum.
pub fn read_cache(path: &Path) -> anyhow::Result<PreparedDataset> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    ensure!(bytes.len() >= MAGIC.len() + 32, "file too short");
    let (body, digest) = bytes.split_at(bytes.len() - 32);
    ensure!(
        Sha256::digest(body).as_slice() == digest,
        "checksum mismatch"
    );
    let mut r = Reader { bytes: body, at: 0 };
    ensure!(r.take(MAGIC.len())? == MAGIC, "not a sample cache");
    let version = u32::from_le_bytes(r.array()?);
    ensure!(version == LAYOUT_VERSION, "layout version {version}");
    let settings = SamplingSettings {
        points_per_shape: r.u64()? as usize,
        knn_k: r.u64()? as usize,
        seed: r.u64()?,
    };
    let count = r.u64()? as usize;
    let mut shapes = Vec::with_capacity(count.min(1 << 16));
    for _ in 0..count {
        let len = r.u64()? as usize;
        let name = String::from_utf8(r.take(len)?.to_vec()).context("shape name")?;
        let [cx, cy, cz, radius] = [r.f64()?, r.f64()?, r.f64()?, r.f64()?];
        let n = r.u64()? as usize;
        let points = r.vec3s(n)?;
        let normals = r.vec3s(n)?;
        let sigma = (0..n).map(|_| r.f32()).collect::<anyhow::Result<_>>()?;
        shapes.push(PreparedShape {
            name,
            transform: UnitBallTransform {
                centre: [cx, cy, cz],
                radius,
            },
            points,
            normals,
            sigma,
        });
    }
    if r.at != body.len() {
        bail!("trailing bytes");
    }
    Ok(PreparedDataset { shapes, settings })
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> anyhow::Result<&[u8]> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.context("unexpected end of file")?;
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }
    fn array<const N: usize>(&mut self) -> anyhow::Result<[u8; N]> {
        Ok(self.take(N)?.try_into().expect("length checked"))
    }
    fn u64(&mut self) -> anyhow::Result<u64> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    fn f64(&mut self) -> anyhow::Result<f64> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    fn f32(&mut self) -> anyhow::Result<f32> {
        Ok(f32::from_le_bytes(self.array()?))
    }
    fn vec3s(&mut self, n: usize) -> anyhow::Result<Vec<[f32; 3]>> {
        (0..n)
            .map(|_| Ok([self.f32()?, self.f32()?, self.f32()?]))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetrahedron(scale: f32) -> TriMesh {
        let p = [
            [1.0, 1.0, 1.0],
            [1.0, -1.0, -1.0],
            [-1.0, 1.0, -1.0],
            [-1.0, -1.0, 1.0],
        ];
        let positions = p.iter().map(|v: &[f32; 3]| v.map(|c| c * scale)).collect();
        TriMesh::new(positions, vec![[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])
    }

    fn inputs() -> (Vec<(String, TriMesh)>, SamplingSettings) {
        let meshes = vec![
            ("a".into(), tetrahedron(2.0)),
            ("b".into(), tetrahedron(5.0)),
        ];
        let settings = SamplingSettings {
            points_per_shape: 300,
            knn_k: 10,
            seed: 3,
        };
        (meshes, settings)
    }

    #[test]
    fn the_cache_round_trips_and_is_reused() {
        let dir = tempfile::tempdir().unwrap();
        let (meshes, settings) = inputs();
        let (first, key) = prepare_cached(&meshes, &settings, Some(dir.path())).unwrap();
        let path = cache_path(dir.path(), &key);
        assert_eq!(read_cache(&path).unwrap(), first);
        // A second call reads the file: prove it by planting a recognisable (valid) change.
        let mut planted = first.clone();
        planted.shapes[0].sigma[0] = 123.0;
        write_cache(&path, &planted).unwrap();
        let (again, _) = prepare_cached(&meshes, &settings, Some(dir.path())).unwrap();
        assert_eq!(again.shapes[0].sigma[0], 123.0);
        assert!((first.shapes[1].transform.radius - 5.0 * 3f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn any_input_change_changes_the_key() {
        let (meshes, settings) = inputs();
        let key = dataset_key(&meshes, &settings);
        let mut other = settings;
        other.seed += 1;
        assert_ne!(key, dataset_key(&meshes, &other));
        let mut moved = meshes.clone();
        moved[1].1.positions[0][0] += 1e-3;
        assert_ne!(key, dataset_key(&moved, &settings));
        let mut renamed = meshes.clone();
        renamed[0].0 = "c".into();
        assert_ne!(key, dataset_key(&renamed, &settings));
    }

    #[test]
    fn damaged_caches_are_rejected_and_rebuilt() {
        let dir = tempfile::tempdir().unwrap();
        let (meshes, settings) = inputs();
        let (first, key) = prepare_cached(&meshes, &settings, Some(dir.path())).unwrap();
        let path = cache_path(dir.path(), &key);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[100] ^= 0x40;
        std::fs::write(&path, &bytes).unwrap();
        assert!(
            read_cache(&path)
                .unwrap_err()
                .to_string()
                .contains("checksum")
        );
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
        assert!(read_cache(&path).is_err());
        let (rebuilt, _) = prepare_cached(&meshes, &settings, Some(dir.path())).unwrap();
        assert_eq!(rebuilt, first);
        assert_eq!(read_cache(&path).unwrap(), first);
    }
}
