//! `aortagen mesh FILE --capped|--open`: the simulation mesh of any surface in mm —
//! openings cut flat, capped or left open, optionally extended and remeshed, labelled per
//! face — written in one labelled format with its sidecar JSON (face table with
//! boundary-condition data, openings, quality). The same pipeline and parameter checks as
//! the service's `openings=capped|open` downloads.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use serde::Serialize;

use crate::formats::{LoadedMesh, MeshMetadata};
use crate::geometry::TriMesh;
use crate::simulation::request::failure_field;
use crate::simulation::{
    FaceData, MeshRequest, ParamError, PreparedSimulation, SimulationParams, SimulationRequest,
    Step, simulation_mesh_observed,
};

/// The simulation flags of `aortagen mesh`.
#[derive(Debug, Default, Clone, clap::Args)]
pub struct SimulationFlags {
    /// Write the simulation mesh: openings cut and closed by flat labelled caps.
    #[arg(long, conflicts_with = "open")]
    pub capped: bool,
    /// Write the simulation mesh with its openings cut and left open (the wall only).
    #[arg(long)]
    pub open: bool,
    /// Simulation mesh format: vtp (default), vtk, stl (a solid per face), obj (a group
    /// per face) or glb (a primitive per face).
    #[arg(long, value_name = "FORMAT")]
    pub format: Option<String>,
    /// Isotropic remesh to this target edge length, mm (0.1–10).
    #[arg(long, value_name = "MM")]
    pub remesh_mm: Option<f64>,
    /// Flow extensions at every opening, in diameters of the opening (0–20).
    #[arg(long, value_name = "DIAMETERS")]
    pub extension_diameters: Option<f64>,
    /// The rules the openings follow: auto (default), root, aorta or tube.
    #[arg(long)]
    pub kind: Option<String>,
    /// Root: inlet below the annulus, mm (default 0).
    #[arg(long, value_name = "MM")]
    pub inlet_below_annulus_mm: Option<f64>,
    /// Root: outlet above the sinotubular junction, mm (default 20).
    #[arg(long, value_name = "MM")]
    pub outlet_above_stj_mm: Option<f64>,
    /// Aorta and tube: inlet and main outlet in from the ends, mm (default 20).
    #[arg(long, value_name = "MM")]
    pub end_trim_mm: Option<f64>,
    /// Aorta: branch outlets in from the branch ends, mm (default 8).
    #[arg(long, value_name = "MM")]
    pub branch_trim_mm: Option<f64>,
    /// Simulation mesh file; default `<input stem>_<capped|open>.<format>` beside the
    /// input. Its sidecar is `<file>.json`.
    #[arg(long, value_name = "OUT")]
    pub out: Option<PathBuf>,
}

/// What was written.
#[derive(Debug, Clone, Serialize)]
pub struct SimulationOutput {
    /// The mesh file.
    pub file: String,
    /// The sidecar JSON.
    pub sidecar: String,
    /// Bytes of the mesh file.
    pub bytes: usize,
    /// Seconds the pipeline took.
    pub seconds: f64,
    /// The face table of the written variant.
    pub faces: Vec<FaceData>,
}

impl SimulationFlags {
    /// Whether a simulation mesh was asked for.
    pub fn wanted(&self) -> bool {
        self.capped || self.open
    }

    /// Any simulation flag given without `--capped` or `--open`.
    fn stray(&self) -> Option<&'static str> {
        let given = [
            ("--format", self.format.is_some()),
            ("--remesh-mm", self.remesh_mm.is_some()),
            ("--extension-diameters", self.extension_diameters.is_some()),
            ("--kind", self.kind.is_some()),
            (
                "--inlet-below-annulus-mm",
                self.inlet_below_annulus_mm.is_some(),
            ),
            ("--outlet-above-stj-mm", self.outlet_above_stj_mm.is_some()),
            ("--end-trim-mm", self.end_trim_mm.is_some()),
            ("--branch-trim-mm", self.branch_trim_mm.is_some()),
            ("--out", self.out.is_some()),
        ];
        given.into_iter().find(|(_, g)| *g).map(|(name, _)| name)
    }

    fn request(
        &self,
    ) -> Result<(crate::simulation::SimulationFormat, SimulationRequest), ParamError> {
        let params = SimulationParams {
            openings: Some(if self.open { "open" } else { "capped" }.to_owned()),
            kind: self.kind.clone(),
            remesh_mm: self.remesh_mm,
            extension_diameters: self.extension_diameters,
            inlet_below_annulus_mm: self.inlet_below_annulus_mm,
            outlet_above_stj_mm: self.outlet_above_stj_mm,
            end_trim_mm: self.end_trim_mm,
            branch_trim_mm: self.branch_trim_mm,
        };
        match MeshRequest::parse(Some(self.format.as_deref().unwrap_or("vtp")), &params)? {
            MeshRequest::Simulation { format, request } => Ok((format, request)),
            MeshRequest::Closed(_) => unreachable!("openings are capped or open"),
        }
    }
}

/// Refuses simulation flags given without `--capped` or `--open`.
pub fn check_stray(flags: &SimulationFlags) -> anyhow::Result<()> {
    match flags.stray() {
        Some(flag) if !flags.wanted() => {
            bail!("{flag} applies to simulation meshes: add --capped or --open")
        }
        _ => Ok(()),
    }
}

fn flag(field: &str) -> String {
    format!("--{}", field.replace('_', "-"))
}

