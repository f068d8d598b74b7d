//! The cohort job: the cohort pipeline ([`crate::cohort`]) generates the shapes not yet
//! stored on an engine thread, this task commits each in its own transaction as it arrives,
//! then the pairwise Chamfer metrics. Re-running it after an interruption continues where
//! it stopped.

use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;
use serde::{Deserialize, Serialize};
use tokio::sync::{mpsc, oneshot};

use super::priority::spawn_background;
use super::{JobContext, JobError, join_error, setup, stats};
use crate::cohort::{
    CohortError, CohortGenerator, CohortPlan, CohortRequest, CohortSetup, CohortShape,
    EngineHandle, ModelLatents,
};
use crate::db::{self, cohorts::CohortRow, models::ModelRow};
use crate::engine::AnchorLatent;
use crate::formats::mesh_blob;

/// The payload of a `cohort` job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CohortPayload {
    /// The cohort to generate.
    pub cohort_id: i64,
}

pub(super) async fn run(
    ctx: &JobContext,
    job_id: i64,
    payload: &CohortPayload,
    flag: &Arc<AtomicBool>,
) -> Result<(), JobError> {
    let cohort = db::cohorts::get(&ctx.pool, payload.cohort_id)
        .await?
        .with_context(|| format!("cohort {} no longer exists", payload.cohort_id))?;
    tracing::Span::current().record("cohort_id", cohort.cohort_id);
    let model = db::models::get(&ctx.pool, &cohort.model_id)
        .await?
        .with_context(|| format!("model {:?} no longer exists", cohort.model_id))?;
    let request = cohort.request().context("the stored request")?;
    let stored: HashSet<i64> = db::shapes::existing_indices(&ctx.pool, cohort.cohort_id)
        .await?
        .into_iter()
        .collect();
    let missing: Vec<u64> = (0..cohort.count)
        .filter(|i| !stored.contains(i))
        .map(|i| i as u64)
        .collect();
    if !missing.is_empty() {
        if !stored.is_empty() {
            tracing::info!(done = stored.len(), "resuming cohort");
        }
        let generation = Generation {
            ctx,
            job_id,
            cohort: &cohort,
            model: &model,
            request,
            flag,
        };
        generation.run(missing, stored.len() as i64).await?;
    }
    let has_metrics = db::cohort_metrics::get(&ctx.pool, cohort.cohort_id)
        .await?
        .is_some();
    if !has_metrics {
        compute_metrics(ctx, &cohort)
            .await
            .context("pairwise metrics")?;
    }
    Ok(())
}

/// The generation of a cohort's missing shapes.
struct Generation<'a> {
    ctx: &'a JobContext,
    job_id: i64,
    cohort: &'a CohortRow,
    model: &'a ModelRow,
    request: CohortRequest<i64>,
    flag: &'a Arc<AtomicBool>,
}

/// Why the engine thread stopped generating.
enum GenerationStop {
    /// The pipeline stopped.
    Cohort(CohortError),
    /// This task stopped taking shapes (its commit failed).
    Abandoned,
}

impl From<CohortError> for GenerationStop {
    fn from(e: CohortError) -> Self {
        Self::Cohort(e)
    }
}

/// A finished shape with its canonical encoding.
struct Encoded {
    shape: CohortShape,
    blob: Vec<u8>,
    sha: String,
}

