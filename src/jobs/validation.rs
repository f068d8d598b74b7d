//! The validation job, one task: a stored cohort compared with a reference population
//! (the model's held-out or training shapes, or an uploaded one) at the shape and the
//! measurement level ([`crate::validation`]); the report and its verdict are stored on the
//! validation row in the transaction that ends the job. A validation has no checkpoint: an
//! interrupted one starts again, and its seed makes the rerun give the same report.

use std::time::Duration;

use anyhow::{Context, bail};
use serde::{Deserialize, Serialize};

use super::{JobContext, JobError, TaskRun, lifecycle, run_with_progress, stopped};
use crate::db::{self, jobs::FinalStatus, references::ReferenceRow};
use crate::geometry::normalize::UnitBallTransform;
use crate::sdf::store::manifest::ModelManifest;
use crate::stats::bootstrap::{BandTestConfig, Discount};
use crate::validation::measures::MeasureSettings;
use crate::validation::shapes::Progress;
use crate::validation::sources::{ModelPopulations, mean_training_radius, model_populations};
use crate::validation::table::parse_table;
use crate::validation::{
    AcceptanceCriteria, Dossier, Newcomers, Population, ShapeInputs, ShapeSettings, StoredShape,
    Subject, ValidationInput, validate,
};

/// The payload of a `validation` job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValidationPayload {
    /// The validation row.
    pub validation_id: i64,
}

/// A validation request as stored, its defaults filled in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValidationSettings {
    /// `heldout`, `training`, or an uploaded reference's id.
    pub reference: String,
    /// Acceptance criteria (checked when the request was accepted).
    pub criteria: AcceptanceCriteria,
    /// The trial's context of use, for the dossier.
    pub context_of_use: Option<String>,
    /// The question of interest, for the dossier.
    pub question_of_interest: Option<String>,
    /// Surface samples per shape for the Chamfer distances.
    pub points: usize,
    /// Equal-size subsets of 1-NNA, MMD and COV.
    pub subsets: usize,
    /// Bootstrap resamples of the density-band test.
    pub resamples: usize,
    /// Its uncertainty discount.
    pub discount: Discount,
    /// Seed of the samplings, subsets and resamples.
    pub seed: u64,
}

/// How often the Chamfer distances done are copied to the job row.
const PROGRESS_INTERVAL: Duration = Duration::from_millis(500);

/// The reference and the model's own populations a validation compares.
struct Compared {
    reference: Population,
    reference_subject: Subject,
    ignored: Vec<(String, String)>,
    /// The model's manifest, when this machine can read it (scale, dossier).
    manifest: Option<ModelManifest>,
    /// The training shapes (DCR, baseline) and the held-out ones, when readable.
    model: Option<ModelPopulations>,
    /// Why the training shapes are missing.
    model_note: Option<String>,
}

impl Compared {
    fn shape_inputs<'a>(
        &'a self,
        cohort: &'a Population,
        reference_is_training: bool,
    ) -> ShapeInputs<'a> {
        let newcomers = match (reference_is_training, &self.model) {
            (false, _) => Newcomers::Reference,
            (
                true,
                Some(ModelPopulations {
                    heldout: Some(h), ..
                }),
            ) => Newcomers::Other(h),
            (true, _) => Newcomers::Missing("the model has no held-out shapes".into()),
        };
        ShapeInputs {
            cohort,
            reference: &self.reference,
            training: self.model.as_ref().map(|m| &m.training),
            reference_is_training,
            newcomers,
        }
    }
}

