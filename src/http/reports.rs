//! Plots (`image/svg+xml`) and self-contained HTML reports of models and cohorts, built
//! from what is stored: a model's evaluation, a cohort's shapes and pairwise metrics.

use std::path::Path as FsPath;

use axum::extract::{Path, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::error::{ApiError, Problem, Result};
use super::extractors::parse_id;
use super::rendering::render_off_executor;
use crate::anatomy::shape::ShapeAnatomy;
use crate::db;
use crate::db::cohorts::CohortRow;
use crate::db::shapes::ShapeRow;
use crate::engine::read_evaluation;
use crate::jobs::stats::PairDistances;
use crate::report::{Report, Section, footer, render_html, sections};

/// Plots of a model, by name.
pub const MODEL_PLOTS: [&str; 1] = ["reconstruction-cd"];
/// Plots of a cohort, by name.
pub const COHORT_PLOTS: [&str; 9] = [
    "pairwise-cd",
    "novelty-cd",
    "annulus",
    "sinus",
    "stj",
    "sinus-height",
    "length",
    "area",
    "volume",
];

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(model_plot))
        .routes(routes!(model_report))
        .routes(routes!(cohort_plot))
        .routes(routes!(cohort_report))
}

/// A plot of a model as SVG: `reconstruction-cd` (the training shapes' reconstruction
/// Chamfer distances with the sampling floor).
#[utoipa::path(get, path = "/v1/models/{id}/plots/{plot}", tag = "reports",
    params(("id" = String, Path, description = "Model id"),
           ("plot" = String, Path, description = "Plot name: reconstruction-cd")),
    responses((status = 200, content_type = "image/svg+xml", body = String),
              (status = 404, body = Problem, content_type = "application/problem+json", description = "Unknown model or plot")))]
async fn model_plot(
    State(state): State<AppState>,
    Path((id, plot)): Path<(String, String)>,
) -> Result<Response> {
    let position = plot_position(&plot, &MODEL_PLOTS)?;
    let (_, inputs) = model_inputs(&state, &id).await?;
    render_off_executor(move || {
        let mut sections = inputs.sections();
        Ok(svg(sections.swap_remove(position).svg))
    })
    .await
}

/// The model's report as one self-contained HTML page.
#[utoipa::path(get, path = "/v1/models/{id}/report", tag = "reports",
    params(("id" = String, Path, description = "Model id")),
    responses((status = 200, content_type = "text/html", body = String),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn model_report(State(state): State<AppState>, Path(id): Path<String>) -> Result<Response> {
    let (facts, inputs) = model_inputs(&state, &id).await?;
    render_off_executor(move || {
        Ok(html(&Report {
            title: format!("Model {id}"),
            facts,
            sections: inputs.sections(),
            footer: footer(),
        }))
    })
    .await
}

/// A plot of a cohort as SVG: `pairwise-cd` (the seed paper's Fig. 3), `novelty-cd`
/// (distance of each shape to its nearest training shape), the anatomical measurements
/// `annulus`, `sinus`, `stj`, `sinus-height`, `length` (mm), `area` or `volume` (per shape,
/// mm² / mm³). A cohort still running shows the shapes done so far.
#[utoipa::path(get, path = "/v1/cohorts/{id}/plots/{plot}", tag = "reports",
    params(("id" = i64, Path, description = "Cohort id"),
           ("plot" = String, Path, description = "Plot name: pairwise-cd, novelty-cd, annulus, sinus, stj, sinus-height, length, area or volume")),
    responses((status = 200, content_type = "image/svg+xml", body = String),
              (status = 404, body = Problem, content_type = "application/problem+json", description = "Unknown cohort or plot")))]
async fn cohort_plot(
    State(state): State<AppState>,
    Path((id, plot)): Path<(String, String)>,
) -> Result<Response> {
    let position = plot_position(&plot, &COHORT_PLOTS)?;
    let cohort = load_cohort(&state, &id).await?;
    let inputs = cohort_inputs(&state, &cohort).await?;
    render_off_executor(move || {
        let mut sections = inputs.sections(cohort.min_novelty)?;
        Ok(svg(sections.swap_remove(position).svg))
    })
    .await
}

