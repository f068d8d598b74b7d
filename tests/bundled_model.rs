//! The model shipped in `models/default`: it loads, its manifest is consistent, and the fast
//! extraction reproduces the dense reference mesh on its latents.

use std::path::Path;

use aortagen::sdf::backend::Backend;
use aortagen::sdf::generate::Mixture;
use aortagen::sdf::reconstruct::{ExtractionMethod, reconstruct};
use aortagen::sdf::store::LoadedModel;

fn bundled() -> LoadedModel {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/default");
    LoadedModel::load(&dir, Backend::default()).expect("the bundled model loads")
}

#[test]
fn bundled_model_has_one_latent_and_one_transform_per_training_shape() {
    let model = bundled();
    let shapes = model.manifest.shapes.len();
    assert!(shapes >= 2, "a cohort needs at least two training shapes");
    assert_eq!(model.num_shapes(), shapes);
    let latents = model.latents();
    assert!(
        latents
            .iter()
            .all(|z| z.len() == model.manifest.architecture.latent_dim)
    );
    assert!(model.manifest.progress.complete, "training finished");
}

#[test]
fn fast_extraction_equals_dense_on_the_bundled_model() {
    let model = bundled();
    let latents = model.latents();
    let mixture = Mixture {
        indices: vec![0, 1],
        weights: vec![0.35, 0.65],
    };
    let candidates = [latents[0].clone(), mixture.mix_latents(&latents)];
    for latent in candidates {
        let field = model.field(&latent).unwrap();
        let fast = reconstruct(&field, 64, ExtractionMethod::Fast).unwrap();
        let dense = reconstruct(&field, 64, ExtractionMethod::Dense).unwrap();
        let worst = fast.mesh.max_surface_difference(&dense.mesh);
        assert!(worst.is_some_and(|w| w <= 1e-5), "{worst:?}");
        assert!(fast.mesh.edge_report().is_closed_and_oriented());
        assert!(fast.evaluations.samples < dense.evaluations.samples);
    }
}
