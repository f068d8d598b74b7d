//! Re-fitting the training shapes with the network frozen ([`crate::sdf::store::refits`]):
//! each training shape is fitted exactly as a new patient is ([`fit_mesh`]), so a density
//! sampler can be fitted to latents from the same process as a new patient's.

use std::sync::atomic::AtomicBool;
use std::time::{SystemTime, UNIX_EPOCH};

use super::fit::{FitError, FitSettings, fit_mesh};
use crate::geometry::TriMesh;
use crate::sdf::store::LoadedModel;
use crate::sdf::store::anchors::Anchor;

/// The settings of training shape `index`'s fit: `base` with the seed `base.seed + 2 index`
/// (for the surface sampling, the batches and the scoring alike), so each shape's fit is
/// reproducible on its own and a resumed run fits the remaining shapes as an
/// uninterrupted one would.
pub fn refit_settings(base: &FitSettings, index: usize) -> FitSettings {
    let seed = base.seed.wrapping_add(2 * index as u64);
    let mut settings = *base;
    settings.seed = seed;
    settings.evaluation.seed = seed;
    settings
}

/// Fits training shape `index` (`name`, `mesh` in mesh units) with the frozen network of
/// `model`; the record keeps the latent, the transform and the reconstruction Chamfer
/// distance. Raising `cancel` stops the fit after its current step.
pub fn refit_shape(
    model: &LoadedModel,
    index: usize,
    name: &str,
    mesh: &TriMesh,
    base: &FitSettings,
    cancel: Option<&AtomicBool>,
) -> Result<Anchor, FitError> {
    let settings = refit_settings(base, index);
    let fitted = fit_mesh(model, mesh, &settings, &mut |_| {}, cancel)?;
    Ok(Anchor {
        name: name.to_owned(),
        latent: fitted.latent,
        transform: fitted.transform,
        chamfer: fitted.chamfer,
        source: format!("training shape {index}"),
        iterations: settings.iterations,
        seed: settings.seed,
        created_unix: SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_shape_gets_its_own_seed_for_fitting_and_scoring() {
        let base = FitSettings {
            iterations: 50,
            ..FitSettings::new(7)
        };
        let third = refit_settings(&base, 3);
        assert_eq!((third.seed, third.evaluation.seed), (13, 13));
        assert_eq!(third.iterations, 50);
        assert_eq!(refit_settings(&base, 0), base);
    }
}
