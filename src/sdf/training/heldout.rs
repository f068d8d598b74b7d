//! The held-out half of DeepSDF's test protocol: every shape kept out of training is fitted
//! with the network frozen ([`super::fit::fit_mesh`]) and its reconstruction measured exactly
//! as a training shape's, so the two distributions stand side by side in one report.

use std::sync::atomic::AtomicBool;

use super::fit::{FitSettings, FittedLatent, fit_mesh};
use crate::geometry::TriMesh;
use crate::geometry::chamfer::sampling_floor;
use crate::geometry::normalize::normalize_to_unit_ball;
use crate::sdf::inference::evaluation::{EvaluationSettings, HeldOutEvaluation, ShapeFidelity};
use crate::sdf::store::LoadedModel;

/// Fits every `(name, mesh)` of `heldout` (mesh units) with `iterations` Adam steps and
/// scores it with `settings`; `on_shape` sees each result (for progress) with the fitted
/// latent when the fit worked. A failed fit is recorded with its reason, not an error.
pub fn evaluate_heldout(
    model: &LoadedModel,
    heldout: &[(String, TriMesh)],
    iterations: usize,
    settings: &EvaluationSettings,
    cancel: Option<&AtomicBool>,
    on_shape: &mut dyn FnMut(&ShapeFidelity, Option<&FittedLatent>),
) -> HeldOutEvaluation {
    let mut shapes = Vec::with_capacity(heldout.len());
    for (index, (name, mesh)) in heldout.iter().enumerate() {
        // Seeds apart from the training shapes' (which use seed + 2 i), as evaluate's do.
        let seed = settings.seed.wrapping_add(1_000_003 + 2 * index as u64);
        let mut fit = FitSettings::new(seed);
        fit.iterations = iterations;
        fit.evaluation = EvaluationSettings { seed, ..*settings };
        let fitted = fit_mesh(model, mesh, &fit, &mut |_| {}, cancel);
        let unit = normalize_to_unit_ball(mesh).0;
        let floor = sampling_floor(&unit, settings.chamfer_points, seed);
        let result = ShapeFidelity {
            index,
            name: name.clone(),
            chamfer: fitted.as_ref().ok().map(|f| f.chamfer),
            sampling_floor: floor,
            triangles: fitted.as_ref().map_or(0, |f| f.triangles),
            error: fitted.as_ref().err().map(|e| e.to_string()),
        };
        on_shape(&result, fitted.as_ref().ok());
        shapes.push(result);
    }
    HeldOutEvaluation::new(iterations, shapes)
}
