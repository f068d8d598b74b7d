//! The `aortagen` command line: one subcommand per capability.

use clap::{Parser, Subcommand};

pub mod mesh;

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
    /// Report a mesh file's counts, area, volume, closedness and extent; convert formats.
    Mesh(mesh::MeshArgs),
}

/// Parses the process arguments and runs the chosen subcommand.
pub fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Mesh(args) => mesh::run(args),
    }
}
