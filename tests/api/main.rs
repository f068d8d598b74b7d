//! End-to-end tests of the cohort service: a real server on port 0, a temporary SQLite file,
//! the analytic test engine (or the bundled model), and jobs driven synchronously with
//! `run_pending_jobs`; and the released binary itself, killed and stopped mid-cohort
//! ([`crash_safety`], [`graceful_shutdown`] through [`process`]).

mod access;
mod cohorts;
mod conditioned;
mod conformance;
mod connections;
mod contract;
mod crash_safety;
mod cross_site;
mod dashboard;
mod engine;
mod errors;
mod fit;
mod graceful_shutdown;
mod helpers;
mod jobs;
mod leases;
mod limits;
mod models;
mod object_store;
mod openapi;
mod pipeline;
mod process;
mod refits;
mod reports;
mod resume;
mod schema;
mod science;
mod shapes;
mod simulation;
mod storage;
mod validations;
