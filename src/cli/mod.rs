//! The `aortagen` command line: one subcommand per capability.

use clap::{Parser, Subcommand};

pub mod compare;
pub mod evaluate;
pub mod fit;
pub mod generate;
pub mod measure;
pub mod mesh;
pub mod migrate;
pub mod progress;
pub mod refit;
pub mod render;
pub mod report;
pub mod serve;
pub mod simulate;
pub mod synth;
pub mod train;
pub mod validate;
pub mod worker;

/// Generative models of aortic shapes and synthetic cohorts for in-silico trials.
#[derive(Debug, Parser)]
#[command(name = "aortagen", version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Generate parametric aortic roots with their ground-truth parameters.
    Synth(synth::SynthArgs),
    /// Render meshes side by side into a PNG.
    Render(render::RenderArgs),
    /// Train a neural SDF auto-decoder on a mesh directory or parametric roots.
    Train(train::TrainArgs),
    /// Reconstruct every training shape and report its Chamfer distance.
    Evaluate(evaluate::EvaluateArgs),
    /// Fit a latent to a new mesh (network frozen) and keep it as an anchor of the model.
    Fit(fit::FitArgs),
    /// Fit every training shape again with the network frozen, as a new patient is fitted,
    /// for density samplers that draw like new patients (`generate --latents refitted`).
    Refit(refit::RefitArgs),
    /// Generate shapes as convex combinations of learned latents.
    Generate(generate::GenerateArgs),
    /// Report a mesh file's counts, area, volume, closedness and extent; convert formats.
    Mesh(mesh::MeshArgs),
    /// Run the cohort service: REST API and job workers on SQLite or PostgreSQL.
    Serve(serve::ServeArgs),
    /// Run job workers only (no API), against the database the service uses.
    Worker(worker::WorkerArgs),
    /// Bring the database's schema to this version and exit.
    Migrate(migrate::MigrateArgs),
    /// Measure a vessel surface: centreline length, diameter profile, root landmarks.
    Measure(measure::MeasureArgs),
    /// Write an HTML report with SVG plots of a model or a directory of meshes.
    Report(report::ReportArgs),
    /// Compare the diversity and novelty of generated cohorts side by side.
    Compare(compare::CompareArgs),
    /// Validate a generated cohort against a real population (held-out or training shapes,
    /// patient meshes, or a measurements table), with acceptance criteria.
    Validate(validate::ValidateArgs),
}

/// Parses the process arguments and runs the chosen subcommand.
pub fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Synth(args) => synth::run(args),
        Command::Render(args) => render::run(args),
        Command::Train(args) => train::run(args),
        Command::Evaluate(args) => evaluate::run(args),
        Command::Fit(args) => fit::run(args),
        Command::Refit(args) => refit::run(args),
        Command::Generate(args) => generate::run(args),
        Command::Mesh(args) => mesh::run(args),
        Command::Serve(args) => serve::run(args),
        Command::Worker(args) => worker::run(args),
        Command::Migrate(args) => migrate::run(args),
        Command::Measure(args) => measure::run(args),
        Command::Report(args) => report::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Validate(args) => validate::run(args),
    }
}
