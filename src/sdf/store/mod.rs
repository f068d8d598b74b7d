//! Saving and loading a model directory (see [`crate::sdf::store::manifest`] for the layout).
//!
//! Weights and Adam state use burn's burnpack format, which also stores each parameter's id:
//! Adam's state is keyed by parameter id, so a resumed run finds its moments again. Files are
//! written to temporary names and renamed, the manifest last, so an interrupted save leaves
//! the previous checkpoint readable. Loading never panics on bad files: every problem is a
//! [`ModelLoadError`] that names the file and the rule it breaks.

pub mod anchors;
pub mod manifest;
pub mod refits;
pub mod sidecar;

use std::path::{Path, PathBuf};

use burn::optim::ModuleOptimizer;
use burn::store::{BurnpackStore, ModuleSnapshot};
use burn::tensor::{Bytes, Device};

use crate::sdf::backend::{Backend, BackendError};
use crate::sdf::inference::field::{FieldError, SdfField};
use crate::sdf::model::decoder::SdfAutoDecoder;
use crate::sdf::model::network::NetworkConfigError;
use crate::sdf::store::manifest::{
    FileRecord, MANIFEST_FILE, MANIFEST_FORMAT, MANIFEST_VERSION, ModelManifest, OPTIMIZER_FILE,
    WEIGHTS_FILE,
};

/// Why a model directory cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ModelLoadError {
    /// A file the model needs does not exist.
    #[error("model file {path} is missing")]
    MissingFile {
        /// The missing file.
        path: PathBuf,
    },
    /// A file exists but cannot be read.
    #[error("cannot read model file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        source: std::io::Error,
    },
    /// The manifest is not an aortagen model manifest (other JSON, or not JSON at all).
    #[error("{path} is not an aortagen model manifest: {reason}")]
    NotAManifest {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// Written by a newer (or unknown) manifest layout.
    #[error("{path} has manifest format version {found}; this build reads version {supported}")]
    UnsupportedVersion {
        /// The file.
        path: PathBuf,
        /// Version in the file.
        found: u32,
        /// Version this build reads.
        supported: u32,
    },
    /// A file's bytes do not match the manifest (truncated, damaged or replaced).
    #[error("model file {path} is corrupted: {reason}")]
    Corrupted {
        /// The file.
        path: PathBuf,
        /// Which check failed.
        reason: String,
    },
    /// The stored tensors do not fit the architecture the manifest describes.
    #[error("weights in {path} do not match the manifest's architecture: {detail}")]
    ArchitectureMismatch {
        /// The weights file.
        path: PathBuf,
        /// Which tensors differ.
        detail: String,
    },
    /// The manifest's architecture itself is invalid.
    #[error("the manifest describes an invalid network: {0}")]
    InvalidArchitecture(#[from] NetworkConfigError),
    /// The requested backend is unavailable.
    #[error(transparent)]
    Backend(#[from] BackendError),
}

/// A trained model ready for inference: manifest plus network and latents on a plain device.
#[derive(Debug)]
pub struct LoadedModel {
    /// The model directory.
    pub dir: PathBuf,
    /// Its manifest (already checked).
    pub manifest: ModelManifest,
    /// Network and latent table.
    pub decoder: SdfAutoDecoder,
}

impl LoadedModel {
    /// Loads `dir` on `backend` without autodiff, checking every file (see [`ModelLoadError`]).
    pub fn load(dir: &Path, backend: Backend) -> Result<Self, ModelLoadError> {
        let manifest = read_manifest(dir)?;
        let device = backend.device(false)?;
        let decoder = load_decoder(dir, &manifest, &device)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            manifest,
            decoder,
        })
    }

    /// Number of training shapes (latent rows).
    pub fn num_shapes(&self) -> usize {
        self.decoder.num_shapes()
    }

    /// All latents on the host, one row per training shape.
    pub fn latents(&self) -> Vec<Vec<f32>> {
        self.decoder.latents_to_vec()
    }

    /// The signed-distance field of an arbitrary latent (for example a mixture).
    pub fn field(&self, latent: &[f32]) -> Result<SdfField, FieldError> {
        SdfField::new(&self.decoder.network, latent)
    }
}

/// Reads and checks `dir/manifest.json` (format marker and version).
pub fn read_manifest(dir: &Path) -> Result<ModelManifest, ModelLoadError> {
    let path = dir.join(MANIFEST_FILE);
    let bytes = read_file(&path)?;
    let not_manifest = |reason: String| ModelLoadError::NotAManifest {
        path: path.clone(),
        reason,
    };
    let value: serde_json::Value =
        serde_json::from_slice(&bytes).map_err(|e| not_manifest(format!("not JSON ({e})")))?;
    if value.get("format").and_then(|f| f.as_str()) != Some(MANIFEST_FORMAT) {
        return Err(not_manifest(format!(
            "its \"format\" field is not \"{MANIFEST_FORMAT}\""
        )));
    }
    let found = value.get("format_version").and_then(|v| v.as_u64());
    let found = found.ok_or_else(|| not_manifest("no numeric \"format_version\"".into()))?;
    if found != u64::from(MANIFEST_VERSION) {
        return Err(ModelLoadError::UnsupportedVersion {
            path: path.clone(),
            found: u32::try_from(found).unwrap_or(u32::MAX),
            supported: MANIFEST_VERSION,
        });
    }
    serde_json::from_value(value).map_err(|e| not_manifest(format!("invalid field: {e}")))
}

