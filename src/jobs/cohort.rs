//! The cohort job's tasks: setup steps (training surfaces for novelty, training
//! measurements for targets), one task per shape drawn by the cohort pipeline
//! ([`crate::cohort`]) and committed with its lease, then the pairwise Chamfer metrics.
//! Any worker may run any of them; a cohort interrupted anywhere continues with the shapes
//! not yet stored, and each shape is the same whichever worker draws it.

use std::collections::HashSet;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use super::priority::spawn_background;
use super::{
    JobContext, JobError, TaskRun, join_error, lifecycle, setup, stats, stopped, stopped_or_failed,
};
use crate::cohort::{
    CohortError, CohortGenerator, CohortPlan, CohortRequest, CohortSetup, CohortShape,
    EngineHandle, ModelLatents,
};
use crate::db::tasks::NewTask;
use crate::db::{self, cohorts::CohortRow, jobs::FinalStatus, models::ModelRow, states::TaskKind};
use crate::engine::AnchorLatent;
use crate::formats::mesh_blob;

/// The payload of a `cohort` job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CohortPayload {
    /// The cohort to generate.
    pub cohort_id: i64,
}

/// The tasks of a cohort job: the training surfaces its model lacks at the cohort's
/// resolution, the training measurements when it has targets and they are not stored, one
/// task per shape not yet stored, and the metrics step when every shape is stored.
pub(super) async fn plan(pool: &db::Pool, payload: &CohortPayload) -> anyhow::Result<Vec<NewTask>> {
    let (cohort, model) = load(pool, payload).await?;
    let request = cohort.request().context("the stored request")?;
    let count = training_count(&model)?;
    let stored_surfaces: HashSet<i64> =
        db::novelty_surfaces::stored_indices(pool, &model.model_id, request.resolution)
            .await?
            .into_iter()
            .collect();
    let mut tasks: Vec<NewTask> = (0..count as i64)
        .filter(|i| !stored_surfaces.contains(i))
        .map(|item| NewTask {
            kind: TaskKind::Surface,
            item,
        })
        .collect();
    if request.targets.is_some()
        && setup::stored_training_anatomy(pool, &model.model_id, count)
            .await?
            .is_none()
    {
        tasks.push(NewTask::whole(TaskKind::Anatomy));
    }
    let stored: HashSet<i64> = db::shapes::existing_indices(pool, cohort.cohort_id)
        .await?
        .into_iter()
        .collect();
    let missing: Vec<NewTask> = (0..cohort.count)
        .filter(|i| !stored.contains(i))
        .map(|item| NewTask {
            kind: TaskKind::Shape,
            item,
        })
        .collect();
    if missing.is_empty()
        && db::cohort_metrics::get(pool, cohort.cohort_id)
            .await?
            .is_none()
    {
        tasks.push(NewTask::whole(TaskKind::Metrics));
    }
    tasks.extend(missing);
    Ok(tasks)
}

/// The cohort and its model, or an error naming the one that is gone.
async fn load(pool: &db::Pool, payload: &CohortPayload) -> anyhow::Result<(CohortRow, ModelRow)> {
    let cohort = db::cohorts::get(pool, payload.cohort_id)
        .await?
        .with_context(|| format!("cohort {} no longer exists", payload.cohort_id))?;
    tracing::Span::current().record("cohort_id", cohort.cohort_id);
    let model = db::models::get(pool, &cohort.model_id)
        .await?
        .with_context(|| format!("model {:?} no longer exists", cohort.model_id))?;
    Ok((cohort, model))
}

fn training_count(model: &ModelRow) -> anyhow::Result<usize> {
    let info = model
        .info()
        .with_context(|| format!("model {:?} has no manifest", model.model_id))?;
    Ok(info.training_shape_count())
}

