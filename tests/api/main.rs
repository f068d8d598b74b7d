//! End-to-end tests of the cohort service: a real server on port 0, a temporary SQLite file,
//! the analytic test engine, and jobs driven synchronously with `run_pending_jobs`.

mod access;
mod cohorts;
mod conditioned;
mod conformance;
mod cross_site;
mod dashboard;
mod engine;
mod errors;
mod fit;
mod helpers;
mod jobs;
mod limits;
mod models;
mod openapi;
mod pipeline;
mod reports;
mod science;
mod shapes;
mod storage;