/// Makes and writes the simulation mesh of `loaded` (read from `input`), telling each
/// step on stderr as it starts.
pub fn write(
    input: &Path,
    loaded: &LoadedMesh,
    flags: &SimulationFlags,
) -> anyhow::Result<SimulationOutput> {
    match loaded.units.as_deref() {
        None | Some("mm") => {}
        Some(other) => bail!(
            "{} is in {other}; simulation meshes are made from surfaces in mm",
            input.display()
        ),
    }
    let source = input.file_name().map_or_else(
        || input.display().to_string(),
        |n| n.to_string_lossy().into(),
    );
    write_surface(&source, &loaded.mesh, &input.with_extension(""), flags)
}

/// Makes the simulation mesh of `mesh` (mm, from `source`) and writes it to `flags.out`,
/// else `<stem>_<capped|open>.<format>`, with its sidecar.
pub fn write_surface(
    source: &str,
    mesh: &TriMesh,
    stem: &Path,
    flags: &SimulationFlags,
) -> anyhow::Result<SimulationOutput> {
    let (format, request) = flags
        .request()
        .map_err(|e| anyhow::anyhow!("{}: {}", flag(e.field), e.message))?;
    let started = Instant::now();
    let mut kind = request.options.kind;
    let sim = simulation_mesh_observed(mesh, &request.options, None, &mut |step| {
        if let Step::Kind(k) = step {
            kind = Some(k);
        }
        eprintln!(
            "{:7.1} s  {}",
            started.elapsed().as_secs_f64(),
            step.describe()
        );
    })
    .map_err(|e| {
        let field = failure_field(kind, &e);
        let hint = match field {
            "openings" => "the surface has no openings of this kind".to_owned(),
            f => format!("change {}", flag(f)),
        };
        anyhow::anyhow!("no simulation mesh: {e} ({hint})")
    })?;
    let seconds = started.elapsed().as_secs_f64();
    let prepared = PreparedSimulation::new(sim);
    let variant = request.variant;
    let meta = MeshMetadata {
        extras: serde_json::json!({ "source": source, "variant": variant,
            "simulation": request.options }),
        ..MeshMetadata::new("mm")
    };
    let out = flags.out.clone().unwrap_or_else(|| {
        let mut name = stem.as_os_str().to_owned();
        name.push(format!("_{}.{}", variant.name(), format.extension()));
        PathBuf::from(name)
    });
    let bytes = prepared.file(format, variant, &meta)?;
    std::fs::write(&out, &bytes).with_context(|| format!("cannot write {}", out.display()))?;
    let mut sidecar = out.clone().into_os_string();
    sidecar.push(".json");
    let sidecar = PathBuf::from(sidecar);
    let json = serde_json::to_vec_pretty(&prepared.summary.sidecar(variant, &meta))?;
    std::fs::write(&sidecar, json)
        .with_context(|| format!("cannot write {}", sidecar.display()))?;
    Ok(SimulationOutput {
        file: out.display().to_string(),
        sidecar: sidecar.display().to_string(),
        bytes: bytes.len(),
        seconds,
        faces: prepared.summary.faces(variant).to_vec(),
    })
}

/// The simulation flags of `aortagen generate`: a simulation mesh beside every shape.
#[derive(Debug, Default, Clone, clap::Args)]
pub struct GenerateSimulation {
    /// Also write each shape's simulation mesh, `shape_NNNN_<variant>.<format>` with its
    /// sidecar JSON: capped or open.
    #[arg(long, value_name = "VARIANT")]
    pub simulation: Option<String>,
    /// Format of the simulation meshes: vtp (default), vtk, stl, obj or glb.
    #[arg(long, value_name = "FORMAT", requires = "simulation")]
    pub simulation_format: Option<String>,
    /// Isotropic remesh of the simulation meshes to this edge length, mm (0.1–10).
    #[arg(long, value_name = "MM", requires = "simulation")]
    pub remesh_mm: Option<f64>,
    /// Flow extensions of the simulation meshes, in diameters of each opening (0–20).
    #[arg(long, value_name = "DIAMETERS", requires = "simulation")]
    pub extension_diameters: Option<f64>,
}

impl GenerateSimulation {
    /// The mesh flags these stand for (`None` without `--simulation`), checked before any
    /// shape is generated.
    pub fn flags(&self) -> anyhow::Result<Option<SimulationFlags>> {
        let Some(variant) = self.simulation.as_deref() else {
            return Ok(None);
        };
        let flags = SimulationFlags {
            capped: variant == "capped",
            open: variant == "open",
            format: self.simulation_format.clone(),
            remesh_mm: self.remesh_mm,
            extension_diameters: self.extension_diameters,
            ..Default::default()
        };
        if !flags.wanted() {
            bail!("--simulation: unknown variant {variant:?}; use capped or open");
        }
        flags.request().map_err(|e| {
            let name = match e.field {
                "format" => "--simulation-format".to_owned(),
                f => flag(f),
            };
            anyhow::anyhow!("{name}: {}", e.message)
        })?;
        Ok(Some(flags))
    }
}

/// The written mesh in the text report, one face a line.
pub fn to_text(out: &SimulationOutput) -> String {
    let mut lines = vec![format!(
        "simulation mesh:      {} ({} bytes, {:.1} s; faces in {})",
        out.file, out.bytes, out.seconds, out.sidecar
    )];
    for f in &out.faces {
        lines.push(format!(
            "  face {:>2} {:<20} area {:>10.2} mm²  diameter {:>7.2} mm  normal [{:.3}, {:.3}, {:.3}]",
            f.id, f.name, f.area_mm2, f.equivalent_diameter_mm, f.normal[0], f.normal[1], f.normal[2]
        ));
    }
    lines.join("\n")
}
