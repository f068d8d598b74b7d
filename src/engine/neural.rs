//! The science engine behind the service: trained SDF models, fast surface extraction and
//! Chamfer metrics, exposed through [`Engine`] so the job worker calls the very library
//! code the command line uses.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use anyhow::{Context, bail};
use rayon::prelude::*;

use super::cache::{BoundedCache, DirStamp};
use super::{
    Engine, FitSpec, FittedAnchor, GeneratedShape, ModelInfo, RefitSpec, ShapeSpec,
    TrainingShapeInfo, TrainingSpec,
};
use crate::geometry::TriMesh;
use crate::geometry::chamfer::{ChamferIndex, DEFAULT_CHAMFER_POINTS, chamfer_between_serial};
use crate::geometry::sampling::sample_surface;
use crate::sdf::backend::Backend;
use crate::sdf::data::DataSource;
use crate::sdf::data::holdout::{HoldoutSpec, load_split};
use crate::sdf::inference::evaluation::EvaluationReport;
use crate::sdf::inference::mixing::{AnchorPart, Mixture, anchored_latent};
use crate::sdf::inference::novelty::{NoveltyReference, training_surface, training_surfaces};
use crate::sdf::inference::reconstruct::{ExtractionMethod, reconstruct};
use crate::sdf::store::LoadedModel;
use crate::sdf::store::manifest::MANIFEST_FILE;
use crate::sdf::store::refits::{RefitSet, RefittedLatents};
use crate::sdf::training::config::Preset;
use crate::sdf::training::fit::{FitSettings, fit_mesh};
use crate::sdf::training::refit::refit_settings;
use crate::sdf::training::{TrainingObserver, TrainingRequest, train};

/// File in a model directory holding `aortagen evaluate --json` output; when present, its
/// per-shape reconstruction Chamfer distances are reported with the model.
pub const EVALUATION_FILE: &str = "evaluation.json";

/// A loaded model with its latents on the host, shared by all workers.
struct CachedModel {
    model: LoadedModel,
    latents: Vec<Vec<f32>>,
}

/// The [`Engine`] backed by trained neural SDF models.
pub struct SdfEngine {
    backend: Backend,
    extraction: ExtractionMethod,
    chamfer_points: usize,
    /// Loaded models by directory and content, so each shape does not reload the weights.
    models: Mutex<BoundedCache<ModelKey, Arc<Mutex<CachedModel>>>>,
    /// Training surfaces for novelty, by model directory, content and resolution.
    references: Mutex<BoundedCache<ReferenceKey, Arc<NoveltyReference>>>,
    /// The training meshes of the model last re-fitted, so a refit's tasks read its data
    /// once, not once per shape.
    training_meshes: Mutex<Option<(ModelKey, NamedMeshes)>>,
}

/// Models kept loaded at once (each holds its weights and latents).
const CACHED_MODELS: usize = 8;

/// Novelty references kept at once (each holds the training surfaces' samples and trees:
/// tens of MB at 30 000 points and 80 shapes).
const CACHED_REFERENCES: usize = 8;

/// A model directory and what it holds.
type ModelKey = (PathBuf, DirStamp);

/// A model's training meshes with their names, in training order.
type NamedMeshes = Arc<Vec<(String, TriMesh)>>;

/// A model directory, what it holds, and a resolution.
type ReferenceKey = (PathBuf, DirStamp, usize);

/// The cache key of a model directory's novelty reference at `resolution`.
fn reference_key(dir: &Path, resolution: usize) -> anyhow::Result<ReferenceKey> {
    let stamp =
        DirStamp::of(dir).with_context(|| format!("cannot read the model in {}", dir.display()))?;
    Ok((dir.to_path_buf(), stamp, resolution))
}

