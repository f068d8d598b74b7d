//! The parameters of a simulation mesh as callers give them — the service's query string,
//! the cohort export's body and the command line's flags — checked once, before any
//! geometry runs, with every error naming the parameter at fault.
//!
//! `openings` chooses between the surface as generated (`closed`, the plain mesh formats)
//! and the two simulation variants (`capped`, `open`); the other parameters are the
//! [`SimulationOptions`] of the pipeline and only apply to the simulation variants.

use serde::{Deserialize, Serialize};

use super::SimulationError;
use super::export::{SimulationFormat, Variant};
use super::opening::{OpeningOptions, ShapeKind};
use super::pipeline::SimulationOptions;
use super::remesh::RemeshOptions;
use crate::formats::MeshFormat;

/// Largest flow extension, in diameters of its opening.
pub const MAX_EXTENSION_DIAMETERS: f64 = 20.0;

/// The parameters as given; `None` means the default.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SimulationParams {
    /// `closed` (the generated surface), `capped` or `open`.
    pub openings: Option<String>,
    /// `root`, `aorta`, `tube`, or `auto` (decided from the shape).
    pub kind: Option<String>,
    /// Target edge length of an isotropic remesh, mm.
    pub remesh_mm: Option<f64>,
    /// Flow-extension length in diameters of each opening.
    pub extension_diameters: Option<f64>,
    /// Root inlet below the annulus, mm.
    pub inlet_below_annulus_mm: Option<f64>,
    /// Root outlet above the sinotubular junction, mm.
    pub outlet_above_stj_mm: Option<f64>,
    /// Aorta and tube: inlet and main outlet in from the ends, mm.
    pub end_trim_mm: Option<f64>,
    /// Aorta: branch outlets in from the branch ends, mm.
    pub branch_trim_mm: Option<f64>,
}

/// A parameter that cannot be used, named.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct ParamError {
    /// The parameter (`format`, `openings`, `remesh_mm`, …).
    pub field: &'static str,
    /// What is wrong with it.
    pub message: String,
}

impl ParamError {
    fn new(field: &'static str, message: impl Into<String>) -> Self {
        Self {
            field,
            message: message.into(),
        }
    }
}

impl From<SimulationError> for ParamError {
    fn from(e: SimulationError) -> Self {
        match e {
            SimulationError::BadOption { field, message } => Self::new(field, message),
            other => Self::new("openings", other.to_string()),
        }
    }
}

/// A simulation variant with every option checked.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulationRequest {
    /// Capped or open.
    pub variant: Variant,
    /// What the pipeline does.
    pub options: SimulationOptions,
}

impl SimulationRequest {
    /// The options as canonical JSON: equal options give equal text, so it keys caches.
    /// The variant is not part of it: both variants come from one computation.
    pub fn options_key(&self) -> String {
        serde_json::to_string(&self.options).expect("options serialise")
    }
}

/// What a mesh download (or export) is: the generated surface in a plain format, or a
/// simulation variant in a simulation format.
#[derive(Debug, Clone, PartialEq)]
pub enum MeshRequest {
    /// The closed surface as generated.
    Closed(MeshFormat),
    /// A capped or open simulation mesh.
    Simulation {
        /// File format.
        format: SimulationFormat,
        /// Variant and options.
        request: SimulationRequest,
    },
}

impl MeshRequest {
    /// Checks `format` with the other parameters. Without `openings` the plain formats
    /// (`glb` by default) give the closed surface and `vtp`/`vtk` the capped mesh.
    pub fn parse(format: Option<&str>, params: &SimulationParams) -> Result<Self, ParamError> {
        let format = format.map(|f| f.trim().to_ascii_lowercase());
        let simulation_only = matches!(format.as_deref(), Some("vtp" | "vtk"));
        let openings = match params.openings.as_deref().map(str::trim) {
            None if simulation_only => "capped",
            None => "closed",
            Some(o) => o,
        };
        let variant = match openings {
            "closed" => None,
            "capped" => Some(Variant::Capped),
            "open" => Some(Variant::Open),
            other => {
                return Err(ParamError::new(
                    "openings",
                    format!("unknown value {other:?}; use closed, capped or open"),
                ));
            }
        };
        let Some(variant) = variant else {
            reject_simulation_options(params)?;
            return closed_format(format.as_deref()).map(Self::Closed);
        };
        let format = simulation_format(format.as_deref().unwrap_or("vtp"), variant)?;
        let request = SimulationRequest {
            variant,
            options: parse_options(params)?,
        };
        Ok(Self::Simulation { format, request })
    }
}