/// The cohort's report as one self-contained HTML page.
#[utoipa::path(get, path = "/v1/cohorts/{id}/report", tag = "reports",
    params(("id" = i64, Path, description = "Cohort id")),
    responses((status = 200, content_type = "text/html", body = String),
              (status = 404, body = Problem, content_type = "application/problem+json")))]
async fn cohort_report(State(state): State<AppState>, Path(id): Path<String>) -> Result<Response> {
    let cohort = load_cohort(&state, &id).await?;
    let inputs = cohort_inputs(&state, &cohort).await?;
    let weights = match &cohort.weights {
        Some(w) => serde_json::to_string(&w.0).map_err(anyhow::Error::from)?,
        None => cohort.weighting.as_str().to_owned(),
    };
    let facts = vec![
        ("model".to_owned(), cohort.model_id.clone()),
        ("status".into(), cohort.status.to_string()),
        (
            "shapes".into(),
            format!("{} of {}", cohort.shapes_done, cohort.count),
        ),
        ("arity".into(), cohort.arity.to_string()),
        ("weights".into(), weights),
        ("selection".into(), cohort.selection.as_str().to_owned()),
        ("latent noise".into(), cohort.latent_noise.to_string()),
        (
            "minimum novelty".into(),
            cohort.min_novelty.map_or("none".into(), |v| v.to_string()),
        ),
        ("seed".into(), cohort.seed.to_string()),
        ("resolution".into(), format!("{}³", cohort.resolution)),
        ("created".into(), cohort.created_at.clone()),
    ];
    render_off_executor(move || {
        Ok(html(&Report {
            title: format!("Cohort {}", cohort.cohort_id),
            facts,
            sections: inputs.sections(cohort.min_novelty)?,
            footer: footer(),
        }))
    })
    .await
}

/// What a model's sections are drawn from (read on the executor, drawn off it).
struct ModelInputs {
    cds: Vec<f64>,
    floor: Option<f64>,
}

impl ModelInputs {
    /// The sections of a model report, in [`MODEL_PLOTS`] order.
    fn sections(&self) -> Vec<Section> {
        vec![sections::reconstruction_cd(&self.cds, self.floor)]
    }
}

/// Facts of a model report and what its sections are drawn from.
async fn model_inputs(state: &AppState, id: &str) -> Result<(Vec<(String, String)>, ModelInputs)> {
    let row = db::models::get(&state.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("model", id))?;
    let info = row.info();
    let shapes = info.map(|i| i.training_shapes.clone()).unwrap_or_default();
    let cds: Vec<f64> = shapes.iter().filter_map(|s| s.reconstruction_cd).collect();
    let dir = state.jobs.model_dir(&row).await?;
    let floor = tokio::task::spawn_blocking(move || {
        read_evaluation(FsPath::new(&dir)).map(|e| e.sampling_floor_median)
    })
    .await
    .map_err(anyhow::Error::from)?;
    let facts = vec![
        ("status".to_owned(), row.status.to_string()),
        ("training shapes".into(), shapes.len().to_string()),
        (
            "latent dimension".into(),
            info.map_or("?".into(), |i| i.latent_dim.to_string()),
        ),
        ("registered".into(), row.created_at.clone()),
    ];
    Ok((facts, ModelInputs { cds, floor }))
}

/// What a cohort's sections are drawn from: its stored pairwise matrix (JSON, parsed off the
/// executor with the rest) and its shapes.
struct CohortInputs {
    matrix: Option<String>,
    shapes: Vec<ShapeRow>,
}

/// Reads what a cohort's sections are drawn from.
async fn cohort_inputs(state: &AppState, cohort: &CohortRow) -> Result<CohortInputs> {
    let matrix = db::cohort_metrics::get(&state.pool, cohort.cohort_id)
        .await?
        .map(|row| row.matrix);
    let shapes = db::shapes::list_for_cohort(&state.pool, cohort.cohort_id, i64::MAX, 0).await?;
    Ok(CohortInputs { matrix, shapes })
}

