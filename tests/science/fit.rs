//! Fitting a new shape to a frozen model: a tiny model trained here on three synthetic roots,
//! then a latent fitted from zero to one of its training meshes; and re-fitting every
//! training shape that way for density samplers (`aortagen refit`).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use aortagen::cli::refit::{self, RefitArgs};
use aortagen::cohort::{
    CohortFields, CohortPlan, CohortRequest, LatentSource, ModelLatents, RequestLimits,
    SamplerFields, SamplerKind,
};
use aortagen::engine::{Engine, SdfEngine};
use aortagen::geometry::normalize::normalize_to_unit_ball;
use aortagen::sdf::backend::Backend;
use aortagen::sdf::data::{DataSource, PreparedDataset, load_source_meshes, prepare_shapes};
use aortagen::sdf::inference::evaluation::EvaluationSettings;
use aortagen::sdf::inference::reconstruct::ExtractionMethod;
use aortagen::sdf::model::network::SdfNetwork;
use aortagen::sdf::store::LoadedModel;
use aortagen::sdf::store::refits::RefitSet;
use aortagen::sdf::training::fit::{
    FitError, FitSettings, fit_mesh, frozen_trainable_copy, latent_chamfer, optimise_latent,
};
use aortagen::sdf::training::refit::refit_settings;
use aortagen::sdf::training::{Preset, Silent, TrainingRequest, train};

const SHAPES: usize = 3;
const TARGET: usize = 1;

fn train_tiny(dir: &Path, epochs: u64) -> LoadedModel {
    let mut setup = Preset::Cpu.setup(11);
    setup.network = setup.network.with_latent_dim(8).with_hidden(32);
    setup.sampling.points_per_shape = 1000;
    let t = &mut setup.training;
    (t.epochs, t.batch_shapes, t.surface_points, t.eikonal_points) = (epochs, SHAPES, 256, 256);
    (t.checkpoint_every, t.lr_halving_epochs, t.learning_rate) = (epochs, 0, 5e-3);
    let request = TrainingRequest {
        out_dir: dir.to_path_buf(),
        source: DataSource::Synth {
            count: SHAPES,
            seed: 5,
        },
        holdout: None,
        setup,
        backend: Backend::Flex,
        resume: false,
        stop: None,
    };
    train(&request, &mut Silent).unwrap();
    LoadedModel::load(dir, Backend::Flex).unwrap()
}

fn network_values(network: &SdfNetwork) -> Vec<f32> {
    let mut out = Vec::new();
    for layer in &network.layers {
        out.extend(layer.weight.val().into_data().iter::<f32>());
        if let Some(b) = &layer.bias {
            out.extend(b.val().into_data().iter::<f32>());
        }
    }
    out
}

fn settings(iterations: usize, seed: u64) -> FitSettings {
    FitSettings {
        iterations,
        evaluation: EvaluationSettings {
            resolution: 32,
            chamfer_points: 2000,
            seed: 3,
            extraction: ExtractionMethod::Fast,
        },
        ..FitSettings::new(seed)
    }
}

#[test]
fn a_latent_fitted_from_zero_reconstructs_a_training_mesh_like_its_trained_latent() {
    let dir = tempfile::tempdir().unwrap();
    let model = train_tiny(dir.path(), 150);
    let weights_before = network_values(&model.decoder.network);
    let meshes = load_source_meshes(&model.manifest.data.source).unwrap();
    let mesh = &meshes[TARGET].1;
    let (unit, transform) = normalize_to_unit_ball(mesh);
    let eval = settings(1, 0).evaluation;
    let cd = |latent: &[f32]| {
        latent_chamfer(&model, latent, &unit, &eval).map_or(f64::INFINITY, |(cd, _)| cd)
    };
    let trained = cd(&model.latents()[TARGET]);
    let zero = cd(&[0.0; 8]);

    let mut steps = 0;
    let fitted = fit_mesh(&model, mesh, &settings(300, 7), &mut |_| steps += 1, None).unwrap();
    eprintln!(
        "CD trained {trained}, zero {zero}, fitted {}",
        fitted.chamfer
    );
    assert_eq!(steps, 300);
    assert_eq!(fitted.loss_history.len(), 300);
    assert_eq!(fitted.transform, transform, "normalised as training does");
    assert!(
        fitted.chamfer < 0.5 * zero,
        "fitted {} vs zero latent {zero}",
        fitted.chamfer
    );
    assert!(
        fitted.chamfer < 2.0 * trained,
        "fitted {} vs trained latent {trained}",
        fitted.chamfer
    );
    let first: f32 = fitted.loss_history[..10].iter().map(|l| l.loss).sum();
    let last: f32 = fitted.loss_history[290..].iter().map(|l| l.loss).sum();
    assert!(last < first, "the loss falls: {first} → {last}");

    // The same seed gives the same latent, another seed another one.
    let again = fit_mesh(&model, mesh, &settings(300, 7), &mut |_| {}, None).unwrap();
    assert_eq!(again.latent, fitted.latent);
    assert_eq!(again.chamfer, fitted.chamfer);
    let other = fit_mesh(&model, mesh, &settings(300, 8), &mut |_| {}, None).unwrap();
    assert_ne!(other.latent, fitted.latent);

    // Neither the loaded model nor the saved weights moved.
    assert_eq!(network_values(&model.decoder.network), weights_before);
    let reloaded = LoadedModel::load(dir.path(), Backend::Flex).unwrap();
    assert_eq!(network_values(&reloaded.decoder.network), weights_before);
}

