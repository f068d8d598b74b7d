//! Tests of the science library and the command line, without the service: geometry and
//! marching cubes against analytic shapes, mesh formats and hostile files, the parametric
//! roots, anatomy against known parameters, training and fitting end to end on tiny models,
//! the bundled model, the cohort request rules as properties, and the report commands.
//! One binary, so the library is linked once for all of them.

mod anatomy;
mod bundled_model;
mod extract;
mod fit;
mod formats;
mod marching_cubes;
mod proptest_cohort_request;
mod report_cli;
mod simulation_cli;
mod synth_cli;
mod synth_intersect;
mod synth_params;
mod synth_render;
mod synth_surface;
mod training;
mod validate_cli;
mod validation;
