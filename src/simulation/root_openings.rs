//! Openings of an aortic root, placed from its landmarks: the inlet on (or a stated distance
//! below) the annulus plane, the outlet a stated distance above the sinotubular junction,
//! both perpendicular to the measured centreline.

use super::SimulationError;
use super::opening::{FIRST_OUTLET_ID, INLET_ID, Opening, OpeningOptions};
use crate::anatomy::centreline::Centreline;
use crate::anatomy::root::measure_prepared_root;
use crate::anatomy::surface::Surface;

/// The inlet and outlet of an aortic-root surface in millimetres.
pub fn root_openings(
    surface: &Surface,
    opts: &OpeningOptions,
) -> Result<Vec<Opening>, SimulationError> {
    opts.validate()?;
    let (_, landmarks, _, line) = measure_prepared_root(surface)?;
    // σ runs from the inlet end; s is the centreline's own arc length.
    let towards_outlet = if landmarks.inlet_at_start { 1.0 } else { -1.0 };
    let inlet_s = landmarks.annulus_s_mm - towards_outlet * opts.inlet_below_annulus_mm;
    let outlet_s = landmarks.stj_s_mm + towards_outlet * opts.outlet_above_stj_mm;
    let inlet = opening_at(surface, &line, inlet_s, -towards_outlet, INLET_ID, "inlet")?;
    let outlet = opening_at(
        surface,
        &line,
        outlet_s,
        towards_outlet,
        FIRST_OUTLET_ID,
        "outlet",
    )?;
    Ok(vec![inlet, outlet])
}

/// The opening at arc length `s`, its normal along `sign` × the centreline tangent.
fn opening_at(
    surface: &Surface,
    line: &Centreline,
    s: f64,
    sign: f64,
    id: u32,
    name: &str,
) -> Result<Opening, SimulationError> {
    let outside = |message: String| SimulationError::OutsideVessel {
        opening: name.to_owned(),
        message,
    };
    if !(0.0..=line.length()).contains(&s) {
        return Err(outside(format!(
            "it would sit {s:.1} mm along a centreline of {:.1} mm",
            line.length()
        )));
    }
    let (centre, tangent) = line.frame_at(s);
    let section = surface.wall_section_at(centre, tangent).ok_or_else(|| {
        outside(format!(
            "no closed wall section at {s:.1} mm along the centreline (the plane reaches the \
             closed end of the surface)"
        ))
    })?;
    Ok(Opening {
        id,
        name: name.to_owned(),
        origin: section.centroid,
        normal: tangent.map(|c| sign * c),
        radius_mm: (section.area / std::f64::consts::PI).sqrt(),
    })
}
