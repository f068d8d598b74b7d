//! Plots (SVG) and HTML reports of models and cohorts.

use axum::http::StatusCode;

use crate::helpers::{MODEL, TestApp, cohort_body, spawn_app};

fn text(body: &[u8]) -> &str {
    std::str::from_utf8(body).expect("UTF-8")
}

async fn svg(app: &TestApp, path: &str) -> String {
    let r = app.get(path).await;
    assert_eq!(r.status, StatusCode::OK, "{path}: {}", text(&r.body));
    assert_eq!(r.header("content-type"), Some("image/svg+xml"));
    let body = text(&r.body).to_owned();
    assert!(
        body.starts_with("<svg") && body.trim_end().ends_with("</svg>"),
        "{body}"
    );
    body
}

#[tokio::test]
async fn cohort_plots_count_every_pair_and_every_shape() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(4, 2)).await;
    // Before the job ran there is nothing to plot yet, and the plot says so.
    let pending = svg(&app, &format!("/v1/cohorts/{id}/plots/pairwise-cd")).await;
    assert!(pending.contains("no data yet"), "{pending}");

    app.run_pending_jobs().await;
    let pairwise = svg(&app, &format!("/v1/cohorts/{id}/plots/pairwise-cd")).await;
    assert!(
        pairwise.contains("(n = 6)"),
        "4 shapes have 6 pairs: {pairwise}"
    );
    let area = svg(&app, &format!("/v1/cohorts/{id}/plots/area.svg")).await;
    assert!(area.contains("Surface area (n = 4)"));
    let volume = svg(&app, &format!("/v1/cohorts/{id}/plots/volume")).await;
    assert!(volume.contains("Enclosed volume (n = 4)"));
    let novelty = svg(&app, &format!("/v1/cohorts/{id}/plots/novelty-cd")).await;
    assert!(
        novelty.contains("(n = 4)"),
        "every shape has a novelty: {novelty}"
    );
    // The test shapes are measured as roots (see the science tests): one annulus each.
    let shapes = app.get(&format!("/v1/cohorts/{id}/shapes")).await.json();
    let measured = shapes["items"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["anatomy"]["annulus_mm"].is_number())
        .count();
    let annulus = svg(&app, &format!("/v1/cohorts/{id}/plots/annulus")).await;
    assert!(
        annulus.contains(&format!("Annulus diameter (n = {measured})")),
        "{annulus}"
    );
}

#[tokio::test]
async fn a_cohort_report_is_one_self_contained_page() {
    let app = spawn_app().await;
    let id = app.create_cohort_ok(&cohort_body(3, 2)).await;
    app.run_pending_jobs().await;
    let r = app.get(&format!("/v1/cohorts/{id}/report")).await;
    assert_eq!(r.status, StatusCode::OK);
    assert_eq!(r.header("content-type"), Some("text/html; charset=utf-8"));
    let html = text(&r.body);
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(html.contains(&format!("<h1>Cohort {id}</h1>")));
    assert_eq!(html.matches("<svg").count(), 9);
    assert!(html.contains("3 of 3") && html.contains(MODEL));
    // Nothing to fetch: no scripts, no linked resources.
    assert!(!html.contains("<script") && !html.contains(" src=") && !html.contains("href="));
}

#[tokio::test]
async fn a_model_report_shows_each_training_reconstruction() {
    let app = spawn_app().await;
    let shapes = app.get(&format!("/v1/models/{MODEL}/shapes")).await.json();
    let n = shapes.as_array().unwrap().len();
    assert!(n > 0);
    let plot = svg(&app, &format!("/v1/models/{MODEL}/plots/reconstruction-cd")).await;
    assert!(plot.contains(&format!("(n = {n})")), "{plot}");
    let r = app.get(&format!("/v1/models/{MODEL}/report")).await;
    assert_eq!(r.status, StatusCode::OK);
    let html = text(&r.body);
    assert!(html.contains("Reconstruction Chamfer distance"));
    assert!(html.contains(&format!("<td>training shapes</td><td>{n}</td>")));
}

#[tokio::test]
async fn unknown_subjects_and_plots_are_404_naming_the_choices() {
    let app = spawn_app().await;
    let r = app.get(&format!("/v1/models/{MODEL}/plots/loss")).await;
    assert_eq!(r.status, StatusCode::NOT_FOUND);
    assert_eq!(r.header("content-type"), Some("application/problem+json"));
    assert!(r.detail().contains("reconstruction-cd"));
    let r = app.get("/v1/cohorts/1/plots/histogram").await;
    assert!(r.detail().contains("pairwise-cd, novelty-cd, annulus"));
    assert_eq!(
        app.get("/v1/models/nope/report").await.status,
        StatusCode::NOT_FOUND
    );
    assert_eq!(
        app.get("/v1/cohorts/999/report").await.status,
        StatusCode::NOT_FOUND
    );
    assert_eq!(
        app.get("/v1/cohorts/999/plots/area").await.status,
        StatusCode::NOT_FOUND
    );
}
