//! Latent → mesh: the field on a dense grid over [-1,1]³, marching cubes at f = 0, and
//! vertex normals from the network's exact gradient ∇ₓf.
//!
//! The dense grid is the reference path (DESIGN §3); it is evaluated one z-slab at a time so
//! memory stays at one R² slab of points plus the R³ values.

use crate::extract::{
    ExtractError, ExtractOptions, Extraction, ScalarField, extract_dense, extract_surface,
};
use crate::geometry::TriMesh;
use crate::geometry::marching_cubes::Grid;

use crate::sdf::inference::field::{FieldError, SdfField};

/// Grid resolution of reconstruction-fidelity evaluations when none is given (cohorts mesh
/// at [`crate::cohort::DEFAULT_RESOLUTION`]).
pub const EVALUATION_RESOLUTION: usize = 128;

/// Why a latent produced no usable mesh.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReconstructError {
    /// Resolution outside the supported range.
    #[error("resolution must be between {MIN_RESOLUTION} and {MAX_RESOLUTION} (got {0})")]
    Resolution(usize),
    /// The extraction rejected its input.
    #[error("surface extraction failed: {0}")]
    Extract(ExtractError),
    /// The network could not be evaluated.
    #[error(transparent)]
    Field(#[from] FieldError),
    /// The field has no sign change on the grid (entirely inside or outside).
    #[error("the field has no zero level set inside [-1,1]³ at resolution {0}")]
    EmptySurface(usize),
    /// The field produced NaN or infinite values.
    #[error("the field is not finite at {0} grid points")]
    NotFinite(usize),
}

/// Smallest grid resolution accepted.
pub const MIN_RESOLUTION: usize = 8;
/// Largest grid resolution accepted: the grid's own bound (the sparse path's memory stays
/// bounded up to here).
pub use crate::geometry::marching_cubes::MAX_RESOLUTION;

/// The R³ grid over [-1,1]³ used for every reconstruction.
pub fn unit_grid(resolution: usize) -> Grid {
    Grid {
        resolution,
        min: -1.0,
        max: 1.0,
    }
}

/// How the zero level is extracted from the network.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum ExtractionMethod {
    /// Coarse-to-fine: the network is evaluated only in blocks that can hold the surface
    /// ([`crate::extract::extract_surface`]); same mesh as `dense`, a fraction of the work.
    #[default]
    Fast,
    /// Every sample of the R³ grid (the reference path).
    Dense,
}

/// Samples per axis of the probe grid that estimates the field's Lipschitz constant.
const LIPSCHITZ_PROBE_RESOLUTION: usize = 17;

/// A neural field as the extraction code sees it: values, exact gradients, and a Lipschitz
/// bound estimated from the gradient norm.
///
/// A trained SDF has ‖∇f‖ ≈ 1 near its surface (the eikonal term), but nothing bounds it
/// analytically. The bound is the largest ‖∇f‖ over a probe grid (and never below 1, the
/// value of an exact SDF); [`ExtractOptions::safety`] adds the margin on top.
pub struct NeuralField<'a> {
    field: &'a SdfField,
    lipschitz: f32,
}

impl<'a> NeuralField<'a> {
    /// Wraps `field`, probing its gradient on a coarse grid over [-1,1]³.
    pub fn new(field: &'a SdfField) -> Result<Self, ReconstructError> {
        let grid = unit_grid(LIPSCHITZ_PROBE_RESOLUTION);
        let points: Vec<[f32; 3]> = grid.points().collect();
        let mut values = vec![0.0f32; points.len()];
        let mut gradients = vec![[0.0f32; 3]; points.len()];
        field.try_eval_batch(&points, &mut values, Some(&mut gradients))?;
        let mut largest = 1.0f32;
        for g in &gradients {
            let n = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            if !n.is_finite() {
                return Err(ReconstructError::NotFinite(1));
            }
            largest = largest.max(n);
        }
        Ok(Self {
            field,
            lipschitz: largest,
        })
    }
}

impl ScalarField for NeuralField<'_> {
    fn eval_batch(
        &self,
        points: &[[f32; 3]],
        values: &mut [f32],
        gradients: Option<&mut [[f32; 3]]>,
    ) {
        self.field.eval_batch(points, values, gradients);
    }

    fn lipschitz_bound(&self) -> f32 {
        self.lipschitz
    }
}

/// The zero level set of `field` in unit-ball coordinates by `method`, with unit normals
/// from ∇ₓf at the vertices and small floating pieces removed (see [`ExtractOptions`]).
pub fn reconstruct(
    field: &SdfField,
    resolution: usize,
    method: ExtractionMethod,
) -> Result<Extraction, ReconstructError> {
    if !(MIN_RESOLUTION..=MAX_RESOLUTION).contains(&resolution) {
        return Err(ReconstructError::Resolution(resolution));
    }
    let neural = NeuralField::new(field)?;
    let options = ExtractOptions::default();
    let extraction = match method {
        ExtractionMethod::Fast => extract_surface(&neural, resolution, &options),
        ExtractionMethod::Dense => extract_dense(&neural, resolution, &options),
    }
    .map_err(|e| match e {
        ExtractError::NonFinite { .. } => ReconstructError::NotFinite(1),
        other => ReconstructError::Extract(other),
    })?;
    if extraction.mesh.triangles.is_empty() {
        return Err(ReconstructError::EmptySurface(resolution));
    }
    Ok(extraction)
}