impl CohortInputs {
    /// The sections of a cohort report, in [`COHORT_PLOTS`] order.
    fn sections(&self, min_novelty: Option<f64>) -> Result<Vec<Section>> {
        let distances: Option<PairDistances> = match &self.matrix {
            Some(json) => Some(serde_json::from_str(json).map_err(anyhow::Error::from)?),
            None => None,
        };
        let pairwise = match &distances {
            None => sections::pairwise_cd(&[], None),
            Some(d) => sections::pairwise_cd(&d.values(), d.is_sampled().then(|| d.population())),
        };
        cohort_sections(pairwise, &self.shapes, min_novelty)
    }
}

/// Sections of a cohort report, in [`COHORT_PLOTS`] order.
fn cohort_sections(
    pairwise: Section,
    shapes: &[ShapeRow],
    min_novelty: Option<f64>,
) -> Result<Vec<Section>> {
    let novelty: Vec<f64> = shapes.iter().filter_map(|s| s.novelty_cd).collect();
    let anatomy: Vec<ShapeAnatomy> = shapes
        .iter()
        .filter_map(|s| s.anatomy.as_ref().map(|a| a.0.clone()))
        .collect();
    let measured = |f: fn(&ShapeAnatomy) -> Option<f64>| -> Vec<f64> {
        anatomy.iter().filter_map(f).collect()
    };
    let area: Vec<f64> = shapes.iter().map(|s| s.area_mm2).collect();
    let volume: Vec<f64> = shapes.iter().map(|s| s.volume_mm3).collect();
    let floor = sections::novelty_floor(min_novelty);
    let mm = |heading: &str, what: &str, values: &[f64]| {
        sections::distribution(
            heading,
            &format!("{what} of each generated shape, measured on its centreline (mm)."),
            &format!("{} (mm)", heading.to_lowercase()),
            values,
            &[],
        )
    };
    Ok(vec![
        pairwise,
        sections::novelty_cd(&novelty, floor.as_slice()),
        mm(
            "Annulus diameter",
            "Mean annulus diameter",
            &measured(|a| a.annulus_mm),
        ),
        mm(
            "Sinus diameter",
            "Sinus-of-Valsalva diameter",
            &measured(|a| a.sinus_mm),
        ),
        mm(
            "STJ diameter",
            "Sinotubular-junction diameter",
            &measured(|a| a.stj_mm),
        ),
        mm(
            "Sinus height",
            "Annulus-to-junction distance",
            &measured(|a| a.sinus_height_mm),
        ),
        mm(
            "Centreline length",
            "Centreline length",
            &measured(|a| Some(a.length_mm)),
        ),
        sections::distribution(
            "Surface area",
            "Area of each generated surface in millimetres (training frame restored).",
            "area (mm²)",
            &area,
            &[],
        ),
        sections::distribution(
            "Enclosed volume",
            "Volume enclosed by each generated surface (closed meshes), in millimetres.",
            "volume (mm³)",
            &volume,
            &[],
        ),
    ])
}

async fn load_cohort(state: &AppState, raw: &str) -> Result<CohortRow> {
    let id = parse_id("cohort", raw)?;
    db::cohorts::get(&state.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("cohort", raw))
}

/// Index of `plot` (with or without `.svg`) among the `known` plot names, in section order.
fn plot_position(plot: &str, known: &[&str]) -> Result<usize> {
    let name = plot.trim_end_matches(".svg");
    known.iter().position(|p| *p == name).ok_or_else(|| {
        ApiError::not_found("plot", format!("{plot} (available: {})", known.join(", ")))
    })
}

fn svg(body: String) -> Response {
    ([(header::CONTENT_TYPE, "image/svg+xml")], body).into_response()
}

fn html(report: &Report) -> Response {
    (
        [(header::CONTENT_TYPE, "text/html; charset=utf-8")],
        render_html(report),
    )
        .into_response()
}