/// Loads the network and latents the manifest describes onto `device`.
pub fn load_decoder(
    dir: &Path,
    manifest: &ModelManifest,
    device: &Device,
) -> Result<SdfAutoDecoder, ModelLoadError> {
    let path = dir.join(&manifest.weights.file);
    let bytes = read_checked(&path, &manifest.weights)?;
    let shapes = manifest.shapes.len();
    let mut decoder = SdfAutoDecoder::new(&manifest.architecture, shapes.max(1), 0, device)?;
    let mut store = BurnpackStore::from_bytes(Some(Bytes::from_bytes_vec(bytes)))
        .validate(false)
        .allow_partial(true);
    let result = decoder
        .load_from(&mut store)
        .map_err(|e| ModelLoadError::Corrupted {
            path: path.clone(),
            reason: format!("unreadable burnpack: {e}"),
        })?;
    let mut problems: Vec<String> = result.errors.iter().map(ToString::to_string).collect();
    problems.extend(
        result
            .missing
            .iter()
            .map(|(p, _)| format!("missing tensor {p}")),
    );
    problems.extend(
        result
            .unused
            .iter()
            .map(|p| format!("unexpected tensor {p}")),
    );
    if !problems.is_empty() {
        return Err(ModelLoadError::ArchitectureMismatch {
            path,
            detail: problems.join("; "),
        });
    }
    Ok(decoder)
}

/// Loads the saved Adam state into `fresh` (an optimizer built like the saved one), for
/// `--resume`.
pub fn load_optimizer(
    dir: &Path,
    manifest: &ModelManifest,
    fresh: ModuleOptimizer,
) -> Result<ModuleOptimizer, ModelLoadError> {
    let record = manifest
        .optimizer
        .as_ref()
        .ok_or(ModelLoadError::MissingFile {
            path: dir.join(OPTIMIZER_FILE),
        })?;
    let path = dir.join(&record.file);
    let bytes = read_checked(&path, record)?;
    fresh
        .from_bytes(Bytes::from_bytes_vec(bytes))
        .map_err(|e| ModelLoadError::Corrupted {
            path,
            reason: format!("unreadable optimizer state: {e}"),
        })
}

/// Writes weights (and optimizer state), then `manifest` with their hashes. Updates
/// `manifest.weights` / `manifest.optimizer` in place.
pub fn save_model(
    dir: &Path,
    manifest: &mut ModelManifest,
    decoder: &SdfAutoDecoder,
    optimizer: Option<&ModuleOptimizer>,
) -> anyhow::Result<()> {
    use anyhow::Context;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut store = BurnpackStore::from_bytes(None);
    decoder
        .save_into(&mut store)
        .map_err(|e| anyhow::anyhow!("cannot serialise the weights: {e}"))?;
    let weights = store
        .get_bytes()
        .map_err(|e| anyhow::anyhow!("cannot serialise the weights: {e}"))?;
    let weights_tmp = write_temp(dir, WEIGHTS_FILE, &weights)?;
    manifest.weights = file_record(WEIGHTS_FILE, &weights);
    let optimizer_tmp = match optimizer {
        Some(o) => {
            let bytes = o
                .into_bytes()
                .map_err(|e| anyhow::anyhow!("cannot serialise the optimizer state: {e}"))?;
            manifest.optimizer = Some(file_record(OPTIMIZER_FILE, &bytes));
            Some(write_temp(dir, OPTIMIZER_FILE, &bytes)?)
        }
        None => {
            manifest.optimizer = None;
            None
        }
    };
    let json = serde_json::to_vec_pretty(manifest)?;
    let manifest_tmp = write_temp(dir, MANIFEST_FILE, &json)?;
    rename(&weights_tmp, &dir.join(WEIGHTS_FILE))?;
    match optimizer_tmp {
        Some(tmp) => rename(&tmp, &dir.join(OPTIMIZER_FILE))?,
        None => {
            let _ = std::fs::remove_file(dir.join(OPTIMIZER_FILE));
        }
    }
    rename(&manifest_tmp, &dir.join(MANIFEST_FILE))
}

/// Name, SHA-256 and length of a file's bytes.
pub fn file_record(file: &str, bytes: &[u8]) -> FileRecord {
    FileRecord {
        file: file.to_string(),
        sha256: crate::digest::sha256_hex(bytes),
        bytes: bytes.len() as u64,
    }
}

fn read_file(path: &Path) -> Result<Vec<u8>, ModelLoadError> {
    std::fs::read(path).map_err(|source| match source.kind() {
        std::io::ErrorKind::NotFound => ModelLoadError::MissingFile {
            path: path.to_path_buf(),
        },
        _ => ModelLoadError::Io {
            path: path.to_path_buf(),
            source,
        },
    })
}

/// Reads a file and checks its length and SHA-256 against the manifest.
fn read_checked(path: &Path, record: &FileRecord) -> Result<Vec<u8>, ModelLoadError> {
    let bytes = read_file(path)?;
    let corrupted = |reason| ModelLoadError::Corrupted {
        path: path.to_path_buf(),
        reason,
    };
    if bytes.len() as u64 != record.bytes {
        return Err(corrupted(format!(
            "{} bytes, the manifest records {} (truncated or replaced)",
            bytes.len(),
            record.bytes
        )));
    }
    let found = crate::digest::sha256_hex(&bytes);
    if found != record.sha256 {
        return Err(corrupted(format!(
            "SHA-256 {found} differs from the manifest's {}",
            record.sha256
        )));
    }
    Ok(bytes)
}

fn write_temp(dir: &Path, name: &str, bytes: &[u8]) -> anyhow::Result<PathBuf> {
    use anyhow::Context;
    let tmp = dir.join(format!(".{name}.tmp"));
    std::fs::write(&tmp, bytes).with_context(|| format!("cannot write {}", tmp.display()))?;
    Ok(tmp)
}

fn rename(from: &Path, to: &Path) -> anyhow::Result<()> {
    use anyhow::Context;
    std::fs::rename(from, to).with_context(|| format!("cannot write {}", to.display()))
}
