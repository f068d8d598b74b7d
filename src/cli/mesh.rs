//! `aortagen mesh`: reports what a mesh file holds (counts, area, volume, closedness,
//! topology, extent, units), converts it to another format, and with `--capped` or
//! `--open` writes its simulation mesh ([`super::simulate`]).

use std::path::PathBuf;

use anyhow::Context as _;
use serde::Serialize;

use super::simulate::{self, SimulationFlags};
use crate::formats::{LoadedMesh, MeshFormat, MeshMetadata, load_mesh_file, write_mesh};

/// Arguments of `aortagen mesh`.
#[derive(Debug, clap::Args)]
pub struct MeshArgs {
    /// Mesh file to inspect: .stl, .obj, .ply, .glb or .gltf.
    pub file: PathBuf,
    /// Print the report as JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also write the mesh to this file, in the format named by its extension.
    #[arg(long, value_name = "OUT")]
    pub convert: Option<PathBuf>,
    /// Units to record in the converted file (no scaling is applied); default: the
    /// units the input states, else "unknown".
    #[arg(long, requires = "convert")]
    pub units: Option<String>,
    /// Simulation mesh options.
    #[command(flatten)]
    pub simulation: SimulationFlags,
}

/// Everything `aortagen mesh` reports about one file.
#[derive(Debug, Clone, Serialize)]
pub struct MeshReport {
    /// File as given.
    pub file: String,
    /// Format it was parsed as.
    pub format: MeshFormat,
    /// Units stated in the file, if any.
    pub units: Option<String>,
    /// Vertex count (after welding, for STL).
    pub vertices: usize,
    /// Triangle count (after triangulating polygons).
    pub triangles: usize,
    /// Whether per-vertex normals were read.
    pub has_normals: bool,
    /// Total triangle area, in units².
    pub surface_area: f64,
    /// Enclosed volume in units³; `None` unless the surface is closed and consistently oriented.
    pub enclosed_volume: Option<f64>,
    /// Signed volume by the divergence theorem, whether or not it is meaningful.
    pub signed_volume: f64,
    /// Every edge shared by exactly two triangles, in opposite directions.
    pub closed: bool,
    /// Distinct edges.
    pub edges: usize,
    /// Edges used by one triangle only.
    pub boundary_edges: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Edges whose two triangles disagree on orientation.
    pub inconsistently_oriented_edges: usize,
    /// V − E + F (2 for a sphere-like closed surface).
    pub euler_characteristic: i64,
    /// Smallest corner of the bounding box.
    pub bbox_min: [f64; 3],
    /// Largest corner of the bounding box.
    pub bbox_max: [f64; 3],
    /// Edge lengths of the bounding box.
    pub bbox_size: [f64; 3],
}

impl MeshReport {
    /// Measures a loaded mesh.
    pub fn new(file: &str, loaded: &LoadedMesh) -> Self {
        let mesh = &loaded.mesh;
        let edges = mesh.edge_report();
        let closed = edges.is_closed_and_oriented();
        let signed_volume = mesh.signed_volume();
        let bbox = mesh.bounding_box().unwrap_or(crate::geometry::Aabb {
            min: [0.0; 3],
            max: [0.0; 3],
        });
        Self {
            file: file.to_owned(),
            format: loaded.format,
            units: loaded.units.clone(),
            vertices: mesh.vertex_count(),
            triangles: mesh.triangle_count(),
            has_normals: mesh.normals.is_some(),
            surface_area: mesh.area(),
            enclosed_volume: closed.then_some(signed_volume),
            signed_volume,
            closed,
            edges: edges.edges,
            boundary_edges: edges.boundary_edges,
            non_manifold_edges: edges.non_manifold_edges,
            inconsistently_oriented_edges: edges.inconsistently_oriented_edges,
            euler_characteristic: mesh.euler_characteristic(),
            bbox_min: bbox.min,
            bbox_max: bbox.max,
            bbox_size: bbox.size(),
        }
    }