impl SdfEngine {
    /// An engine computing on `backend` with the fast extraction and 30 000-point Chamfer.
    pub fn new(backend: Backend) -> Self {
        Self {
            backend,
            extraction: ExtractionMethod::Fast,
            chamfer_points: DEFAULT_CHAMFER_POINTS,
            models: Mutex::new(BoundedCache::new(CACHED_MODELS)),
            references: Mutex::new(BoundedCache::new(CACHED_REFERENCES)),
            training_meshes: Mutex::new(None),
        }
    }

    /// Extracts surfaces with `extraction` (fast by default; both give the same mesh).
    pub fn with_extraction(mut self, extraction: ExtractionMethod) -> Self {
        self.extraction = extraction;
        self
    }

    /// Uses `points` surface samples per shape for the cohort's pairwise Chamfer distances
    /// and the novelty against the training shapes.
    pub fn with_chamfer_points(mut self, points: usize) -> Self {
        self.chamfer_points = points.max(1);
        self
    }

    fn model(&self, dir: &Path) -> anyhow::Result<Arc<Mutex<CachedModel>>> {
        let mut models = self
            .models
            .lock()
            .map_err(|_| anyhow::anyhow!("model cache poisoned"))?;
        let key = (
            dir.to_path_buf(),
            DirStamp::of(dir)
                .with_context(|| format!("cannot read the model in {}", dir.display()))?,
        );
        if let Some(model) = models.get(&key) {
            return Ok(model);
        }
        let model = LoadedModel::load(dir, self.backend)
            .with_context(|| format!("cannot load the model in {}", dir.display()))?;
        let latents = model.latents();
        let cached = Arc::new(Mutex::new(CachedModel { model, latents }));
        models.insert(key, cached.clone());
        Ok(cached)
    }
}

impl Engine for SdfEngine {
    fn model_info(&self, model_dir: &Path) -> anyhow::Result<ModelInfo> {
        let cached = self.model(model_dir)?;
        let cached = cached
            .lock()
            .map_err(|_| anyhow::anyhow!("model poisoned"))?;
        let manifest = &cached.model.manifest;
        let fidelity = read_reconstruction_cds(model_dir);
        let training_shapes = manifest
            .shapes
            .iter()
            .enumerate()
            .map(|(index, shape)| TrainingShapeInfo {
                index,
                name: shape.name.clone(),
                reconstruction_cd: fidelity.get(index).copied().flatten(),
            })
            .collect();
        let refitted_latents = match RefitSet::load(model_dir, manifest) {
            Ok(set) => set.is_complete(manifest),
            Err(e) => {
                tracing::warn!(error = %e, "the re-fitted latents are not usable");
                false
            }
        };
        Ok(ModelInfo {
            latent_dim: manifest.architecture.latent_dim,
            architecture: serde_json::to_value(&manifest.architecture)?,
            training_shapes,
            refitted_latents,
        })
    }

    fn refitted_latents(&self, model_dir: &Path) -> anyhow::Result<Option<RefittedLatents>> {
        let cached = self.model(model_dir)?;
        let cached = cached
            .lock()
            .map_err(|_| anyhow::anyhow!("model poisoned"))?;
        let manifest = &cached.model.manifest;
        Ok(RefitSet::load(model_dir, manifest)?.latents(manifest))
    }

    fn training_latents(&self, model_dir: &Path) -> anyhow::Result<Vec<Vec<f32>>> {
        let cached = self.model(model_dir)?;
        let cached = cached
            .lock()
            .map_err(|_| anyhow::anyhow!("model poisoned"))?;
        Ok(cached.latents.clone())
    }

    fn training_transforms(
        &self,
        model_dir: &Path,
    ) -> anyhow::Result<Vec<crate::geometry::normalize::UnitBallTransform>> {
        let cached = self.model(model_dir)?;
        let cached = cached
            .lock()
            .map_err(|_| anyhow::anyhow!("model poisoned"))?;
        Ok(cached.model.manifest.transforms())
    }