pub(super) async fn run(
    ctx: &JobContext,
    run: &TaskRun,
    payload: &ValidationPayload,
) -> Result<(), JobError> {
    stopped(&run.flag)?;
    let row = db::validations::get(&ctx.pool, payload.validation_id)
        .await?
        .with_context(|| format!("validation {} no longer exists", payload.validation_id))?;
    let settings: ValidationSettings =
        serde_json::from_str(&row.request).context("the stored validation request")?;
    let cohort = db::cohorts::get(&ctx.pool, row.cohort_id)
        .await?
        .with_context(|| format!("cohort {} no longer exists", row.cohort_id))?;
    tracing::Span::current().record("cohort_id", cohort.cohort_id);
    tracing::Span::current().record("model_id", cohort.model_id.as_str());
    let model = super::existing_model(&ctx.pool, &cohort.model_id).await?;
    let model_dir = ctx.model_dir(&model).await?;
    let cohort_population = load_cohort(ctx, &cohort).await?;
    let uploaded = match row.reference_id {
        Some(id) => Some(
            db::references::get(&ctx.pool, id)
                .await?
                .with_context(|| format!("reference {id} no longer exists"))?,
        ),
        None => None,
    };
    let stored = match &uploaded {
        Some(r) => Some(ctx.objects.require(&r.object_sha256).await?),
        None => None,
    };
    stopped(&run.flag)?;
    let cohort_subject = Subject {
        label: format!("cohort {}", cohort.cohort_id),
        id: Some(cohort.cohort_id),
        kind: "cohort".into(),
        shapes: cohort_population.len(),
        seed: Some(cohort.seed as u64),
        details: serde_json::json!({
            "model_id": cohort.model_id,
            "count": cohort.count,
            "arity": cohort.arity,
            "resolution": cohort.resolution,
            "seed": cohort.seed,
            "latent_noise": cohort.latent_noise,
            "min_novelty": cohort.min_novelty,
            "sampler": cohort.sampler,
        }),
        sha256: None,
    };
    // Without them a validation against an uploaded reference goes on without the
    // training shapes (and says so); one against the model's own shapes fails naming them.
    if let Err(e) = super::training::ensure_training_inputs(ctx, &model.model_id).await {
        tracing::warn!(
            error = format!("{e:#}"),
            "the model's training inputs are missing"
        );
    }
    let (settings_for_read, dir) = (settings.clone(), model_dir.clone());
    let compared = super::priority::spawn_background(move || {
        compared_populations(&settings_for_read, &dir, uploaded, stored)
    })
    .await
    .map_err(super::join_error)??;
    stopped(&run.flag)?;
    let criteria = settings
        .criteria
        .clone()
        .check()
        .map_err(|e| anyhow::anyhow!("criteria: {e}"))?;
    let reference_is_training = settings.reference == "training";
    // The common scale: the model's mean training radius, else the reference's, else the
    // cohort's.
    let scale_mm = compared
        .manifest
        .as_ref()
        .map(mean_training_radius)
        .or_else(|| compared.reference.mean_radius_mm())
        .or_else(|| cohort_population.mean_radius_mm())
        .unwrap_or(1.0);
    let mut ignored = compared.ignored.clone();
    if let Some(note) = &compared.model_note {
        ignored.push(("training shapes".into(), note.clone()));
    }
    let dossier = Dossier {
        context_of_use: settings.context_of_use.clone(),
        question_of_interest: settings.question_of_interest.clone(),
        model_id: compared
            .manifest
            .as_ref()
            .map_or_else(|| cohort.model_id.clone(), |m| m.model_id().to_owned()),
        model_sha256: compared.manifest.as_ref().map(|m| m.weights.sha256.clone()),
        software_version: crate::VERSION.into(),
        cohort: cohort_subject,
        reference: compared.reference_subject.clone(),
        criteria: criteria.given.clone(),
        computed_at: crate::validation::report::utc_now(),
    };
    // The Chamfer distances of the shape level; none against a table (no surfaces).
    let total = match compared.reference.has_surfaces() && cohort_population.has_surfaces() {
        true => compared
            .shape_inputs(&cohort_population, reference_is_training)
            .pairs(),
        false => 0,
    };
    {
        let mut conn = ctx.pool.acquire().await?;
        db::jobs::set_progress_total(&mut conn, run.lease.job_id, total as i64).await?;
    }
    let stop = run.flag.clone();
    let report = run_with_progress(ctx, run, PROGRESS_INTERVAL, move |done| {
        let input = ValidationInput {
            shapes: compared.shape_inputs(&cohort_population, reference_is_training),
            shape_settings: ShapeSettings {
                points: settings.points,
                scale_mm,
                seed: settings.seed,
                subsets: settings.subsets,
            },
            measure_settings: MeasureSettings {
                band: BandTestConfig {
                    resamples: settings.resamples,
                    discount: settings.discount,
                    seed: settings.seed,
                },
                tost_margins: criteria.tost_margins.clone(),
            },
            criteria: &criteria,
            ignored,
            dossier,
        };
        Ok(validate(
            input,
            Progress {
                done,
                stop: Some(&stop),
            },
        ))
    })
    .await?;
    stopped(&run.flag)?;
    let report = report.context("validating")?;
    let verdict = serde_json::to_value(report.verdict)
        .map_err(anyhow::Error::from)?
        .as_str()
        .unwrap_or("inconclusive")
        .to_owned();
    let json = serde_json::to_string(&report).map_err(anyhow::Error::from)?;
    let mut tx = db::begin_write(&ctx.pool).await?;
    db::tasks::complete(&mut tx, &run.lease).await?;
    db::validations::set_report(&mut tx, payload.validation_id, &json, &verdict).await?;
    lifecycle::finish_job(&mut tx, run.lease.job_id, FinalStatus::Succeeded, None).await?;
    tx.commit()
        .await
        .context("cannot commit the validation report")?;
    tracing::info!(verdict, "validation done");
    Ok(())
}

