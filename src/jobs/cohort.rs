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
    EngineHandle, LatentSource, ModelLatents,
};
use crate::db::tasks::NewTask;
use crate::db::{self, cohorts::CohortRow, jobs::FinalStatus, models::ModelRow, states::TaskKind};
use crate::engine::AnchorLatent;
use crate::formats::mesh_blob;
use crate::jobs::stats::PairDistances;
use crate::stats::pair_sample::PairPlan;

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
        let stored = db::cohort_metrics::stored_pair_keys(pool, cohort.cohort_id).await?;
        tasks.extend(metrics_tasks(&cohort, &stored.into_iter().collect()));
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
    let model = super::existing_model(pool, &cohort.model_id).await?;
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

/// The pairs of a cohort its statistics are over (all of them, or a sample for a large
/// cohort), drawn from the cohort's seed.
fn pair_plan(cohort: &CohortRow) -> PairPlan {
    PairPlan::new(cohort.count.max(0) as usize, cohort.seed as u64)
}

/// The metrics tasks of a cohort whose shapes are all stored: one per part of its pair
/// plan whose pairs are not all stored yet, and at least one, which assembles them.
fn metrics_tasks(cohort: &CohortRow, stored: &HashSet<(u32, u32)>) -> Vec<NewTask> {
    let plan = pair_plan(cohort);
    let mut tasks: Vec<NewTask> = (0..plan.task_count())
        .filter(|&t| {
            let pairs = plan.task_pairs(t);
            pairs.is_empty() || !pairs.iter().all(|p| stored.contains(p))
        })
        .map(|t| NewTask {
            kind: TaskKind::Metrics,
            item: t as i64,
        })
        .collect();
    if tasks.is_empty() {
        tasks.push(NewTask {
            kind: TaskKind::Metrics,
            item: 0,
        });
    }
    tasks
}

/// One part of a finished cohort's pairwise statistics: its pairs' Chamfer distances,
/// committed with the task. The part that finds every other part done assembles the
/// statistics, and the cohort's job succeeds with them. (Item -1, a metrics step queued
/// by an older version, is every part at once.)
pub(super) async fn metrics(
    ctx: &JobContext,
    run: &TaskRun,
    payload: &CohortPayload,
) -> Result<(), JobError> {
    let (cohort, _) = load(&ctx.pool, payload).await?;
    stopped(&run.flag)?;
    let plan = pair_plan(&cohort);
    let pairs: Vec<(u32, u32)> = match usize::try_from(run.lease.item) {
        Ok(part) => plan.task_pairs(part).to_vec(),
        Err(_) => plan.pairs().to_vec(),
    };
    let distances = pair_distances(ctx, &cohort, &pairs)
        .await
        .context("pairwise metrics")?;
    let job_id = run.lease.job_id;
    let mut tx = db::begin_write(&ctx.pool).await?;
    db::tasks::complete(&mut tx, &run.lease).await?;
    db::cohort_metrics::insert_pairs(&mut tx, cohort.cohort_id, &distances).await?;
    // Touching the job's row orders this commit after any concurrent part's on
    // PostgreSQL, so exactly one part sees all the others done.
    db::jobs::set_progress(&mut tx, job_id, cohort.count).await?;
    if db::tasks::unfinished_count(&mut tx, job_id, TaskKind::Metrics).await? == 0 {
        let stored = db::cohort_metrics::stored_pairs(&mut tx, cohort.cohort_id).await?;
        let (distances, summary) = assemble(&plan, stored).context("pairwise metrics")?;
        db::cohort_metrics::upsert(&mut *tx, cohort.cohort_id, &distances, &summary).await?;
        db::cohort_metrics::delete_pairs(&mut tx, cohort.cohort_id).await?;
        lifecycle::finish_job(&mut tx, job_id, FinalStatus::Succeeded, None).await?;
    }
    tx.commit()
        .await
        .context("cannot commit the cohort's metrics")?;
    Ok(())
}