    fn generate_shape(
        &self,
        model_dir: &Path,
        spec: &ShapeSpec,
        cancel: &AtomicBool,
    ) -> anyhow::Result<GeneratedShape> {
        if cancel.load(Ordering::Relaxed) {
            bail!("cancelled");
        }
        let cached = self.model(model_dir)?;
        let cached = cached
            .lock()
            .map_err(|_| anyhow::anyhow!("model poisoned"))?;
        let shapes = cached.latents.len();
        if let Some(&bad) = spec.training_indices.iter().find(|&&i| i >= shapes) {
            bail!("training index {bad} is out of range: the model has {shapes} shapes");
        }
        let (transform, latent) =
            mixed_latent(spec, &cached.latents, &cached.model.manifest.transforms())?;
        let field = cached.model.field(&latent)?;
        let extraction = reconstruct(&field, spec.resolution, self.extraction)?;
        let mesh_unit = extraction.mesh;
        let mesh_mm = transform.mesh_to_mesh_units(&mesh_unit);
        Ok(GeneratedShape {
            area_mm2: mesh_mm.area(),
            volume_mm3: mesh_mm.signed_volume(),
            mesh_unit,
            transform,
        })
    }

    fn novelty_reference(
        &self,
        model_dir: &Path,
        resolution: usize,
        cancel: &AtomicBool,
    ) -> anyhow::Result<Arc<NoveltyReference>> {
        let key = reference_key(model_dir, resolution)?;
        let cached = self.model(model_dir)?;
        // Held while extracting, so concurrent jobs on one model build the reference once.
        let cached = cached
            .lock()
            .map_err(|_| anyhow::anyhow!("model poisoned"))?;
        let lock_references = || {
            self.references
                .lock()
                .map_err(|_| anyhow::anyhow!("reference cache poisoned"))
        };
        if let Some(reference) = lock_references()?.get(&key) {
            return Ok(reference);
        }
        let surfaces = training_surfaces(
            &cached.model,
            &cached.latents,
            resolution,
            self.extraction,
            cancel,
        )?;
        let reference = Arc::new(NoveltyReference::new(&surfaces, self.chamfer_points)?);
        lock_references()?.insert(key, reference.clone());
        Ok(reference)
    }

    fn training_surface(
        &self,
        model_dir: &Path,
        index: usize,
        resolution: usize,
        cancel: &AtomicBool,
    ) -> anyhow::Result<TriMesh> {
        let cached = self.model(model_dir)?;
        let cached = cached
            .lock()
            .map_err(|_| anyhow::anyhow!("model poisoned"))?;
        let latent = cached
            .latents
            .get(index)
            .with_context(|| format!("the model has no training shape {index}"))?;
        Ok(training_surface(
            &cached.model,
            latent,
            index,
            resolution,
            self.extraction,
            cancel,
        )?)
    }

    fn cached_novelty_reference(
        &self,
        model_dir: &Path,
        resolution: usize,
    ) -> Option<Arc<NoveltyReference>> {
        let key = reference_key(model_dir, resolution).ok()?;
        self.references.lock().ok()?.get(&key)
    }

    fn novelty_reference_from(
        &self,
        model_dir: &Path,
        resolution: usize,
        surfaces: &[TriMesh],
    ) -> anyhow::Result<Arc<NoveltyReference>> {
        let reference = Arc::new(NoveltyReference::new(surfaces, self.chamfer_points)?);
        self.references
            .lock()
            .map_err(|_| anyhow::anyhow!("reference cache poisoned"))?
            .insert(reference_key(model_dir, resolution)?, reference.clone());
        Ok(reference)
    }