impl Generation<'_> {
    /// Generates `missing` on an engine thread and commits each shape as it arrives; the
    /// next shape is generated only once the last one is stored. `done` shapes are stored
    /// already.
    async fn run(self, missing: Vec<u64>, mut done: i64) -> Result<(), JobError> {
        let generator = self.generator().await?;
        let (sender, mut shapes) = mpsc::channel::<(Encoded, oneshot::Sender<()>)>(1);
        let task = spawn_background(move || {
            generator.run(missing, |shape| {
                let blob = mesh_blob::encode(&shape.shape.mesh_unit);
                let sha = mesh_blob::sha256_hex(&blob);
                let (stored, committed) = oneshot::channel();
                sender
                    .blocking_send((Encoded { shape, blob, sha }, stored))
                    .map_err(|_| GenerationStop::Abandoned)?;
                committed
                    .blocking_recv()
                    .map_err(|_| GenerationStop::Abandoned)
            })
        });
        let mut commit_error = None;
        while let Some((encoded, stored)) = shapes.recv().await {
            done += 1;
            let committed = self.commit_shape(&encoded, done).await;
            let cancel = match committed {
                Ok(()) => db::jobs::is_cancel_requested(&self.ctx.pool, self.job_id)
                    .await
                    .map_err(anyhow::Error::from),
                Err(e) => Err(e),
            };
            match cancel {
                Ok(cancel) => {
                    self.ctx.metrics.inc_shapes_generated();
                    tracing::debug!(index = encoded.shape.index, done, "shape committed");
                    if cancel {
                        self.flag.store(true, Ordering::SeqCst);
                    }
                    let _ = stored.send(());
                }
                Err(e) => {
                    self.flag.store(true, Ordering::SeqCst);
                    commit_error = Some(e);
                    break;
                }
            }
        }
        drop(shapes);
        let generated = task.await.map_err(join_error)?;
        if let Some(e) = commit_error {
            return Err(JobError::Failed(e.context("cannot store a shape")));
        }
        match generated {
            Ok(()) => Ok(()),
            Err(GenerationStop::Cohort(e)) => Err(e.into()),
            Err(GenerationStop::Abandoned) => Err(JobError::Stopped),
        }
    }

    /// The pipeline of this cohort: anchors, training measurements and latents read, the
    /// novelty reference built from the training surfaces stored for the model and
    /// resolution (the missing ones computed and stored first).
    async fn generator(&self) -> Result<CohortGenerator, JobError> {
        let ctx = self.ctx;
        let info = self
            .model
            .info()
            .with_context(|| format!("model {:?} has no manifest", self.model.model_id))?;
        let count = info.training_shape_count();
        let model_dir = PathBuf::from(&self.model.dir_path);
        let anchors = anchor_latents(&ctx.pool, &self.request.anchors)
            .await
            .context("anchors")?;
        let training = match &self.request.targets {
            None => None,
            Some(_) => Some(
                setup::training_anatomy(
                    &ctx.pool,
                    ctx.engine.clone(),
                    &self.model.model_id,
                    &model_dir,
                    count,
                )
                .await
                .context("targets")?,
            ),
        };
        let source = setup::ReferenceSource {
            job_id: self.job_id,
            model_id: &self.model.model_id,
            model_dir: &model_dir,
            count,
            resolution: self.request.resolution,
        };
        let reference = setup::novelty_reference(ctx, &source, self.flag).await?;
        let engine = ctx.engine.clone();
        let (request, flag) = (self.request.clone(), self.flag.clone());
        let handle = EngineHandle {
            engine: engine.clone(),
            model_dir: model_dir.clone(),
            model_id: self.model.model_id.clone(),
            cancel: flag.clone(),
        };
        let built = spawn_background(move || -> Result<CohortGenerator, JobError> {
            let latents = ModelLatents::read(&*engine, &model_dir, &request, count)?;
            let plan = CohortPlan::new(&request, count, latents.as_ref(), anchors)?;
            let setup = CohortSetup {
                reference,
                training,
            };
            Ok(CohortGenerator::new(handle, plan, &request, setup)?)
        });
        built.await.map_err(join_error)?
    }

    /// Stores one shape and the job's progress in a single transaction.
    async fn commit_shape(&self, encoded: &Encoded, done: i64) -> anyhow::Result<()> {
        let CohortShape {
            index,
            spec,
            shape,
            novelty,
            redraws,
            novelty_met,
            anatomy,
            provenance,
            ..
        } = &encoded.shape;
        let row = db::shapes::NewShape {
            cohort_id: self.cohort.cohort_id,
            shape_index: *index as i64,
            training_indices: &spec.training_indices,
            weights: &spec.weights,
            seed: spec.seed as i64,
            resolution: spec.resolution as i64,
            software_version: &provenance.software_version,
            vertex_count: shape.mesh_unit.vertex_count() as i64,
            triangle_count: shape.mesh_unit.triangle_count() as i64,
            area_mm2: shape.area_mm2,
            volume_mm3: shape.volume_mm3,
            centre: shape.transform.centre,
            radius: shape.transform.radius,
            mesh: &encoded.blob,
            mesh_sha256: &encoded.sha,
            latent_noise: spec.latent_noise,
            selection: provenance.selection,
            attempt: provenance.attempt,
            redraws: i64::from(*redraws),
            novelty_cd: Some(novelty.chamfer),
            nearest_training_index: Some(novelty.nearest as i64),
            novelty_met: Some(*novelty_met),
            anatomy: anatomy.as_ref().ok(),
            anatomy_error: anatomy.as_ref().err().map(String::as_str),
            candidates: provenance.candidates,
            targets_met: provenance.targets_met,
        };
        let mut tx = self.ctx.pool.begin_with(db::BEGIN_WRITE).await?;
        let shape_id = db::shapes::insert(&mut tx, &row)
            .await
            .with_context(|| format!("cannot store shape {index}"))?;
        if !self.request.anchors.is_empty() {
            db::anchors::set_shape_anchors(&mut tx, shape_id, &self.request.anchors).await?;
        }
        db::jobs::set_progress(&mut tx, self.job_id, done).await?;
        tx.commit().await.context("cannot commit shape")?;
        Ok(())
    }
}

