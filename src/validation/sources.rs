//! Populations read from files, as the command line gives them: a directory written by
//! `aortagen generate` (meshes with their `shape_NNNN.json` records), a directory of real
//! meshes in mm, a measurements table, and a model directory's training and held-out shapes
//! (read again from the data its manifest records).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use super::population::{Population, StoredShape};
use super::table::parse_table;
use crate::cohort::ShapeRecord;
use crate::sdf::data::holdout::load_split;
use crate::sdf::data::{DataSource, MESH_EXTENSIONS, read_mesh_directory};
use crate::sdf::store::manifest::ModelManifest;
use crate::sdf::store::read_manifest;

/// A generated cohort read from a directory.
#[derive(Debug, Clone)]
pub struct CohortFiles {
    /// Its shapes, in file-name order.
    pub population: Population,
    /// The first shape's record (provenance), when the directory has records.
    pub first_record: Option<ShapeRecord>,
}

/// Reads a directory of generated shapes: with `shape_NNNN.json` records, each mesh is
/// brought to mm by its record's transform and keeps the record's measurements (measured
/// again when an earlier method made them); without records, every mesh is taken in mm and
/// measured.
pub fn read_cohort_dir(dir: &Path) -> anyhow::Result<CohortFiles> {
    let label = format!("cohort {}", dir.display());
    let mut records: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    records.sort();
    if records.is_empty() {
        let meshes = read_mesh_directory(dir)?;
        return Ok(CohortFiles {
            population: Population::from_meshes(label, meshes),
            first_record: None,
        });
    }
    let mut shapes = Vec::with_capacity(records.len());
    let mut first_record = None;
    for path in &records {
        let record: ShapeRecord = serde_json::from_slice(&std::fs::read(path)?)
            .with_context(|| format!("{} is not a shape record", path.display()))?;
        let mesh = crate::formats::read_mesh_file(&mesh_beside(path)?)?;
        let mesh_mm = match record.units.as_str() {
            "unit" => record.transform.mesh_to_mesh_units(&mesh),
            _ => mesh,
        };
        shapes.push(StoredShape {
            name: path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            surface_mm: mesh_mm,
            anatomy: record.anatomy.clone(),
            area_mm2: record.area_mm2,
            volume_mm3: record.volume_mm3,
        });
        first_record.get_or_insert(record);
    }
    Ok(CohortFiles {
        population: Population::from_stored(label, shapes),
        first_record,
    })
}

/// The mesh file with the same stem as a record.
fn mesh_beside(record: &Path) -> anyhow::Result<PathBuf> {
    MESH_EXTENSIONS
        .iter()
        .map(|ext| record.with_extension(ext))
        .find(|p| p.is_file())
        .with_context(|| format!("no mesh file beside {}", record.display()))
}

/// A reference read from a path: a measurements table (`.csv`) or a directory of meshes.
#[derive(Debug, Clone)]
pub struct ReferenceFiles {
    /// The population.
    pub population: Population,
    /// Table columns accepted but not compared, with the reason.
    pub ignored: Vec<(String, String)>,
    /// SHA-256 of the data (the table, or the meshes' bytes in file-name order).
    pub sha256: String,
    /// `measurements` or `meshes`.
    pub kind: &'static str,
}

/// Reads a reference from `path`.
pub fn read_reference_path(path: &Path) -> anyhow::Result<ReferenceFiles> {
    let label = format!("reference {}", path.display());
    if path.is_file() {
        let bytes =
            std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        let text = String::from_utf8(bytes.clone()).context("the table is not UTF-8 text")?;
        let table =
            parse_table(&label, &text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        return Ok(ReferenceFiles {
            population: table.population,
            ignored: table.ignored,
            sha256: crate::digest::sha256_hex(&bytes),
            kind: "measurements",
        });
    }
    let meshes = read_mesh_directory(path)?;
    if meshes.len() < 2 {
        bail!(
            "a reference needs at least 2 meshes, {} has {}",
            path.display(),
            meshes.len()
        );
    }
    let sha256 = meshes_sha256(&meshes);
    Ok(ReferenceFiles {
        population: Population::from_meshes(label, meshes),
        ignored: Vec::new(),
        sha256,
        kind: "meshes",
    })
}

/// SHA-256 over the meshes' names and canonical encodings, in order.
pub fn meshes_sha256(meshes: &[(String, crate::geometry::TriMesh)]) -> String {
    let mut bytes = Vec::new();
    for (name, mesh) in meshes {
        bytes.extend_from_slice(name.as_bytes());
        bytes.extend_from_slice(&crate::formats::mesh_blob::encode(mesh));
    }
    crate::digest::sha256_hex(&bytes)
}

/// The model's mean training radius in mm: the common scale of its shape-level distances.
pub fn mean_training_radius(manifest: &ModelManifest) -> f64 {
    let t = manifest.transforms();
    t.iter().map(|t| t.radius).sum::<f64>() / t.len().max(1) as f64
}

/// A model's own populations.
#[derive(Debug, Clone)]
pub struct ModelPopulations {
    /// Its manifest.
    pub manifest: ModelManifest,
    /// The training shapes (real meshes, mm).
    pub training: Population,
    /// The held-out shapes, when the model was trained with a holdout.
    pub heldout: Option<Population>,
}

/// The training and held-out shapes of the model in `model_dir`, read from its recorded
/// data (or from `data`, a directory holding the same files).
pub fn model_populations(
    model_dir: &Path,
    data: Option<&Path>,
) -> anyhow::Result<ModelPopulations> {
    let manifest = read_manifest(model_dir)?;
    let source = match data {
        Some(path) => DataSource::Directory {
            path: path.to_path_buf(),
        },
        None => manifest.data.source.clone(),
    };
    let split = load_split(&source, manifest.data.holdout.as_ref())?;
    let heldout = (!split.heldout.is_empty())
        .then(|| Population::from_meshes("the held-out shapes", split.heldout));
    Ok(ModelPopulations {
        training: Population::from_meshes("the training shapes", split.training),
        heldout,
        manifest,
    })
}