    fn pair_chamfer(
        &self,
        meshes: &[(u32, TriMesh)],
        pairs: &[(u32, u32)],
        seed: u64,
    ) -> anyhow::Result<Vec<f64>> {
        let indexed: Vec<(u32, ChamferIndex)> = meshes
            .par_iter()
            .map(|(index, mesh)| {
                let sample = sample_surface(
                    mesh,
                    self.chamfer_points,
                    seed.wrapping_add(u64::from(*index)),
                );
                (*index, ChamferIndex::new(&sample.points))
            })
            .collect();
        if let Some((index, _)) = indexed.iter().find(|(_, set)| set.is_empty()) {
            bail!("shape {index} has no surface to sample");
        }
        let position: HashMap<u32, usize> = indexed
            .iter()
            .enumerate()
            .map(|(k, (index, _))| (*index, k))
            .collect();
        let set = |index: u32| -> anyhow::Result<&ChamferIndex> {
            let k = position
                .get(&index)
                .with_context(|| format!("shape {index} was not given"))?;
            Ok(&indexed[*k].1)
        };
        let resolved = pairs
            .iter()
            .map(|&(i, j)| Ok((set(i)?, set(j)?)))
            .collect::<anyhow::Result<Vec<_>>>()?;
        Ok(resolved
            .par_iter()
            .map(|(a, b)| chamfer_between_serial(a, b))
            .collect())
    }

    fn train_model(
        &self,
        spec: &TrainingSpec,
        cancel: &AtomicBool,
        progress: &AtomicU64,
    ) -> anyhow::Result<ModelInfo> {
        let mut setup = Preset::Cpu.setup(spec.seed);
        if let Some(epochs) = spec.epochs {
            setup.training.epochs = epochs;
        }
        // At least ten checkpoints per run: an interrupted job loses at most a tenth.
        let every = (setup.training.epochs / 10).max(1);
        setup.training.checkpoint_every = setup.training.checkpoint_every.min(every);
        let request = |resume| TrainingRequest {
            out_dir: spec.model_dir.clone(),
            source: DataSource::Directory {
                path: spec.input_dir.clone(),
            },
            holdout: spec.holdout.map(|count| HoldoutSpec {
                count,
                seed: spec.seed,
            }),
            setup: setup.clone(),
            backend: self.backend,
            resume,
            stop: Some(cancel),
        };
        let mut observer = SavedEpochs(progress);
        // A checkpoint exists when an earlier run was interrupted (shutdown or a killed
        // process); continue it. A process killed while saving can leave files that do not
        // match their manifest: such a checkpoint cannot be resumed and training starts over.
        let outcome = if spec.model_dir.join(MANIFEST_FILE).exists() {
            match train(&request(true), &mut observer) {
                Ok(outcome) => outcome,
                Err(e) if !cancel.load(Ordering::SeqCst) => {
                    tracing::warn!(
                        error = format!("{e:#}"),
                        "the training checkpoint cannot be resumed; starting over"
                    );
                    let manifest = spec.model_dir.join(MANIFEST_FILE);
                    std::fs::remove_file(&manifest)
                        .with_context(|| format!("cannot remove {}", manifest.display()))?;
                    progress.store(0, Ordering::SeqCst);
                    train(&request(false), &mut observer)?
                }
                Err(e) => return Err(e),
            }
        } else {
            train(&request(false), &mut observer)?
        };
        if !outcome.finished {
            bail!("training was stopped before its last epoch");
        }
        self.model_info(&spec.model_dir)
    }

    fn fit_anchor(
        &self,
        model_dir: &Path,
        spec: &FitSpec,
        cancel: &AtomicBool,
        progress: &AtomicU64,
    ) -> anyhow::Result<FittedAnchor> {
        let mesh = crate::formats::read_mesh_file(&spec.mesh_path)
            .with_context(|| format!("cannot read {}", spec.mesh_path.display()))?;
        mesh.validate().context("unusable mesh")?;
        let model = self.frozen_copy(model_dir)?;
        self.fit(
            &model,
            &mesh,
            &self.fit_settings(spec.iterations, spec.seed),
            cancel,
            progress,
        )
    }

