//! `aortagen measure`: centreline length, diameter profile and, for aortic roots, the
//! landmark diameters of a surface mesh in millimetres.

use std::path::PathBuf;

use anyhow::Context;
use serde::Serialize;

use crate::anatomy::{
    MeasureOptions, RootLandmarks, RootMeasurements, VesselMeasurements,
    measure_root_with_landmarks, measure_vessel,
};

/// Measure a vessel surface (mm): centreline length, diameter profile, root landmarks.
#[derive(Debug, clap::Args)]
pub struct MeasureArgs {
    /// Mesh file in millimetres (binary PLY).
    pub mesh: PathBuf,
    /// Print the full result (every station) as JSON instead of a summary.
    #[arg(long)]
    pub json: bool,
    /// Distance between stations along the centreline, mm.
    #[arg(long, default_value_t = MeasureOptions::default().station_spacing_mm)]
    pub spacing: f64,
    /// Half-width of the centreline smoothing window, mm.
    #[arg(long, default_value_t = MeasureOptions::default().smoothing_mm)]
    pub smoothing: f64,
    /// Also locate the aortic-root landmarks (annulus, sinus, STJ, ascending aorta).
    #[arg(long)]
    pub root: bool,
}

/// Everything measured on one mesh.
#[derive(Debug, Serialize)]
struct Report {
    mesh: String,
    units: &'static str,
    vessel: VesselMeasurements,
    /// Present with `--root` when the profile has the landmarks of an aortic root.
    root: Option<RootMeasurements>,
    root_landmarks: Option<RootLandmarks>,
    /// Why the root landmarks were not found, otherwise.
    root_error: Option<String>,
}

/// Runs the command.
pub fn run(args: MeasureArgs) -> anyhow::Result<()> {
    let mesh = super::render::read_mesh(&args.mesh)?;
    let opts = MeasureOptions {
        station_spacing_mm: args.spacing,
        smoothing_mm: args.smoothing,
        ..MeasureOptions::default()
    };
    let vessel = measure_vessel(&mesh, &opts)
        .with_context(|| format!("measuring {}", args.mesh.display()))?;
    let (root, root_landmarks, root_error) = if args.root {
        match measure_root_with_landmarks(&mesh) {
            Ok((m, l)) => (Some(m), Some(l), None),
            Err(e) => (None, None, Some(e.to_string())),
        }
    } else {
        (None, None, None)
    };
    let report = Report {
        mesh: args.mesh.display().to_string(),
        units: "mm",
        vessel,
        root,
        root_landmarks,
        root_error,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", summary(&report));
    }
    Ok(())
}

/// A short human-readable summary.
fn summary(r: &Report) -> String {
    let mut d: Vec<f64> = r
        .vessel
        .stations
        .iter()
        .map(|s| s.equivalent_diameter_mm)
        .collect();
    d.sort_by(f64::total_cmp);
    let q = |f: f64| d[((d.len() - 1) as f64 * f).round() as usize];
    let mut out = format!(
        "{}\n  centreline length   {:.2} mm ({} stations)\n  equivalent diameter min {:.2}  median {:.2}  max {:.2} mm\n  maximum diameter    {:.2} mm (branch ostia left out)\n",
        r.mesh,
        r.vessel.centreline_length_mm,
        d.len(),
        q(0.0),
        q(0.5),
        q(1.0),
        r.vessel.max_diameter_mm()
    );
    match (&r.root, &r.root_error) {
        (Some(m), _) => out.push_str(&format!(
            "  annulus             {:.2} × {:.2} mm (mean {:.2})\n  sinus of Valsalva   {:.2} mm\n  sinotubular junction {:.2} mm\n  sinus height        {:.2} mm\n  ascending aorta     {:.2} mm\n",
            m.annulus_major_mm,
            m.annulus_minor_mm,
            m.annulus_mean_mm,
            m.sinus_diameter_mm,
            m.stj_diameter_mm,
            m.sinus_height_mm,
            m.ascending_diameter_mm
        )),
        (None, Some(e)) => out.push_str(&format!("  no root landmarks: {e}\n")),
        (None, None) => {}
    }
    out
}
