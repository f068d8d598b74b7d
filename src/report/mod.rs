//! Reports people look at: distributions as SVG plots and whole reports as one
//! self-contained HTML page, for models (reconstruction fidelity) and cohorts (diversity).
//! Served by the API and written by `aortagen report`.

pub mod figures;
pub mod html;
pub mod plot;
pub mod sections;
pub mod validation;

pub use html::{Report, Section, render_html};
pub use plot::{HistogramPlot, Marker, Series, histogram_svg, overlay_svg};

/// The footer every report carries: software version and units.
pub fn footer() -> String {
    format!(
        "aortagen {}. Chamfer distances are squared distances in unit-ball coordinates; \
         lengths, areas and volumes in the meshes' units (mm for generated shapes).",
        crate::VERSION
    )
}