    /// Human-readable report, one fact per line.
    pub fn to_text(&self) -> String {
        let unit = self.units.clone().unwrap_or_default();
        let suffix = |power: &str| {
            if unit.is_empty() {
                String::new()
            } else {
                format!(" {unit}{power}")
            }
        };
        let v3 = |v: [f64; 3]| format!("[{:.4}, {:.4}, {:.4}]", v[0], v[1], v[2]);
        let volume = match self.enclosed_volume {
            Some(v) if v < 0.0 => format!(
                "{v:.6}{} (negative: the triangles face inward)",
                suffix("³")
            ),
            Some(v) => format!("{v:.6}{}", suffix("³")),
            None => format!(
                "not meaningful, the surface is not closed (signed volume {:.6}{})",
                self.signed_volume,
                suffix("³")
            ),
        };
        let lines = [
            format!("file:                 {}", self.file),
            format!("format:               {}", self.format),
            format!(
                "units:                {}",
                self.units.as_deref().unwrap_or("not stated in the file")
            ),
            format!("vertices:             {}", self.vertices),
            format!("triangles:            {}", self.triangles),
            format!(
                "vertex normals:       {}",
                if self.has_normals { "yes" } else { "no" }
            ),
            format!(
                "surface area:         {:.6}{}",
                self.surface_area,
                suffix("²")
            ),
            format!("enclosed volume:      {volume}"),
            format!(
                "closed:               {} ({} edges: {} boundary, {} non-manifold, {} inconsistently oriented)",
                if self.closed { "yes" } else { "no" },
                self.edges,
                self.boundary_edges,
                self.non_manifold_edges,
                self.inconsistently_oriented_edges
            ),
            format!("euler characteristic: {}", self.euler_characteristic),
            format!("bounding box min:     {}", v3(self.bbox_min)),
            format!("bounding box max:     {}", v3(self.bbox_max)),
            format!("bounding box size:    {}{}", v3(self.bbox_size), suffix("")),
        ];
        lines.join("\n")
    }
}

/// Runs `aortagen mesh`.
pub fn run(args: MeshArgs) -> anyhow::Result<()> {
    simulate::check_stray(&args.simulation)?;
    let file = args.file.display().to_string();
    let loaded = load_mesh_file(&args.file)?;
    let report = MeshReport::new(&file, &loaded);
    let mut written = None;
    if let Some(out) = &args.convert {
        let format = MeshFormat::from_path(out)?;
        let source = args
            .file
            .file_name()
            .map_or(file.clone(), |n| n.to_string_lossy().into_owned());
        let meta = conversion_metadata(&source, &loaded, args.units.clone());
        let bytes = write_mesh(&loaded.mesh, format, &meta)?;
        std::fs::write(out, &bytes).with_context(|| format!("cannot write {}", out.display()))?;
        written = Some((out.display().to_string(), format, bytes.len()));
    }
    let simulation = if args.simulation.wanted() {
        Some(simulate::write(&args.file, &loaded, &args.simulation)?)
    } else {
        None
    };
    if args.json {
        let mut value = serde_json::to_value(&report)?;
        if let Some((path, format, bytes)) = &written {
            value["converted_to"] =
                serde_json::json!({ "file": path, "format": format, "bytes": bytes });
        }
        if let Some(sim) = &simulation {
            value["simulation"] = serde_json::to_value(sim)?;
        }
        println!("{}", serde_json::to_string_pretty(&value)?);
    } else {
        println!("{}", report.to_text());
        if let Some((path, format, bytes)) = &written {
            println!("converted to:         {path} ({format}, {bytes} bytes)");
        }
        if let Some(sim) = &simulation {
            println!("{}", simulate::to_text(sim));
        }
    }
    Ok(())
}

/// Metadata for a converted file: the stated units and where the mesh came from
/// (carrying over any provenance the input recorded).
fn conversion_metadata(file: &str, loaded: &LoadedMesh, units: Option<String>) -> MeshMetadata {
    let units = units
        .or_else(|| loaded.units.clone())
        .unwrap_or_else(|| "unknown".to_owned());
    let mut extras = serde_json::json!({
        "converted_from": file,
        "source_format": loaded.format,
    });
    if let Some(prov) = loaded.extras.as_ref().and_then(|e| e.get("provenance")) {
        extras["source_provenance"] = prov.clone();
    }
    MeshMetadata {
        extras,
        ..MeshMetadata::new(units)
    }
}
