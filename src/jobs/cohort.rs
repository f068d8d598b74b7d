//! The cohort job: generates the shapes not yet stored, one transaction per shape, then the
//! pairwise Chamfer metrics. Re-running it after an interruption continues where it stopped.

use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::Context;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::conditioned::{ShapeSearch, Targeting, search_shape, training_anatomy};
use super::engine::{AnchorLatent, CohortEngine, GeneratedShape, ModelInfo, ShapeSpec};
use super::plan::{CohortPlan, Weighting, force_anchors};
use super::priority::spawn_background;
use super::{JobContext, RunOutcome, join_error, stats, stop_outcome};
use crate::anatomy::shape::{ShapeAnatomy, measure_shape};
use crate::anatomy::targets::{DEFAULT_MAX_CANDIDATES, TargetRange, Targets, check_feasible};
use crate::db::{self, cohorts::CohortRow, jobs::ClaimedJob, mesh_blob};
use crate::sdf::generate::MAX_REDRAWS;
use crate::sdf::generate::Selection;
use crate::sdf::novelty::{Novelty, NoveltyReference};

/// The payload of a `cohort` job.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CohortPayload {
    /// The cohort to generate.
    pub cohort_id: i64,
}

/// The plan a stored cohort describes; `latents` are the model's training latents (needed
/// for spread selection only).
pub fn plan_for(
    cohort: &CohortRow,
    info: &ModelInfo,
    latents: Option<Arc<Vec<Vec<f32>>>>,
) -> anyhow::Result<CohortPlan> {
    let weights = match &cohort.weights {
        Some(json) => Some(serde_json::from_str(json).context("stored weights are not JSON")?),
        None => None,
    };
    Ok(CohortPlan {
        training_shapes: info.training_shape_count(),
        arity: cohort.arity as usize,
        weights,
        weighting: Weighting::parse(&cohort.weighting).context("stored weighting is unknown")?,
        seed: cohort.seed as u64,
        resolution: cohort.resolution as usize,
        selection: Selection::parse(&cohort.selection).context("stored selection is unknown")?,
        latent_noise: cohort.latent_noise,
        latents,
    })
}