fn closed_format(format: Option<&str>) -> Result<MeshFormat, ParamError> {
    match format {
        None => Ok(MeshFormat::Glb),
        Some("vtp" | "vtk") => Err(ParamError::new(
            "format",
            "vtp and vtk carry face labels and are written for openings=capped or open",
        )),
        Some(f) => f.parse().map_err(|_| {
            ParamError::new(
                "format",
                format!("unknown mesh format {f:?}; use glb, gltf, stl, obj, ply, vtp or vtk"),
            )
        }),
    }
}

fn simulation_format(format: &str, variant: Variant) -> Result<SimulationFormat, ParamError> {
    SimulationFormat::ALL
        .into_iter()
        .find(|f| f.extension() == format)
        .ok_or_else(|| {
            let openings = match variant {
                Variant::Capped => "capped",
                Variant::Open => "open",
            };
            ParamError::new(
                "format",
                format!(
                    "{format:?} is not written for openings={openings}; use vtp, vtk, stl \
                     (one solid per face), obj (one group per face) or glb (one primitive \
                     per face)"
                ),
            )
        })
}

/// The simulation parameters given, by name (for the closed surface, which takes none).
fn given(params: &SimulationParams) -> impl Iterator<Item = &'static str> {
    let numbers = [
        ("remesh_mm", params.remesh_mm),
        ("extension_diameters", params.extension_diameters),
        ("inlet_below_annulus_mm", params.inlet_below_annulus_mm),
        ("outlet_above_stj_mm", params.outlet_above_stj_mm),
        ("end_trim_mm", params.end_trim_mm),
        ("branch_trim_mm", params.branch_trim_mm),
    ];
    let kind = params.kind.as_ref().map(|_| "kind");
    kind.into_iter().chain(
        numbers
            .into_iter()
            .filter_map(|(name, value)| value.map(|_| name)),
    )
}

fn reject_simulation_options(params: &SimulationParams) -> Result<(), ParamError> {
    match given(params).next() {
        Some(field) => Err(ParamError::new(
            field,
            "applies to simulation meshes only: add openings=capped or openings=open",
        )),
        None => Ok(()),
    }
}

/// The pipeline's options from the parameters, every range checked.
pub fn parse_options(params: &SimulationParams) -> Result<SimulationOptions, ParamError> {
    let kind = match params.kind.as_deref().map(str::trim) {
        None | Some("auto") => None,
        Some("root") => Some(ShapeKind::Root),
        Some("aorta") => Some(ShapeKind::Aorta),
        Some("tube") => Some(ShapeKind::Tube),
        Some(other) => {
            return Err(ParamError::new(
                "kind",
                format!("unknown kind {other:?}; use auto, root, aorta or tube"),
            ));
        }
    };
    let defaults = OpeningOptions::default();
    let openings = OpeningOptions {
        inlet_below_annulus_mm: params
            .inlet_below_annulus_mm
            .unwrap_or(defaults.inlet_below_annulus_mm),
        outlet_above_stj_mm: params
            .outlet_above_stj_mm
            .unwrap_or(defaults.outlet_above_stj_mm),
        end_trim_mm: params.end_trim_mm.unwrap_or(defaults.end_trim_mm),
        branch_trim_mm: params.branch_trim_mm.unwrap_or(defaults.branch_trim_mm),
        ..defaults
    };
    openings.validate()?;
    if let Some(mm) = params.remesh_mm {
        RemeshOptions::new(mm)?;
    }
    let extension = params.extension_diameters.unwrap_or(0.0);
    if !(extension.is_finite() && (0.0..=MAX_EXTENSION_DIAMETERS).contains(&extension)) {
        return Err(ParamError::new(
            "extension_diameters",
            format!("{extension} must lie within 0–{MAX_EXTENSION_DIAMETERS} diameters"),
        ));
    }
    Ok(SimulationOptions {
        kind,
        openings,
        extension_diameters: extension,
        remesh_mm: params.remesh_mm,
    })
}

/// The parameter that places an opening, from the opening's name and the shape's kind: what
/// a caller changes when that opening's cut misses the surface.
pub fn opening_field(kind: Option<ShapeKind>, opening: &str) -> &'static str {
    match (kind, opening) {
        (Some(ShapeKind::Root), "inlet") => "inlet_below_annulus_mm",
        (Some(ShapeKind::Root), _) => "outlet_above_stj_mm",
        (_, name) if name.starts_with("branch") => "branch_trim_mm",
        _ => "end_trim_mm",
    }
}

