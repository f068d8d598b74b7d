//! The `aortagen` command line: one subcommand per capability.

use clap::{Parser, Subcommand};

pub mod measure;
pub mod render;
pub mod synth;

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
    /// Measure a vessel surface: centreline length, diameter profile, root landmarks.
    Measure(measure::MeasureArgs),
}

/// Parses the process arguments and runs the chosen subcommand.
pub fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Synth(args) => synth::run(args),
        Command::Render(args) => render::run(args),
        Command::Measure(args) => measure::run(args),
    }
}