pub(super) async fn run(
    ctx: &JobContext,
    job: &ClaimedJob,
    flag: &Arc<AtomicBool>,
) -> anyhow::Result<RunOutcome> {
    let payload: CohortPayload = serde_json::from_str(&job.payload).context("bad job payload")?;
    let cohort = db::cohorts::get(&ctx.pool, payload.cohort_id)
        .await?
        .with_context(|| format!("cohort {} no longer exists", payload.cohort_id))?;
    tracing::Span::current().record("cohort_id", cohort.cohort_id);
    let model = db::models::get(&ctx.pool, &cohort.model_id)
        .await?
        .with_context(|| format!("model {:?} no longer exists", cohort.model_id))?;
    let info: ModelInfo = serde_json::from_str(&model.manifest).context("bad model manifest")?;
    let model_dir = PathBuf::from(&model.dir_path);
    let latents = if cohort.selection == Selection::Spread.as_str() {
        let engine = ctx.engine.clone();
        let dir = model_dir.clone();
        let latents = spawn_background(move || engine.training_latents(&dir))
            .await
            .map_err(join_error)?
            .context("cannot read the training latents")?;
        anyhow::ensure!(
            latents.len() == info.training_shape_count(),
            "the engine returned {} latents for {} training shapes",
            latents.len(),
            info.training_shape_count()
        );
        Some(Arc::new(latents))
    } else {
        None
    };
    let plan = plan_for(&cohort, &info, latents)?;
    let anchor_ids: Vec<i64> = match &cohort.anchors {
        Some(json) => serde_json::from_str(json).context("stored anchors are not JSON")?,
        None => Vec::new(),
    };
    let anchors = match anchor_latents(&ctx.pool, &anchor_ids).await {
        Ok(a) => a,
        Err(e) if db::storage_fault_in(&e).is_some() => return Err(e),
        Err(e) => return Ok(RunOutcome::Failed(format!("anchors: {e:#}"))),
    };

    let stored: HashSet<i64> = db::shapes::existing_indices(&ctx.pool, cohort.cohort_id)
        .await?
        .into_iter()
        .collect();
    let mut done = stored.len() as i64;
    if done > 0 {
        tracing::info!(done, "resuming cohort");
    }
    let missing: Vec<i64> = (0..cohort.count).filter(|i| !stored.contains(i)).collect();
    let reference = match missing.is_empty() {
        true => None,
        false => match novelty_reference(ctx, &model_dir, plan.resolution, flag).await {
            Ok(r) => Some(r),
            Err(e) => {
                if let Some(stop) = stop_outcome(ctx, job.job_id, flag).await? {
                    return Ok(stop);
                }
                return Ok(RunOutcome::Failed(format!("training surfaces: {e:#}")));
            }
        },
    };
    let targeting = match (&cohort.targets, missing.is_empty()) {
        (Some(json), false) => match targeting(ctx, &cohort, &model, &info, json).await {
            Ok(t) => Some(Arc::new(t)),
            Err(e) => {
                if let Some(stop) = stop_outcome(ctx, job.job_id, flag).await? {
                    return Ok(stop);
                }
                return Ok(RunOutcome::Failed(format!("targets: {e:#}")));
            }
        },
        _ => None,
    };
    let attempts = match cohort.min_novelty {
        Some(_) => MAX_REDRAWS + 1,
        None => 1,
    };
    for index in missing {
        let reference = reference.clone().context("no novelty reference")?;
        if let Some(targeting) = &targeting {
            if let Some(stop) = stop_outcome(ctx, job.job_id, flag).await? {
                return Ok(stop);
            }
            let search = ShapeSearch {
                engine: ctx.engine.clone(),
                model_dir: model_dir.clone(),
                plan: plan.clone(),
                targeting: targeting.clone(),
                reference,
                min_novelty: cohort.min_novelty,
                cancel: flag.clone(),
                anchors: anchors.clone(),
            };
            let searched = match search_shape(search, index as u64).await {
                Ok(s) => s,
                Err(e) => {
                    if let Some(stop) = stop_outcome(ctx, job.job_id, flag).await? {
                        return Ok(stop);
                    }
                    return Ok(RunOutcome::Failed(format!("shape {index}: {e:#}")));
                }
            };
            let kept = searched.kept;
            let outcome = Outcome {
                redraws: 0,
                novelty_met: cohort
                    .min_novelty
                    .is_none_or(|m| kept.candidate.novelty.chamfer >= m),
                candidates: Some(i64::from(searched.candidates)),
                targets_met: Some(searched.met),
            };
            let finished = match finish(kept.candidate, Some(kept.anatomy)).await {
                Ok(f) => f,
                Err(e) => return Ok(RunOutcome::Failed(format!("shape {index}: {e:#}"))),
            };
            done += 1;
            commit_shape(ctx, job.job_id, &cohort, index, &finished, &outcome, done).await?;
            ctx.metrics.inc_shapes_generated();
            tracing::debug!(
                index,
                done,
                candidates = searched.candidates,
                met = searched.met,
                "targeted shape committed"
            );
            continue;
        }
        let mut best: Option<Candidate> = None;
        let mut redraws = 0;
        for attempt in 0..attempts {
            if let Some(stop) = stop_outcome(ctx, job.job_id, flag).await? {
                return Ok(stop);
            }
            let spec = force_anchors(plan.shape_spec_attempt(index as u64, attempt), &anchors);
            let generated = generate(
                ctx,
                model_dir.clone(),
                spec,
                reference.clone(),
                flag.clone(),
            )
            .await;
            let candidate = match generated {
                Ok(c) => c,
                Err(e) => {
                    if let Some(stop) = stop_outcome(ctx, job.job_id, flag).await? {
                        return Ok(stop);
                    }
                    return Ok(RunOutcome::Failed(format!("shape {index}: {e:#}")));
                }
            };
            redraws = attempt;
            let cd = candidate.novelty.chamfer;
            let met = cohort.min_novelty.is_none_or(|m| cd >= m);
            if best
                .as_ref()
                .is_none_or(|b| candidate.novelty.chamfer > b.novelty.chamfer)
            {
                best = Some(Candidate {
                    attempt,
                    ..candidate
                });
            }
            if met {
                break;
            }
            tracing::debug!(index, attempt, cd, "draw too close to a training shape");
        }
        let best = best.context("no draw was made")?;
        let met = cohort.min_novelty.is_none_or(|m| best.novelty.chamfer >= m);
        let finished = match finish(best, None).await {
            Ok(f) => f,
            Err(e) => return Ok(RunOutcome::Failed(format!("shape {index}: {e:#}"))),
        };
        done += 1;
        let outcome = Outcome {
            redraws: i64::from(redraws),
            novelty_met: met,
            candidates: None,
            targets_met: None,
        };
        commit_shape(ctx, job.job_id, &cohort, index, &finished, &outcome, done).await?;
        ctx.metrics.inc_shapes_generated();
        tracing::debug!(index, done, redraws, "shape committed");
    }
    let has_metrics = db::cohort_metrics::get(&ctx.pool, cohort.cohort_id)
        .await?
        .is_some();
    if !has_metrics && let Err(e) = compute_metrics(ctx, &cohort).await {
        if db::storage_fault_in(&e).is_some() {
            return Err(e.context("cannot store the pairwise metrics"));
        }
        return Ok(RunOutcome::Failed(format!("pairwise metrics: {e:#}")));
    }
    Ok(RunOutcome::Succeeded)
}