/// The latents of a cohort's anchors, in the listed order; an error names a missing one.
async fn anchor_latents(pool: &sqlx::SqlitePool, ids: &[i64]) -> anyhow::Result<Vec<AnchorLatent>> {
    let mut out = Vec::with_capacity(ids.len());
    for &id in ids {
        let row = db::anchors::get(pool, id)
            .await?
            .ok_or_else(|| anyhow::anyhow!("anchor {id} no longer exists"))?;
        let (Some(latent), Some(transform)) = (row.latent_values(), row.transform()) else {
            anyhow::bail!("anchor {id} has no fitted latent");
        };
        out.push(AnchorLatent {
            name: row.name,
            latent,
            transform,
        });
    }
    Ok(out)
}

/// Pairwise Chamfer distances over the stored unit-ball meshes, summarised and stored.
async fn compute_metrics(ctx: &JobContext, cohort: &CohortRow) -> anyhow::Result<()> {
    let stored = db::shapes::cohort_meshes(&ctx.pool, cohort.cohort_id).await?;
    let engine = ctx.engine.clone();
    let seed = cohort.seed as u64;
    let matrix = spawn_background(move || -> anyhow::Result<Vec<Vec<f64>>> {
        let meshes = stored
            .iter()
            .map(|s| mesh_blob::decode(&s.mesh).with_context(|| format!("shape {}", s.shape_id)))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let matrix = engine.pairwise_chamfer(&meshes, seed)?;
        let n = meshes.len();
        anyhow::ensure!(
            matrix.len() == n && matrix.iter().all(|r| r.len() == n),
            "engine returned a matrix that is not {n}×{n}"
        );
        anyhow::ensure!(
            matrix.iter().flatten().all(|v| v.is_finite()),
            "non-finite distance"
        );
        Ok(matrix)
    })
    .await
    .map_err(join_error)??;
    let summary = serde_json::to_value(stats::summarize(&matrix))?;
    db::cohort_metrics::upsert(&ctx.pool, cohort.cohort_id, &matrix, &summary).await?;
    Ok(())
}
