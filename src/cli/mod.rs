//! The `aortagen` command line: one subcommand per capability.

use clap::{Parser, Subcommand};

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
pub enum Command {}

/// Parses the process arguments and runs the chosen subcommand.
pub fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {}
}
