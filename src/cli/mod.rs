//! The `aortagen` command line: one subcommand per capability.

pub mod serve;

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
pub enum Command {
    /// Run the cohort service: REST API and job workers on a SQLite database.
    Serve(serve::ServeArgs),
}

/// Parses the process arguments and runs the chosen subcommand.
pub fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Serve(args) => serve::run(args),
    }
}