/// The stored distances of every planned pair, as stored metrics and their summary; an
/// error names a planned pair that is missing.
fn assemble(
    plan: &PairPlan,
    stored: Vec<(u32, u32, f64)>,
) -> anyhow::Result<(PairDistances, serde_json::Value)> {
    let by_pair: std::collections::HashMap<(u32, u32), f64> =
        stored.into_iter().map(|(i, j, d)| ((i, j), d)).collect();
    let mut pairs = Vec::with_capacity(plan.pairs().len());
    for &(i, j) in plan.pairs() {
        let d = by_pair
            .get(&(i, j))
            .with_context(|| format!("the distance of shapes {i} and {j} is not stored"))?;
        pairs.push((i, j, *d));
    }
    let distances = PairDistances::new(plan.shapes(), plan.is_sampled(), pairs);
    let summary = stats::summarize_pairs(distances.values(), plan.population());
    Ok((distances, serde_json::to_value(summary)?))
}

/// Chamfer distances of `pairs` (shape indices) over the stored unit-ball meshes, reading
/// only the meshes those pairs name.
async fn pair_distances(
    ctx: &JobContext,
    cohort: &CohortRow,
    pairs: &[(u32, u32)],
) -> anyhow::Result<Vec<(u32, u32, f64)>> {
    if pairs.is_empty() {
        return Ok(Vec::new());
    }
    let needed: HashSet<u32> = pairs.iter().flat_map(|&(i, j)| [i, j]).collect();
    let rows = db::shapes::cohort_meshes(&ctx.pool, cohort.cohort_id).await?;
    let mut stored = Vec::with_capacity(needed.len());
    for row in rows {
        let Ok(index) = u32::try_from(row.shape_index) else {
            continue;
        };
        if needed.contains(&index) {
            stored.push((index, ctx.objects.load(row.mesh).await?));
        }
    }
    anyhow::ensure!(
        stored.len() == needed.len(),
        "{} of the {} shapes these pairs need are stored",
        stored.len(),
        needed.len()
    );
    let engine = ctx.engine.clone();
    let seed = cohort.seed as u64;
    let pairs = pairs.to_vec();
    spawn_background(move || -> anyhow::Result<Vec<(u32, u32, f64)>> {
        let meshes = stored
            .iter()
            .map(|(index, s)| {
                let mesh = mesh_blob::decode(&s.mesh)
                    .with_context(|| format!("shape {}", s.row.shape_id))?;
                Ok((*index, mesh))
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        let values = engine.pair_chamfer(&meshes, &pairs, seed)?;
        anyhow::ensure!(
            values.len() == pairs.len(),
            "engine returned {} distances for {} pairs",
            values.len(),
            pairs.len()
        );
        anyhow::ensure!(values.iter().all(|v| v.is_finite()), "non-finite distance");
        Ok(pairs
            .iter()
            .zip(values)
            .map(|(&(i, j), d)| (i, j, d))
            .collect())
    })
    .await
    .map_err(join_error)?
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
        // The service's own refit of the model comes before a refits.json beside it.
        let refitted = match self.request.sampler.latent_source() {
            Some(LatentSource::Refitted) => {
                db::refits::latents(&ctx.pool, &self.model.model_id, count).await?
            }
            _ => None,
        };
        let engine = ctx.engine.clone();
        let request = self.request.clone();
        let handle = EngineHandle {
            engine: engine.clone(),
            model_dir: model_dir.clone(),
            model_id: self.model.model_id.clone(),
            cancel: self.run.flag.clone(),
        };
        let built = spawn_background(move || -> Result<CohortGenerator, JobError> {
            let latents = ModelLatents::read(&*engine, &model_dir, &request, count, refitted)?;
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
            let tasks = metrics_tasks(self.cohort, &HashSet::new());
            db::tasks::insert_missing(&mut tx, job_id, &tasks).await?;
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