#[test]
fn the_optimised_network_keeps_its_weights_and_a_cancel_stops_the_fit() {
    let dir = tempfile::tempdir().unwrap();
    let model = train_tiny(dir.path(), 2);
    let before = network_values(&model.decoder.network);
    let meshes = load_source_meshes(&model.manifest.data.source).unwrap();
    let data = PreparedDataset {
        shapes: prepare_shapes(&meshes[..1], &model.manifest.data.sampling).unwrap(),
        settings: model.manifest.data.sampling,
    };
    let network =
        frozen_trainable_copy(&model.decoder.network, &model.manifest.architecture).unwrap();
    let (after, latent, history) = optimise_latent(
        network,
        &data,
        &model.manifest.training,
        &settings(20, 1),
        &mut |_| {},
        None,
    )
    .unwrap();
    assert_eq!(network_values(&after), before, "the network is frozen");
    assert!(latent.iter().any(|&v| v != 0.0), "the latent moved");
    assert_eq!(history.len(), 20);

    let cancel = AtomicBool::new(false);
    let result = fit_mesh(
        &model,
        &meshes[0].1,
        &settings(50, 1),
        &mut |p| {
            if p.iteration == 5 {
                cancel.store(true, Ordering::SeqCst);
            }
        },
        Some(&cancel),
    );
    assert!(matches!(result, Err(FitError::Cancelled(5))), "{result:?}");
    let bad = fit_mesh(&model, &meshes[0].1, &settings(0, 1), &mut |_| {}, None);
    assert!(matches!(bad, Err(FitError::Iterations(0))), "{bad:?}");
}

fn refit_args(model: &Path, iterations: usize) -> RefitArgs {
    RefitArgs {
        model: model.to_path_buf(),
        data: None,
        iterations,
        seed: 4,
        resolution: 32,
        points: 1000,
        backend: Backend::Flex,
    }
}

#[test]
fn refitting_fits_every_training_shape_resumes_exactly_and_feeds_a_density_sampler() {
    let dir = tempfile::tempdir().unwrap();
    let model = train_tiny(dir.path(), 2);
    let engine = SdfEngine::new(Backend::Flex);
    assert!(!engine.model_info(dir.path()).unwrap().refitted_latents);
    assert!(engine.refitted_latents(dir.path()).unwrap().is_none());

    refit::run(refit_args(dir.path(), 30)).unwrap();
    let set = RefitSet::load(dir.path(), &model.manifest).unwrap();
    assert!(set.is_complete(&model.manifest));
    let meshes = load_source_meshes(&model.manifest.data.source).unwrap();
    let base = FitSettings {
        iterations: 30,
        evaluation: EvaluationSettings {
            resolution: 32,
            chamfer_points: 1000,
            seed: 4,
            extraction: ExtractionMethod::Fast,
        },
        ..FitSettings::new(4)
    };
    for (index, record) in set.shapes.iter().enumerate() {
        // Each record is the shape fitted as a new patient would be, with seed 4 + 2 i.
        let fitted = fit_mesh(
            &model,
            &meshes[index].1,
            &refit_settings(&base, index),
            &mut |_| {},
            None,
        )
        .unwrap();
        assert_eq!(record.name, model.manifest.shapes[index].name);
        assert_eq!((record.seed, record.iterations), (4 + 2 * index as u64, 30));
        assert_eq!(record.latent, fitted.latent, "shape {index}");
        assert_eq!(record.chamfer, fitted.chamfer, "shape {index}");
        assert_ne!(
            record.latent,
            model.latents()[index],
            "not the trained latent"
        );
    }

    // An interrupted run (the last record missing) resumes to the same records.
    let mut partial = set.clone();
    partial.shapes.pop();
    partial.save(dir.path()).unwrap();
    assert!(!engine.model_info(dir.path()).unwrap().refitted_latents);
    refit::run(refit_args(dir.path(), 30)).unwrap();
    let resumed = RefitSet::load(dir.path(), &model.manifest).unwrap();
    let latents = |s: &RefitSet| {
        s.shapes
            .iter()
            .map(|r| r.latent.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(latents(&resumed), latents(&set));
    // Resuming with other settings would mix two kinds of fit: refused.
    partial.save(dir.path()).unwrap();
    let err = refit::run(refit_args(dir.path(), 31)).unwrap_err();
    assert!(err.to_string().contains("other settings"), "{err}");
    resumed.save(dir.path()).unwrap();

    // A density sampler asked for the re-fitted latents is fitted to them.
    assert!(engine.model_info(dir.path()).unwrap().refitted_latents);
    let fields = |latents| CohortFields::<String> {
        count: 4,
        seed: Some(9),
        sampler: Some(SamplerFields {
            kind: SamplerKind::PcaGaussian,
            latents,
            ..SamplerFields::default()
        }),
        ..CohortFields::default()
    };
    let read = |latents| {
        let request = CohortRequest::parse(fields(latents), RequestLimits::NONE, || 0).unwrap();
        let read = ModelLatents::read(&engine, dir.path(), &request, SHAPES, None)
            .unwrap()
            .unwrap();
        let plan = CohortPlan::new(&request, SHAPES, Some(&read), Vec::new()).unwrap();
        (read, plan)
    };
    let (refitted, plan) = read(Some(LatentSource::Refitted));
    assert_eq!(*refitted.latents, latents(&resumed));
    let transforms: Vec<_> = resumed.shapes.iter().map(|r| r.transform).collect();
    assert_eq!(refitted.transforms, transforms);
    let (trained, trained_plan) = read(None);
    assert_eq!(*trained.latents, model.latents());
    let first = |p: &CohortPlan| p.shape_spec(0).sampled.unwrap().latent;
    assert_ne!(
        first(&plan),
        first(&trained_plan),
        "another density, another draw"
    );
}
