//! aortagen: learns a generative neural signed-distance model of aortic shapes and serves
//! synthetic patient cohorts for in-silico trials.
//!
//! The modules follow the architecture: pure geometry at the bottom, the learned model
//! above it, and the command line (and later the HTTP service) on top.

pub mod anatomy;
pub mod cli;
pub mod cohort;
pub mod config;
pub mod db;
pub mod digest;
pub mod engine;
pub mod extract;
pub mod formats;
pub mod geometry;
pub mod http;
pub mod jobs;
pub mod render;
pub mod report;
pub mod sdf;
pub mod simulation;
pub mod startup;
pub mod synth;
pub mod telemetry;

/// Software version recorded in every artefact's provenance.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