/// Why the pipeline failed on a shape, as the parameter to change (or `openings` when the
/// shape itself has no usable openings) and a sentence.
pub fn failure_field(kind: Option<ShapeKind>, error: &SimulationError) -> &'static str {
    match error {
        SimulationError::BadOption { field, .. } => field,
        SimulationError::OverBudget { .. } => "remesh_mm",
        SimulationError::OutsideVessel { opening, .. }
        | SimulationError::CutMissesSurface { opening, .. }
        | SimulationError::CutNotLocal { opening, .. } => opening_field(kind, opening),
        _ => "openings",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> SimulationParams {
        SimulationParams::default()
    }

    #[test]
    fn without_openings_the_plain_formats_are_the_closed_surface_and_vtp_is_capped() {
        assert_eq!(
            MeshRequest::parse(None, &params()),
            Ok(MeshRequest::Closed(MeshFormat::Glb))
        );
        assert_eq!(
            MeshRequest::parse(Some("STL"), &params()),
            Ok(MeshRequest::Closed(MeshFormat::Stl))
        );
        let MeshRequest::Simulation { format, request } =
            MeshRequest::parse(Some("vtp"), &params()).unwrap()
        else {
            panic!("vtp is a simulation format");
        };
        assert_eq!(
            (format, request.variant),
            (SimulationFormat::Vtp, Variant::Capped)
        );
        assert_eq!(request.options, SimulationOptions::default());
    }

    #[test]
    fn openings_choose_the_variant_and_the_labelled_writer_of_a_format() {
        let open = SimulationParams {
            openings: Some("open".into()),
            ..params()
        };
        let MeshRequest::Simulation { format, request } =
            MeshRequest::parse(Some("stl"), &open).unwrap()
        else {
            panic!("openings=open is a simulation mesh");
        };
        assert_eq!(
            (format, request.variant),
            (SimulationFormat::Stl, Variant::Open)
        );
        let default_format = MeshRequest::parse(None, &open).unwrap();
        assert!(matches!(
            default_format,
            MeshRequest::Simulation {
                format: SimulationFormat::Vtp,
                ..
            }
        ));
    }

    #[test]
    fn every_bad_parameter_is_named() {
        let cases: Vec<(Option<&str>, SimulationParams, &str)> = vec![
            (Some("step"), params(), "format"),
            (
                Some("ply"),
                SimulationParams {
                    openings: Some("capped".into()),
                    ..params()
                },
                "format",
            ),
            (
                None,
                SimulationParams {
                    openings: Some("half".into()),
                    ..params()
                },
                "openings",
            ),
            (
                Some("vtp"),
                SimulationParams {
                    openings: Some("closed".into()),
                    ..params()
                },
                "format",
            ),
            (
                None,
                SimulationParams {
                    remesh_mm: Some(1.0),
                    ..params()
                },
                "remesh_mm",
            ),
            (
                Some("vtp"),
                SimulationParams {
                    remesh_mm: Some(0.05),
                    ..params()
                },
                "remesh_mm",
            ),
            (
                Some("vtp"),
                SimulationParams {
                    extension_diameters: Some(-1.0),
                    ..params()
                },
                "extension_diameters",
            ),
            (
                Some("vtp"),
                SimulationParams {
                    outlet_above_stj_mm: Some(f64::NAN),
                    ..params()
                },
                "outlet_above_stj_mm",
            ),
            (
                Some("vtp"),
                SimulationParams {
                    kind: Some("heart".into()),
                    ..params()
                },
                "kind",
            ),
        ];
        for (format, p, field) in cases {
            let e = MeshRequest::parse(format, &p).unwrap_err();
            assert_eq!(e.field, field, "{format:?} {p:?}: {e}");
        }
    }

    #[test]
    fn equal_options_give_equal_keys_and_the_variant_does_not_change_the_key() {
        let capped = SimulationParams {
            openings: Some("capped".into()),
            remesh_mm: Some(1.0),
            ..params()
        };
        let open = SimulationParams {
            openings: Some("open".into()),
            ..capped.clone()
        };
        let key = |p: &SimulationParams| match MeshRequest::parse(Some("vtp"), p).unwrap() {
            MeshRequest::Simulation { request, .. } => request.options_key(),
            MeshRequest::Closed(_) => unreachable!(),
        };
        assert_eq!(key(&capped), key(&open));
        let other = SimulationParams {
            remesh_mm: Some(1.5),
            ..capped.clone()
        };
        assert_ne!(key(&capped), key(&other));
    }

    #[test]
    fn a_cut_that_misses_is_blamed_on_the_distance_that_placed_it() {
        let miss = |opening: &str| SimulationError::CutMissesSurface {
            opening: opening.into(),
            message: String::new(),
        };
        let root = Some(ShapeKind::Root);
        let aorta = Some(ShapeKind::Aorta);
        assert_eq!(
            failure_field(root, &miss("inlet")),
            "inlet_below_annulus_mm"
        );
        assert_eq!(failure_field(root, &miss("outlet")), "outlet_above_stj_mm");
        assert_eq!(failure_field(aorta, &miss("branch_2")), "branch_trim_mm");
        assert_eq!(
            failure_field(aorta, &miss("outlet_descending")),
            "end_trim_mm"
        );
        let none = SimulationError::OpeningsNotFound("no ends".into());
        assert_eq!(failure_field(None, &none), "openings");
    }
}