    fn refit_training_shape(
        &self,
        model_dir: &Path,
        index: usize,
        spec: &RefitSpec,
        cancel: &AtomicBool,
        progress: &AtomicU64,
    ) -> anyhow::Result<FittedAnchor> {
        let model = self.frozen_copy(model_dir)?;
        let meshes = self.training_meshes(model_dir, &model)?;
        let (name, mesh) = meshes.get(index).with_context(|| {
            format!(
                "the model has {} training shapes, not {}",
                meshes.len(),
                index + 1
            )
        })?;
        let recorded = &model.manifest.shapes[index].name;
        anyhow::ensure!(
            name == recorded,
            "the training data changed: shape {index} is {name:?}, the model trained on {recorded:?}"
        );
        let settings = refit_settings(&self.fit_settings(spec.iterations, spec.seed), index);
        self.fit(&model, mesh, &settings, cancel, progress)
            .with_context(|| format!("training shape {index} ({name})"))
    }
}

impl SdfEngine {
    /// A copy of the model in `dir`, so cohorts on the same model are not held up for the
    /// whole of a fit.
    fn frozen_copy(&self, dir: &Path) -> anyhow::Result<LoadedModel> {
        let cached = self.model(dir)?;
        let cached = cached
            .lock()
            .map_err(|_| anyhow::anyhow!("model poisoned"))?;
        Ok(LoadedModel {
            dir: cached.model.dir.clone(),
            manifest: cached.model.manifest.clone(),
            decoder: cached.model.decoder.clone(),
        })
    }

    /// The fit settings of this engine (its Chamfer sampling and extraction).
    fn fit_settings(&self, iterations: usize, seed: u64) -> FitSettings {
        let mut settings = FitSettings::new(seed);
        settings.iterations = iterations;
        settings.evaluation.chamfer_points = self.chamfer_points;
        settings.evaluation.extraction = self.extraction;
        settings
    }

    fn fit(
        &self,
        model: &LoadedModel,
        mesh: &TriMesh,
        settings: &FitSettings,
        cancel: &AtomicBool,
        progress: &AtomicU64,
    ) -> anyhow::Result<FittedAnchor> {
        let fitted = fit_mesh(
            model,
            mesh,
            settings,
            &mut |p| progress.store(p.iteration as u64, Ordering::SeqCst),
            Some(cancel),
        )?;
        Ok(FittedAnchor {
            latent: fitted.latent,
            transform: fitted.transform,
            chamfer: fitted.chamfer,
        })
    }

    /// The training meshes of `model` (in `dir`), read from the data its manifest names
    /// and split as in training; kept for the model last asked about.
    fn training_meshes(&self, dir: &Path, model: &LoadedModel) -> anyhow::Result<NamedMeshes> {
        let key = (
            dir.to_path_buf(),
            DirStamp::of(dir)
                .with_context(|| format!("cannot read the model in {}", dir.display()))?,
        );
        let mut kept = self
            .training_meshes
            .lock()
            .map_err(|_| anyhow::anyhow!("training mesh cache poisoned"))?;
        if let Some((k, meshes)) = kept.as_ref()
            && *k == key
        {
            return Ok(meshes.clone());
        }
        let manifest = &model.manifest;
        let training = load_split(&manifest.data.source, manifest.data.holdout.as_ref())
            .context("cannot read the model's training data")?
            .training;
        anyhow::ensure!(
            training.len() == manifest.shapes.len(),
            "the training data gives {} training shapes, the model has {}",
            training.len(),
            manifest.shapes.len()
        );
        let meshes = Arc::new(training);
        *kept = Some((key, meshes.clone()));
        Ok(meshes)
    }
}