/// Setup step: training shape `item` as the model reconstructs it at the cohort's
/// resolution, stored for every later cohort of that model and resolution.
pub(super) async fn surface(
    ctx: &JobContext,
    run: &TaskRun,
    payload: &CohortPayload,
) -> Result<(), JobError> {
    let (cohort, model) = load(&ctx.pool, payload).await?;
    let resolution = cohort.resolution as usize;
    let index = usize::try_from(run.lease.item).context("a training-shape index")?;
    let stored = db::novelty_surfaces::stored_indices(&ctx.pool, &model.model_id, resolution)
        .await?
        .contains(&run.lease.item);
    let blob = if stored {
        None
    } else {
        let (engine, dir, flag) = (
            ctx.engine.clone(),
            ctx.model_dir(&model).await?,
            run.flag.clone(),
        );
        let made = spawn_background(move || {
            let mesh = engine.training_surface(&dir, index, resolution, &flag)?;
            anyhow::Ok(mesh_blob::encode(&mesh))
        })
        .await
        .map_err(join_error)?;
        let made = made.map_err(|e| {
            let e = e.context(format!("training shape {index} at resolution {resolution}"));
            stopped_or_failed(&run.flag, e.context("novelty reference"))
        })?;
        Some(made)
    };
    let mut tx = db::begin_write(&ctx.pool).await?;
    db::tasks::complete(&mut tx, &run.lease).await?;
    if let Some(blob) = &blob {
        let surface = db::novelty_surfaces::Surface {
            model_id: &model.model_id,
            resolution,
            shape_index: index,
            mesh: blob,
        };
        db::novelty_surfaces::store(&mut tx, run.lease.job_id, &surface).await?;
    }
    tx.commit()
        .await
        .context("cannot commit a novelty surface")?;
    tracing::debug!(index, resolution, "novelty surface stored");
    Ok(())
}

/// Setup step of a targeted cohort: the model's training shapes measured and stored.
pub(super) async fn anatomy(
    ctx: &JobContext,
    run: &TaskRun,
    payload: &CohortPayload,
) -> Result<(), JobError> {
    let (_, model) = load(&ctx.pool, payload).await?;
    let count = training_count(&model)?;
    let dir = ctx.model_dir(&model).await?;
    setup::training_anatomy(&ctx.pool, ctx.engine.clone(), &model.model_id, &dir, count)
        .await
        .context("targets")?;
    let mut tx = db::begin_write(&ctx.pool).await?;
    db::tasks::complete(&mut tx, &run.lease).await?;
    tx.commit()
        .await
        .context("cannot commit the training measurements")?;
    Ok(())
}

/// One shape: drawn by the cohort's pipeline for its index (the same shape whichever worker
/// makes it, and however often), committed with the task. The last shape's commit queues
/// the metrics step.
pub(super) async fn shape(
    ctx: &JobContext,
    run: &TaskRun,
    payload: &CohortPayload,
) -> Result<(), JobError> {
    let (cohort, model) = load(&ctx.pool, payload).await?;
    let index = u64::try_from(run.lease.item).context("a shape index")?;
    let request = cohort.request().context("the stored request")?;
    let generation = Generation {
        ctx,
        run,
        cohort: &cohort,
        model: &model,
        request,
    };
    let generator = generation.generator().await?;
    let made = spawn_background(move || -> Result<Encoded, CohortError> {
        let shape = generator.shape(index)?;
        let blob = mesh_blob::encode(&shape.shape.mesh_unit);
        let sha = mesh_blob::sha256_hex(&blob);
        Ok(Encoded { shape, blob, sha })
    })
    .await
    .map_err(join_error)??;
    generation.commit_shape(&made).await?;
    ctx.metrics.inc_shapes_generated();
    tracing::debug!(index, "shape committed");
    Ok(())
}

/// The pairwise statistics of a finished cohort, committed with the task; the cohort's job
/// succeeds with them.
pub(super) async fn metrics(
    ctx: &JobContext,
    run: &TaskRun,
    payload: &CohortPayload,
) -> Result<(), JobError> {
    let (cohort, _) = load(&ctx.pool, payload).await?;
    stopped(&run.flag)?;
    let (matrix, summary) = compute_metrics(ctx, &cohort)
        .await
        .context("pairwise metrics")?;
    let mut tx = db::begin_write(&ctx.pool).await?;
    db::tasks::complete(&mut tx, &run.lease).await?;
    db::cohort_metrics::upsert(&mut *tx, cohort.cohort_id, &matrix, &summary).await?;
    lifecycle::finish_job(&mut tx, run.lease.job_id, FinalStatus::Succeeded, None).await?;
    tx.commit()
        .await
        .context("cannot commit the cohort's metrics")?;
    Ok(())
}

