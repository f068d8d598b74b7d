//! End-to-end tests of the cohort service: a real server on port 0, a temporary SQLite file,
//! the analytic test engine, and jobs driven synchronously with `run_pending_jobs`.

mod cohorts;
mod engine;
mod errors;
mod helpers;
mod jobs;
mod models;
mod openapi;
mod science;
mod shapes;
