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
/// Density models of training latents (PCA Gaussian, PCA mixture) that draw new latents.
pub mod latent_models;
pub mod objects;
pub mod render;
pub mod report;
pub mod sdf;
/// Shape-level cohort metrics (MMD, COV, 1-NNA, DCR) on precomputed distance matrices.
pub mod shape_metrics;
pub mod simulation;
pub mod startup;
/// Population statistics for validating a virtual cohort against a real one.
pub mod stats;
pub mod synth;
pub mod telemetry;
pub mod validation;

/// Software version recorded in every artefact's provenance.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
