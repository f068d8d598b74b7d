//! From a closed vessel surface to a labelled, capped (or open) simulation mesh: openings,
//! cutting, optional flow extensions, caps, optional remeshing, face table and quality.

use serde::{Deserialize, Serialize};

use super::SimulationError;
use super::cap::{project_loop, triangulate_polygon};
use super::cut::{OpenSurface, cut_openings};
use super::extension::{EXTENSION_BASE, extend_openings};
use super::faces::{FaceData, FaceName, LabelledMesh};
use super::opening::{Opening, OpeningOptions, ShapeKind, WALL_ID};
use super::quality::{QualityReport, quality_report};
use super::remesh::{RemeshOptions, RemeshReport, check_budget, remesh};
use super::root_openings::root_openings;
use super::tree_openings::tree_openings;
use super::tree_openings::vessel_ends;
use crate::anatomy::sections::PlaneFrame;
use crate::anatomy::surface::Surface;
use crate::geometry::TriMesh;

/// What to make of a surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SimulationOptions {
    /// The rules the openings follow; `None` decides from the shape (branches → aorta, a
    /// sinus bulge → root, otherwise tube).
    pub kind: Option<ShapeKind>,
    /// Where the openings go.
    pub openings: OpeningOptions,
    /// Length of a straight flow extension at every opening, in diameters of that opening
    /// (0 = none).
    pub extension_diameters: f64,
    /// Isotropic remeshing to this target edge length in mm (`None` keeps the input's
    /// triangles).
    pub remesh_mm: Option<f64>,
}

impl Default for SimulationOptions {
    fn default() -> Self {
        Self {
            kind: None,
            openings: OpeningOptions::default(),
            extension_diameters: 0.0,
            remesh_mm: None,
        }
    }
}

/// A capped, labelled simulation mesh with everything known about it.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationMesh {
    /// The rules the openings followed.
    pub kind: ShapeKind,
    /// The openings (before any flow extension moved the caps).
    pub openings: Vec<Opening>,
    /// The watertight surface: wall and one flat cap per opening.
    pub capped: LabelledMesh,
    /// Boundary-condition data of every face of `capped`.
    pub faces: Vec<FaceData>,
    /// Triangle quality and topology of `capped`.
    pub quality: QualityReport,
    /// What the remeshing did, when it ran.
    pub remesh: Option<RemeshReport>,
}

impl SimulationMesh {
    /// The open variant: the wall only, one boundary loop per opening.
    pub fn open(&self) -> LabelledMesh {
        self.capped.wall_only()
    }
}

/// The openings of a surface in mm, by the rules of `kind` (or the detected kind).
pub fn find_openings(
    mesh: &TriMesh,
    kind: Option<ShapeKind>,
    opts: &OpeningOptions,
) -> Result<(ShapeKind, Vec<Opening>), SimulationError> {
    find_openings_observed(mesh, kind, opts, &mut |_| {})
}

fn find_openings_observed(
    mesh: &TriMesh,
    kind: Option<ShapeKind>,
    opts: &OpeningOptions,
    observe: &mut dyn FnMut(Step),
) -> Result<(ShapeKind, Vec<Opening>), SimulationError> {
    opts.validate()?;
    let surface = Surface::new(mesh)?;
    let kind = match kind {
        Some(k) => k,
        None => detect_kind(&surface, opts)?,
    };
    observe(Step::Kind(kind));
    let openings = match kind {
        ShapeKind::Root => root_openings(&surface, opts)?,
        ShapeKind::Aorta | ShapeKind::Tube => tree_openings(&surface, kind, opts)?,
    };
    Ok((kind, openings))
}

fn detect_kind(surface: &Surface, opts: &OpeningOptions) -> Result<ShapeKind, SimulationError> {
    if !vessel_ends(surface, opts.ring_spacing_mm)?
        .branches
        .is_empty()
    {
        return Ok(ShapeKind::Aorta);
    }
    Ok(match crate::anatomy::root::measure_prepared_root(surface) {
        Ok(_) => ShapeKind::Root,
        Err(_) => ShapeKind::Tube,
    })
}

/// A step of [`simulation_mesh_observed`], reported as it starts (the kind once it is
/// known), so a long run can show where it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// The rules the openings follow, given or detected.
    Kind(ShapeKind),
    /// Cutting the surface open at the openings.
    Cut,
    /// Appending flow extensions.
    Extend,
    /// Closing the openings with flat caps.
    Cap,
    /// Isotropic remeshing (the long step: seconds per shape).
    Remesh,
    /// Face table and quality report.
    Measure,
}