/// The cohort's shapes in mm with the measurements stored when they were made (measured
/// again when an earlier method made them).
async fn load_cohort(
    ctx: &JobContext,
    cohort: &db::cohorts::CohortRow,
) -> anyhow::Result<Population> {
    let rows = db::shapes::list_for_cohort(&ctx.pool, cohort.cohort_id, i64::MAX, 0).await?;
    if rows.len() < 2 {
        bail!(
            "cohort {} has {} stored shapes; a validation needs at least 2",
            cohort.cohort_id,
            rows.len()
        );
    }
    let mut shapes = Vec::with_capacity(rows.len());
    for row in rows {
        let bytes = ctx
            .objects
            .require(&row.mesh_sha256)
            .await
            .with_context(|| format!("the mesh of shape {}", row.shape_id))?;
        let unit = crate::formats::mesh_blob::decode(&bytes)
            .with_context(|| format!("the mesh of shape {}", row.shape_id))?;
        let transform = UnitBallTransform {
            centre: [row.centre_x, row.centre_y, row.centre_z],
            radius: row.radius,
        };
        shapes.push(StoredShape {
            name: format!("shape {}", row.shape_index),
            surface_mm: transform.mesh_to_mesh_units(&unit),
            anatomy: row.anatomy.map(|a| a.0),
            area_mm2: row.area_mm2,
            volume_mm3: row.volume_mm3,
        });
    }
    // Blocking: shapes measured by an earlier method are measured again.
    let label = format!("cohort {}", cohort.cohort_id);
    super::priority::spawn_background(move || Population::from_stored(label, shapes))
        .await
        .map_err(super::join_error)
}

/// Reads the reference and the model's training (and held-out) shapes. Blocking: the
/// model's data is read (or generated again) and every mesh measured.
fn compared_populations(
    settings: &ValidationSettings,
    model_dir: &std::path::Path,
    uploaded: Option<ReferenceRow>,
    stored: Option<Vec<u8>>,
) -> anyhow::Result<Compared> {
    let subject = |p: &Population, kind: &str, id, sha256| Subject {
        label: p.label.clone(),
        id,
        kind: kind.into(),
        shapes: p.len(),
        seed: None,
        details: serde_json::json!({ "reference": settings.reference }),
        sha256,
    };
    match (uploaded, stored) {
        (Some(row), Some(bytes)) => {
            let (reference, ignored) = uploaded_population(&row, &bytes)?;
            // The training shapes give DCR and the real-vs-real baseline; a model whose
            // data this machine cannot read is validated without them.
            let (model, model_note) = match model_populations(model_dir, None) {
                Ok(m) => (Some(m), None),
                Err(e) => (None, Some(format!("not available: {e:#}"))),
            };
            let manifest = match &model {
                Some(m) => Some(m.manifest.clone()),
                None => crate::sdf::store::read_manifest(model_dir).ok(),
            };
            Ok(Compared {
                reference_subject: subject(
                    &reference,
                    &row.kind,
                    Some(row.reference_id),
                    Some(row.object_sha256.clone()),
                ),
                reference,
                ignored,
                manifest,
                model,
                model_note,
            })
        }
        _ => {
            let m = model_populations(model_dir, None)
                .context("the model's training data (needed for its own reference populations)")?;
            let reference = match settings.reference.as_str() {
                "training" => m.training.clone(),
                _ => m
                    .heldout
                    .clone()
                    .context("the model has no held-out shapes (train it with a holdout)")?,
            };
            let sha = Some(m.manifest.data.dataset_key.clone());
            Ok(Compared {
                reference_subject: subject(&reference, &settings.reference, None, sha),
                reference,
                ignored: Vec::new(),
                manifest: Some(m.manifest.clone()),
                model: Some(m),
                model_note: None,
            })
        }
    }
}

/// An uploaded reference read back from its object: a bundle of canonical meshes in mm, or
/// the table's text.
fn uploaded_population(
    row: &ReferenceRow,
    bytes: &[u8],
) -> anyhow::Result<(Population, Vec<(String, String)>)> {
    let label = format!("reference {}: {}", row.reference_id, row.name);
    match row.kind.as_str() {
        "measurements" => {
            let text = std::str::from_utf8(bytes).context("the stored table is not UTF-8")?;
            let table = parse_table(&label, text).map_err(|e| anyhow::anyhow!("{e}"))?;
            Ok((table.population, table.ignored))
        }
        _ => {
            let mut meshes = Vec::new();
            for (name, mesh) in crate::objects::bundle::files(bytes)? {
                let mesh = crate::formats::mesh_blob::decode(mesh)
                    .with_context(|| format!("the stored mesh {name}"))?;
                meshes.push((display_name(&name).to_owned(), mesh));
            }
            Ok((Population::from_meshes(label, meshes), Vec::new()))
        }
    }
}

/// A stored member's name without the ordering prefix (`0003-patient.stl` → `patient.stl`).
fn display_name(stored: &str) -> &str {
    match stored.split_once('-') {
        Some((index, rest)) if index.len() == 4 && index.bytes().all(|b| b.is_ascii_digit()) => {
            rest
        }
        _ => stored,
    }
}

#[cfg(test)]
mod tests {
    use super::display_name;

    #[test]
    fn stored_member_names_lose_only_their_ordering_prefix() {
        assert_eq!(display_name("0003-patient.stl"), "patient.stl");
        assert_eq!(display_name("0003-a-b.ply"), "a-b.ply");
        assert_eq!(display_name("abcd-x.ply"), "abcd-x.ply");
        assert_eq!(display_name("plain.obj"), "plain.obj");
    }
}