/// The spec's mixed latent and transform: training latents first, then the sampled latent
/// and the anchors (their weights follow in `spec.weights`); the noise scale comes from the
/// training latents.
fn mixed_latent(
    spec: &ShapeSpec,
    latents: &[Vec<f32>],
    transforms: &[crate::geometry::normalize::UnitBallTransform],
) -> anyhow::Result<(crate::geometry::normalize::UnitBallTransform, Vec<f32>)> {
    let k = spec.training_indices.len();
    anyhow::ensure!(
        spec.weights.len() == spec.drawn_members() + spec.anchors.len(),
        "{} weights for {k} training shapes, {} sampled latents and {} anchors",
        spec.weights.len(),
        usize::from(spec.sampled.is_some()),
        spec.anchors.len()
    );
    let mixture = Mixture {
        indices: spec.training_indices.clone(),
        weights: spec.weights[..k].to_vec(),
    };
    // A sampled latent enters the mixture like an anchor: a latent with its own transform.
    let sampled = spec.sampled.iter().map(|s| (&s.latent, &s.transform));
    let anchors = spec.anchors.iter().map(|a| (&a.latent, &a.transform));
    let anchors: Vec<AnchorPart<'_>> = sampled
        .chain(anchors)
        .zip(&spec.weights[k..])
        .map(|((latent, transform), &weight)| AnchorPart {
            weight,
            latent,
            transform,
        })
        .collect();
    Ok(anchored_latent(
        &mixture,
        latents,
        transforms,
        &anchors,
        spec.latent_noise,
        spec.seed,
    )?)
}

/// Publishes the epochs saved in a checkpoint to the job that runs the training.
struct SavedEpochs<'a>(&'a AtomicU64);

impl TrainingObserver for SavedEpochs<'_> {
    fn on_start(&mut self, _epochs: u64, first_epoch: u64, _batches_per_epoch: u64) {
        self.0.store(first_epoch, Ordering::SeqCst);
    }

    fn on_checkpoint(&mut self, epochs_completed: u64) {
        self.0.store(epochs_completed, Ordering::SeqCst);
    }
}

/// Per-shape reconstruction CDs from the model's `evaluation.json`, if it has one.
fn read_reconstruction_cds(model_dir: &Path) -> Vec<Option<f64>> {
    read_evaluation(model_dir)
        .map(|report| report.shapes.iter().map(|s| s.chamfer).collect())
        .unwrap_or_default()
}

/// The model's stored evaluation (`aortagen evaluate --json MODEL_DIR/evaluation.json`),
/// if it has a readable one.
pub fn read_evaluation(model_dir: &Path) -> Option<EvaluationReport> {
    let bytes = std::fs::read(model_dir.join(EVALUATION_FILE)).ok()?;
    serde_json::from_slice(&bytes).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_shapes::uv_sphere;

    #[test]
    fn a_reference_built_from_stored_surfaces_is_kept_for_its_model_and_resolution() {
        let engine = SdfEngine::new(Backend::default()).with_chamfer_points(200);
        let models = tempfile::tempdir().unwrap();
        let model_dir = models.path().join("some-model");
        std::fs::create_dir(&model_dir).unwrap();
        std::fs::write(model_dir.join("weights.bin"), b"weights").unwrap();
        let dir = model_dir.as_path();
        assert!(engine.cached_novelty_reference(dir, 64).is_none());
        let surfaces = [
            uv_sphere(1.0, [0.0; 3], 8, 12),
            uv_sphere(0.5, [0.1, 0.0, 0.0], 8, 12),
        ];
        let built = engine.novelty_reference_from(dir, 64, &surfaces).unwrap();
        let cached = engine.cached_novelty_reference(dir, 64).unwrap();
        assert!(Arc::ptr_eq(&built, &cached));
        assert!(engine.cached_novelty_reference(dir, 128).is_none());
        assert!(
            engine
                .cached_novelty_reference(Path::new("models/other"), 64)
                .is_none()
        );
        // Rewritten weights under the same path are another model: the old reference is not served.
        std::fs::write(model_dir.join("weights.bin"), b"retrained weights").unwrap();
        assert!(engine.cached_novelty_reference(dir, 64).is_none());
        // A directory that cannot be read is an error, never a panic.
        assert!(
            engine
                .novelty_reference_from(&models.path().join("missing"), 64, &surfaces)
                .is_err()
        );
    }
}