impl Step {
    /// A few words for progress output.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Kind(_) => "finding the openings",
            Self::Cut => "cutting the openings",
            Self::Extend => "adding flow extensions",
            Self::Cap => "capping",
            Self::Remesh => "remeshing",
            Self::Measure => "measuring faces and quality",
        }
    }
}

/// The whole pipeline: openings, cut, extensions, caps, remeshing, faces and quality.
pub fn simulation_mesh(
    mesh: &TriMesh,
    opts: &SimulationOptions,
) -> Result<SimulationMesh, SimulationError> {
    simulation_mesh_observed(mesh, opts, None, &mut |_| {})
}

/// [`simulation_mesh`], telling `observe` each step as it starts; with
/// `max_remesh_triangles`, a remesh that would make more triangles (counted on the capped
/// surface, flow extensions included) fails with [`SimulationError::OverBudget`] before it
/// starts.
pub fn simulation_mesh_observed(
    mesh: &TriMesh,
    opts: &SimulationOptions,
    max_remesh_triangles: Option<u64>,
    observe: &mut dyn FnMut(Step),
) -> Result<SimulationMesh, SimulationError> {
    let remesh_opts = opts.remesh_mm.map(RemeshOptions::new).transpose()?;
    if !(opts.extension_diameters.is_finite() && (0.0..=20.0).contains(&opts.extension_diameters)) {
        return Err(SimulationError::option(
            "extension_diameters",
            format!("{} must lie within 0–20", opts.extension_diameters),
        ));
    }
    let (kind, openings) = find_openings_observed(mesh, opts.kind, &opts.openings, observe)?;
    observe(Step::Cut);
    let positions = mesh.positions.iter().map(|p| p.map(f64::from)).collect();
    let mut open = cut_openings(positions, mesh.triangles.clone(), &openings)?;
    let mut caps = openings.clone();
    if opts.extension_diameters > 0.0 {
        observe(Step::Extend);
        caps = extend_openings(&mut open, &openings, opts.extension_diameters)?;
    }
    observe(Step::Cap);
    let mut capped = cap_openings(&open, &caps)?;
    let remesh_report = match remesh_opts {
        Some(r) => {
            if let Some(max) = max_remesh_triangles {
                check_budget(capped.mesh.area(), r.target_mm, max)?;
            }
            observe(Step::Remesh);
            let (m, report) = remesh(&capped, &r)?;
            capped = m;
            Some(report)
        }
        None => None,
    };
    observe(Step::Measure);
    Ok(SimulationMesh {
        kind,
        openings,
        faces: capped.face_table(),
        quality: quality_report(&capped.mesh),
        capped,
        remesh: remesh_report,
    })
}

/// Closes every loop of `open` with a flat cap labelled as its opening.
pub fn cap_openings(
    open: &OpenSurface,
    openings: &[Opening],
) -> Result<LabelledMesh, SimulationError> {
    let mut triangles = open.triangles.clone();
    let mut face_ids = open.face_ids.clone();
    for (ring, opening) in open.loops.iter().zip(openings) {
        // The wall runs along the loop one way; its cap must run the other way.
        let reversed: Vec<u32> = ring.iter().rev().copied().collect();
        let frame = PlaneFrame::new(opening.origin, opening.normal);
        let q = project_loop(&open.positions, &reversed, &frame);
        let signed: f64 = (0..q.len())
            .map(|i| {
                let (a, b) = (q[i], q[(i + 1) % q.len()]);
                a[0] * b[1] - b[0] * a[1]
            })
            .sum();
        if signed <= 0.0 {
            return Err(SimulationError::Topology(format!(
                "the loop of opening `{}` runs the wrong way round: the surface is not \
                 oriented outward",
                opening.name
            )));
        }
        for t in triangulate_polygon(&q) {
            triangles.push(t.map(|k| reversed[k]));
            face_ids.push(opening.id);
        }
    }
    let mut mesh = TriMesh::new(
        open.positions.iter().map(|p| p.map(|c| c as f32)).collect(),
        triangles,
    );
    mesh.normals = Some(mesh.compute_vertex_normals());
    let mut faces = vec![FaceName {
        id: WALL_ID,
        name: "wall".into(),
    }];
    faces.extend(openings.iter().map(|o| FaceName {
        id: o.id,
        name: o.name.clone(),
    }));
    for o in openings {
        if face_ids.contains(&(EXTENSION_BASE + o.id)) {
            faces.push(FaceName {
                id: EXTENSION_BASE + o.id,
                name: format!("{}_extension", o.name),
            });
        }
    }
    faces.sort_by_key(|f| f.id);
    Ok(LabelledMesh {
        mesh,
        face_ids,
        faces,
    })
}