/// The search settings of a targeted cohort, with the model's training measurements
/// (stored with the model when the cohort was accepted).
async fn targeting(
    ctx: &JobContext,
    cohort: &CohortRow,
    model: &db::models::ModelRow,
    info: &ModelInfo,
    json: &str,
) -> anyhow::Result<Targeting> {
    let ranges: std::collections::BTreeMap<String, TargetRange> =
        serde_json::from_str(json).context("stored targets are not JSON")?;
    let targets = Targets::parse(&ranges)?;
    let training = training_anatomy(
        &ctx.pool,
        ctx.engine.clone(),
        &model.model_id,
        std::path::Path::new(&model.dir_path),
        info.training_shape_count(),
    )
    .await?;
    // A cohort accepted before the model was measured is checked here instead of at the edge.
    check_feasible(&targets, &training.shapes)?;
    let max_candidates = cohort.max_candidates.map_or(DEFAULT_MAX_CANDIDATES, |m| {
        m.clamp(1, i64::from(u32::MAX)) as u32
    });
    Ok(Targeting::new(
        targets,
        max_candidates,
        &training,
        cohort.arity as usize,
    ))
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
            anchor_id: id,
            latent,
            transform,
        });
    }
    Ok(out)
}

/// One draw of a shape with its distance to the training set.
pub(super) struct Candidate {
    pub(super) spec: ShapeSpec,
    pub(super) shape: GeneratedShape,
    pub(super) novelty: Novelty,
    pub(super) attempt: u32,
}

/// The kept draw, encoded for storage and measured.
struct Finished {
    candidate: Candidate,
    blob: Vec<u8>,
    sha: String,
    /// Measurements as JSON, or why they failed.
    anatomy: Result<String, String>,
}

/// How the kept draw was reached.
struct Outcome {
    redraws: i64,
    novelty_met: bool,
    /// Candidates drawn (targeted cohorts).
    candidates: Option<i64>,
    /// Whether the kept shape meets every target (targeted cohorts).
    targets_met: Option<bool>,
}

/// The model's training surfaces at the cohort's resolution, off the executor.
async fn novelty_reference(
    ctx: &JobContext,
    model_dir: &std::path::Path,
    resolution: usize,
    flag: &Arc<AtomicBool>,
) -> anyhow::Result<Arc<NoveltyReference>> {
    let engine = ctx.engine.clone();
    let dir = model_dir.to_path_buf();
    let flag = flag.clone();
    spawn_background(move || engine.novelty_reference(&dir, resolution, &flag))
        .await
        .map_err(join_error)?
}

/// Generates one draw and measures its novelty, off the executor.
async fn generate(
    ctx: &JobContext,
    model_dir: PathBuf,
    spec: ShapeSpec,
    reference: Arc<NoveltyReference>,
    flag: Arc<AtomicBool>,
) -> anyhow::Result<Candidate> {
    let engine = ctx.engine.clone();
    spawn_background(move || draw(&*engine, &model_dir, spec, &reference, &flag))
        .await
        .map_err(join_error)?
}

