//! The model shipped in `models/default`: it loads, its manifest is consistent, and the fast
//! extraction reproduces the dense reference mesh on its latents.

use std::path::Path;

use aortagen::sdf::backend::Backend;
use aortagen::sdf::inference::mixing::Mixture;
use aortagen::sdf::inference::reconstruct::{ExtractionMethod, reconstruct};
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

#[test]
fn the_engine_finds_a_training_shape_as_its_own_nearest_neighbour() {
    use std::sync::atomic::AtomicBool;

    use aortagen::engine::SdfEngine;
    use aortagen::engine::{Engine, ShapeSpec};

    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/default");
    let engine = SdfEngine::new(Backend::default()).with_chamfer_points(10_000);
    let cancel = AtomicBool::new(false);
    let reference = engine.novelty_reference(&dir, 48, &cancel).unwrap();
    assert_eq!(reference.len(), bundled().num_shapes());
    let again = engine.novelty_reference(&dir, 48, &cancel).unwrap();
    assert!(
        std::sync::Arc::ptr_eq(&reference, &again),
        "cached per model and resolution"
    );
    // Weight 1 on training shape 3: the same surface, sampled differently.
    let spec = ShapeSpec {
        training_indices: vec![3, 5],
        weights: vec![1.0, 0.0],
        seed: 11,
        resolution: 48,
        latent_noise: 0.0,
        anchors: Vec::new(),
        sampled: None,
    };
    let copy = engine.generate_shape(&dir, &spec, &cancel).unwrap();
    let own = reference.novelty(&copy.mesh_unit, 11).unwrap();
    assert_eq!(own.nearest, 3);
    let mixed = ShapeSpec {
        weights: vec![0.5, 0.5],
        ..spec
    };
    let blend = engine.generate_shape(&dir, &mixed, &cancel).unwrap();
    let other = reference.novelty(&blend.mesh_unit, 11).unwrap();
    assert!(other.chamfer > own.chamfer, "{other:?} vs {own:?}");
}

/// The cohort pipeline measures training shapes (for targets) as a direct reconstruction of
/// each latent in its own mm frame measures them.
#[test]
fn training_shapes_are_measured_as_their_direct_reconstruction() {
    use std::sync::atomic::AtomicBool;

    use aortagen::anatomy::shape::measure_shape;
    use aortagen::cohort::targets::feasibility::measure_training_shapes;
    use aortagen::engine::SdfEngine;

    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/default");
    let engine = SdfEngine::new(Backend::default());
    let measured = measure_training_shapes(&engine, &dir, 2, &AtomicBool::new(false)).unwrap();
    let model = bundled();
    let latents = model.latents();
    let transforms = model.manifest.transforms();
    let direct: Vec<_> = (0..2)
        .map(|i| {
            let field = model.field(&latents[i]).unwrap();
            let mesh = reconstruct(&field, measured.resolution, ExtractionMethod::Fast)
                .unwrap()
                .mesh;
            measure_shape(&transforms[i].mesh_to_mesh_units(&mesh)).ok()
        })
        .collect();
    assert_eq!(measured.shapes, direct);
    for a in direct
        .iter()
        .map(|a| a.as_ref().expect("a training root measures"))
    {
        assert_eq!(a.method, "root", "{a:?}");
        // The parametric roots' annuli are adult-sized (about 20–30 mm).
        assert!(
            a.annulus_mm.is_some_and(|d| (18.0..32.0).contains(&d)),
            "{a:?}"
        );
    }
}
