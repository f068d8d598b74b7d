//! Latent → mesh: the field on a dense grid over [-1,1]³, marching cubes at f = 0, and
//! vertex normals from the network's exact gradient ∇ₓf.
//!
//! The dense grid is the reference path (DESIGN §3); it is evaluated one z-slab at a time so
//! memory stays at one R² slab of points plus the R³ values.

use crate::geometry::TriMesh;
use crate::geometry::marching_cubes::{Grid, marching_cubes};

use super::field::{FieldError, SdfField};

/// Default grid resolution for evaluation and generation (the paper meshes at 256³).
pub const DEFAULT_RESOLUTION: usize = 128;

/// Why a latent produced no usable mesh.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReconstructError {
    /// Fewer than 2 samples per axis.
    #[error("grid resolution must be at least 2 (got {0})")]
    Resolution(usize),
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

/// The R³ grid over [-1,1]³ used for every reconstruction.
pub fn unit_grid(resolution: usize) -> Grid {
    Grid {
        resolution,
        min: -1.0,
        max: 1.0,
    }
}

/// Field values at every grid sample, x-fastest (`values[i + R*(j + R*k)]`).
pub fn sample_grid(field: &SdfField, grid: &Grid) -> Result<Vec<f32>, ReconstructError> {
    let r = grid.resolution;
    if r < 2 {
        return Err(ReconstructError::Resolution(r));
    }
    let step = (grid.max - grid.min) / (r - 1) as f32;
    let coord = |i: usize| grid.min + i as f32 * step;
    let mut values = vec![0.0f32; r * r * r];
    let mut slab = Vec::with_capacity(r * r);
    for (k, out) in values.chunks_mut(r * r).enumerate() {
        slab.clear();
        for j in 0..r {
            for i in 0..r {
                slab.push([coord(i), coord(j), coord(k)]);
            }
        }
        field.try_eval_batch(&slab, out, None)?;
    }
    let bad = values.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        return Err(ReconstructError::NotFinite(bad));
    }
    Ok(values)
}

/// The zero level set of `field` as a mesh in unit-ball coordinates, with unit normals from
/// ∇ₓf at the vertices.
pub fn reconstruct_mesh(field: &SdfField, resolution: usize) -> Result<TriMesh, ReconstructError> {
    let grid = unit_grid(resolution);
    let values = sample_grid(field, &grid)?;
    let mut mesh = marching_cubes(&grid, &values, 0.0);
    if mesh.triangles.is_empty() {
        return Err(ReconstructError::EmptySurface(resolution));
    }
    let mut f = vec![0.0f32; mesh.positions.len()];
    let mut gradients = vec![[0.0f32; 3]; mesh.positions.len()];
    field.try_eval_batch(&mesh.positions, &mut f, Some(&mut gradients))?;
    mesh.normals = Some(gradients.into_iter().map(unit_or_zero).collect());
    Ok(mesh)
}

fn unit_or_zero(g: [f32; 3]) -> [f32; 3] {
    let n = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
    if n > 0.0 && n.is_finite() {
        g.map(|c| c / n)
    } else {
        [0.0; 3]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdf::backend::Backend;
    use crate::sdf::network::SdfNetworkConfig;

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
    fn resolutions_below_two_are_rejected() {
        let device = Backend::default().device(false).unwrap();
        let network = SdfNetworkConfig::new().with_latent_dim(2).with_hidden(8);
        let field = SdfField::new(&network.init(0, &device).unwrap(), &[0.0; 2]).unwrap();
        assert_eq!(
            reconstruct_mesh(&field, 1).unwrap_err(),
            ReconstructError::Resolution(1)
        );
    }
}