/// Generates one draw and measures its novelty (blocking).
pub(super) fn draw(
    engine: &dyn CohortEngine,
    model_dir: &std::path::Path,
    spec: ShapeSpec,
    reference: &NoveltyReference,
    flag: &AtomicBool,
) -> anyhow::Result<Candidate> {
    let shape = engine.generate_shape(model_dir, &spec, flag)?;
    shape
        .mesh_unit
        .validate()
        .context("engine returned an invalid mesh")?;
    let novelty = reference
        .novelty(&shape.mesh_unit, spec.seed)
        .context("novelty")?;
    anyhow::ensure!(
        novelty.chamfer.is_finite() && novelty.nearest < reference.len(),
        "novelty is not a finite distance to a training shape"
    );
    Ok(Candidate {
        spec,
        shape,
        novelty,
        attempt: 0,
    })
}

/// Encodes the kept draw and measures its anatomy in mm (unless `measured` already holds
/// it), off the executor.
async fn finish(
    candidate: Candidate,
    measured: Option<Result<ShapeAnatomy, String>>,
) -> anyhow::Result<Finished> {
    spawn_background(move || {
        let blob = mesh_blob::encode(&candidate.shape.mesh_unit);
        let sha = hex(&Sha256::digest(&blob));
        let shape = &candidate.shape;
        let measured = measured.unwrap_or_else(|| {
            let mesh_mm = shape.transform.mesh_to_mesh_units(&shape.mesh_unit);
            measure_shape(&mesh_mm).map_err(|e| e.to_string())
        });
        let anatomy = match measured {
            Ok(a) => Ok(serde_json::to_string(&a)?),
            Err(e) => Err(e),
        };
        Ok(Finished {
            candidate,
            blob,
            sha,
            anatomy,
        })
    })
    .await
    .map_err(join_error)?
}

/// Stores one shape and the job's progress in a single transaction.
async fn commit_shape(
    ctx: &JobContext,
    job_id: i64,
    cohort: &CohortRow,
    index: i64,
    finished: &Finished,
    outcome: &Outcome,
    done: i64,
) -> anyhow::Result<()> {
    let Candidate {
        spec,
        shape,
        novelty,
        attempt,
    } = &finished.candidate;
    let row = db::shapes::NewShape {
        cohort_id: cohort.cohort_id,
        shape_index: index,
        training_indices: &spec.training_indices,
        weights: &spec.weights,
        seed: spec.seed as i64,
        resolution: spec.resolution as i64,
        software_version: crate::VERSION,
        vertex_count: shape.mesh_unit.vertex_count() as i64,
        triangle_count: shape.mesh_unit.triangle_count() as i64,
        area_mm2: shape.area_mm2,
        volume_mm3: shape.volume_mm3,
        centre: shape.transform.centre,
        radius: shape.transform.radius,
        mesh: &finished.blob,
        mesh_sha256: &finished.sha,
        latent_noise: spec.latent_noise,
        selection: &cohort.selection,
        attempt: i64::from(*attempt),
        redraws: outcome.redraws,
        novelty_cd: Some(novelty.chamfer),
        nearest_training_index: Some(novelty.nearest as i64),
        novelty_met: Some(outcome.novelty_met),
        anatomy: finished.anatomy.as_deref().ok(),
        anatomy_error: finished.anatomy.as_ref().err().map(String::as_str),
        candidates: outcome.candidates,
        targets_met: outcome.targets_met,
    };
    let mut tx = ctx.pool.begin_with(db::BEGIN_WRITE).await?;
    let shape_id = db::shapes::insert(&mut tx, &row)
        .await
        .with_context(|| format!("cannot store shape {index}"))?;
    if !spec.anchors.is_empty() {
        let ids: Vec<i64> = spec.anchors.iter().map(|a| a.anchor_id).collect();
        db::anchors::set_shape_anchors(&mut tx, shape_id, &ids).await?;
    }
    db::jobs::set_progress(&mut tx, job_id, done).await?;
    tx.commit().await.context("cannot commit shape")?;
    Ok(())
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

/// Lower-case hexadecimal.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}