/// The generation of one shape of a cohort.
struct Generation<'a> {
    ctx: &'a JobContext,
    run: &'a TaskRun,
    cohort: &'a CohortRow,
    model: &'a ModelRow,
    request: CohortRequest<i64>,
}

/// A finished shape with its canonical encoding.
struct Encoded {
    shape: CohortShape,
    blob: Vec<u8>,
    sha: String,
}

impl Generation<'_> {
    /// The pipeline of this cohort: anchors, training measurements and latents read, the
    /// novelty reference built from the training surfaces stored for the model and
    /// resolution by the cohort's setup steps.
    async fn generator(&self) -> Result<CohortGenerator, JobError> {
        let ctx = self.ctx;
        let count = training_count(self.model)?;
        let model_dir = ctx.model_dir(self.model).await?;
        let anchors = anchor_latents(&ctx.pool, &self.request.anchors)
            .await
            .context("anchors")?;
        let training = match &self.request.targets {
            None => None,
            Some(_) => Some(
                setup::stored_training_anatomy(&ctx.pool, &self.model.model_id, count)
                    .await?
                    .context("the training shapes are not measured")?,
            ),
        };
        let source = setup::ReferenceSource {
            model_id: &self.model.model_id,
            model_dir: &model_dir,
            count,
            resolution: self.request.resolution,
        };
        let reference = setup::novelty_reference(ctx, &source).await?;
        let engine = ctx.engine.clone();
        let request = self.request.clone();
        let handle = EngineHandle {
            engine: engine.clone(),
            model_dir: model_dir.clone(),
            model_id: self.model.model_id.clone(),
            cancel: self.run.flag.clone(),
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

    /// Stores one shape with its task's result and the job's progress in a single
    /// transaction, refused when the task's lease was taken over; queues the metrics step
    /// after the last shape.
    async fn commit_shape(&self, encoded: &Encoded) -> Result<(), JobError> {
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
        let job_id = self.run.lease.job_id;
        // The object first: a row never names a mesh that is not stored.
        self.ctx.objects.put(&encoded.blob).await?;
        let mut tx = db::begin_write(&self.ctx.pool).await?;
        db::tasks::complete(&mut tx, &self.run.lease).await?;
        let shape_id = db::shapes::insert(&mut tx, &row)
            .await
            .with_context(|| format!("cannot store shape {index}"))?;
        if !self.request.anchors.is_empty() {
            db::anchors::set_shape_anchors(&mut tx, shape_id, &self.request.anchors).await?;
        }
        let done = db::shapes::count_for_cohort(&mut *tx, self.cohort.cohort_id).await?;
        db::jobs::set_progress(&mut tx, job_id, done).await?;
        if db::tasks::unfinished_count(&mut tx, job_id, TaskKind::Shape).await? == 0 {
            db::tasks::insert_missing(&mut tx, job_id, &[NewTask::whole(TaskKind::Metrics)])
                .await?;
        }
        tx.commit().await.context("cannot commit shape")?;
        Ok(())
    }
}

/// The latents of a cohort's anchors, in the listed order; an error names a missing one.
async fn anchor_latents(pool: &db::Pool, ids: &[i64]) -> anyhow::Result<Vec<AnchorLatent>> {
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

/// Pairwise Chamfer distances over the stored unit-ball meshes, and their summary.
async fn compute_metrics(
    ctx: &JobContext,
    cohort: &CohortRow,
) -> anyhow::Result<(Vec<Vec<f64>>, serde_json::Value)> {
    let rows = db::shapes::cohort_meshes(&ctx.pool, cohort.cohort_id).await?;
    let mut stored = Vec::with_capacity(rows.len());
    for row in rows {
        stored.push(ctx.objects.load(row).await?);
    }
    let engine = ctx.engine.clone();
    let seed = cohort.seed as u64;
    let matrix = spawn_background(move || -> anyhow::Result<Vec<Vec<f64>>> {
        let meshes = stored
            .iter()
            .map(|s| {
                mesh_blob::decode(&s.mesh).with_context(|| format!("shape {}", s.row.shape_id))
            })
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
    Ok((matrix, summary))
}