/// The zero level set of `field` as a mesh in unit-ball coordinates (fast path).
pub fn reconstruct_mesh(field: &SdfField, resolution: usize) -> Result<TriMesh, ReconstructError> {
    reconstruct(field, resolution, ExtractionMethod::Fast).map(|e| e.mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdf::backend::Backend;
    use crate::sdf::model::network::SdfNetworkConfig;
    use crate::sdf::model::network::test_support::perturbed;

    /// The untrained network is roughly the SDF of a sphere of radius `radius_init`
    /// (geometric initialisation): a closed, outward mesh whose vertices lie on the field's
    /// zero level to within the linear-interpolation error of the grid.
    #[test]
    fn an_untrained_network_reconstructs_a_closed_zero_level_near_its_initial_sphere() {
        let device = Backend::default().device(false).unwrap();
        let config = SdfNetworkConfig::new().with_latent_dim(4).with_hidden(256);
        let network = config.init(1, &device).unwrap();
        let field = SdfField::new(&network, &[0.0; 4]).unwrap();
        let resolution = 24;
        let mesh = reconstruct_mesh(&field, resolution).unwrap();
        mesh.validate().unwrap();
        let report = mesh.edge_report();
        assert!(report.is_closed_and_oriented(), "{report:?}");
        assert!(mesh.signed_volume() > 0.0);
        let mut f = vec![0.0; mesh.positions.len()];
        field.eval_batch(&mesh.positions, &mut f, None);
        let spacing = 2.0 / (resolution - 1) as f32;
        let worst = f.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(worst < 0.1 * spacing, "|f| at vertices up to {worst}");
        let r0 = config.radius_init as f32;
        let normals = mesh.normals.as_ref().unwrap();
        for (p, n) in mesh.positions.iter().zip(normals) {
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert!((r - r0).abs() < 0.3 * r0, "vertex radius {r}");
            assert!((n.iter().map(|c| c * c).sum::<f32>() - 1.0).abs() < 1e-4);
            let radial: f32 = (0..3).map(|c| n[c] * p[c] / r).sum();
            assert!(radial > 0.8, "normal points outward ({radial})");
        }
    }

    #[test]
    fn resolutions_outside_the_supported_range_are_rejected() {
        let device = Backend::default().device(false).unwrap();
        let network = SdfNetworkConfig::new().with_latent_dim(2).with_hidden(8);
        let field = SdfField::new(&network.init(0, &device).unwrap(), &[0.0; 2]).unwrap();
        for bad in [1, MIN_RESOLUTION - 1, MAX_RESOLUTION + 1] {
            assert_eq!(
                reconstruct_mesh(&field, bad).unwrap_err(),
                ReconstructError::Resolution(bad)
            );
        }
    }

    /// The fast path must give the dense reference's mesh: same triangles, vertices within
    /// 1e-5, on a network whose latent bends the initial sphere into a lumpy shape.
    #[test]
    fn fast_extraction_gives_the_dense_mesh_on_a_network() {
        let device = Backend::default().device(false).unwrap();
        let config = SdfNetworkConfig::new().with_latent_dim(3).with_hidden(32);
        // Noise on every weight turns the initial sphere into a lumpy, latent-dependent
        // surface, which exercises the culling bound far more than a sphere does.
        let network = perturbed(config.init(7, &device).unwrap(), 3, 0.01);
        for latent in [[0.0f32, 0.0, 0.0], [0.8, -0.6, 0.4]] {
            let field = SdfField::new(&network, &latent).unwrap();
            for resolution in [40, 96] {
                let fast = reconstruct(&field, resolution, ExtractionMethod::Fast).unwrap();
                let dense = reconstruct(&field, resolution, ExtractionMethod::Dense).unwrap();
                let worst = fast.mesh.max_surface_difference(&dense.mesh);
                assert!(
                    worst.is_some_and(|w| w <= 1e-5),
                    "R = {resolution}: {worst:?}"
                );
                assert!(
                    fast.mesh.triangle_count() > 100,
                    "a real surface, not a speck"
                );
                // At coarse grids the band |f| ≤ L·half-diagonal covers much of the cube, at
                // finer grids culling pays.
                assert!(fast.evaluations.samples <= dense.evaluations.samples);
                if resolution >= 96 {
                    assert!(fast.evaluations.samples < dense.evaluations.samples);
                }
                assert!(fast.mesh.edge_report().is_closed_and_oriented());
            }
        }
    }
}
