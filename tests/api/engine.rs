//! A test double for the science engine: every "training shape" is an ellipsoid, and a
//! generated shape is the ellipsoid whose semi-axes are the weight-mixed semi-axes, meshed
//! as a UV sphere. Exact expectations (bounding box, area, mixing) follow from that.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::time::Duration;

use anyhow::Context;
use aortagen::engine::{
    Engine, FitSpec, FittedAnchor, GeneratedShape, ModelInfo, RefitSpec, ShapeSpec, TrainingSpec,
};
use aortagen::geometry::TriMesh;
use aortagen::geometry::chamfer::chamfer_distance;
use aortagen::geometry::normalize::UnitBallTransform;
use aortagen::geometry::normalize::normalize_to_unit_ball;
use aortagen::sdf::inference::mixing::{Mixture, noisy_latent};
use aortagen::sdf::inference::novelty::NoveltyReference;

/// Number of training ellipsoids.
pub const TRAINING_SHAPES: usize = 5;
/// Surface samples per shape for novelty (small, so tests stay quick).
pub const NOVELTY_POINTS: usize = 2000;
/// Where every generated shape is centred, in mm.
pub const CENTRE_MM: [f64; 3] = [100.0, -50.0, 20.0];

/// Semi-axes (mm) of training ellipsoid `i`.
pub fn training_axes(i: usize) -> [f64; 3] {
    let i = i as f64;
    [10.0 + 2.0 * i, 12.0 + i, 30.0 + 3.0 * i]
}

/// Semi-axes of the weight-mixed shape.
pub fn mixed_axes(indices: &[usize], weights: &[f64]) -> [f64; 3] {
    let mut axes = [0.0; 3];
    for (&i, &w) in indices.iter().zip(weights) {
        for (a, t) in axes.iter_mut().zip(training_axes(i)) {
            *a += w * t;
        }
    }
    axes
}

/// The latents of the analytic model: the training ellipsoids' semi-axes.
pub fn training_latents() -> Vec<Vec<f32>> {
    (0..TRAINING_SHAPES)
        .map(|i| training_axes(i).iter().map(|&a| a as f32).collect())
        .collect()
}

/// The analytic engine, with hooks to hold or break generation at a given call.
#[derive(Default)]
pub struct AnalyticEngine {
    /// `generate_shape` calls so far.
    pub calls: AtomicUsize,
    /// `generate_shape` calls that have returned a shape.
    pub returned: AtomicUsize,
    /// Calls numbered ≥ this (0-based) wait until `release` or the cancel flag is set.
    pub hold_from_call: Option<usize>,
    /// Lets held calls continue.
    pub release: AtomicBool,
    /// The call with this number panics.
    pub panic_on_call: Option<usize>,
    /// `training_surface` calls so far (the novelty reference's setup work).
    pub surfaces_built: AtomicUsize,
    /// `refit_training_shape` calls so far.
    pub refit_calls: AtomicUsize,
    /// The training shape whose refit fails until `refit_mended` is set.
    pub refit_breaks_at: Option<usize>,
    /// Lets the broken refit succeed.
    pub refit_mended: AtomicBool,
}

/// How much larger a re-fitted ellipsoid is than its training latent says: re-fitted
/// latents differ from the training ones, as a network-frozen fit's do.
pub const REFIT_SCALE: f64 = 1.1;

/// The re-fitted latent of training shape `index` with refit seed `seed`: its semi-axes
/// scaled by [`REFIT_SCALE`], plus 0.001 mm × the shape's own seed (seed + 2 index) on the
/// first axis, so a test can tell which seed a shape was fitted with.
pub fn refitted_axes(index: usize, seed: u64) -> [f64; 3] {
    let mut axes = training_axes(index).map(|a| a * REFIT_SCALE);
    axes[0] += 0.001 * (seed + 2 * index as u64) as f64;
    axes
}

impl Engine for AnalyticEngine {
    fn model_info(&self, _: &Path) -> anyhow::Result<ModelInfo> {
        let mut info = ModelInfo::with_shapes(
            3,
            (0..TRAINING_SHAPES).map(|index| format!("ellipsoid-{index}")),
        );
        info.architecture = serde_json::json!({ "kind": "analytic ellipsoids" });
        for shape in &mut info.training_shapes {
            shape.reconstruction_cd = Some(0.001 * (shape.index + 1) as f64);
        }
        Ok(info)
    }

    fn training_latents(&self, _: &Path) -> anyhow::Result<Vec<Vec<f32>>> {
        Ok(training_latents())
    }

    fn training_transforms(&self, _: &Path) -> anyhow::Result<Vec<UnitBallTransform>> {
        Ok((0..TRAINING_SHAPES)
            .map(|i| UnitBallTransform {
                centre: CENTRE_MM,
                radius: training_axes(i).iter().cloned().fold(0.0, f64::max),
            })
            .collect())
    }

    fn generate_shape(
        &self,
        _: &Path,
        spec: &ShapeSpec,
        cancel: &AtomicBool,
    ) -> anyhow::Result<GeneratedShape> {
        let call = self.calls.fetch_add(1, Ordering::SeqCst);
        if self.panic_on_call == Some(call) {
            panic!("analytic engine breaks on call {call}");
        }
        if self.hold_from_call.is_some_and(|h| call >= h) {
            while !self.release.load(Ordering::SeqCst) && !cancel.load(Ordering::SeqCst) {
                std::thread::sleep(Duration::from_millis(2));
            }
        }
        anyhow::ensure!(!cancel.load(Ordering::SeqCst), "generation cancelled");
        let k = spec.training_indices.len();
        let axes = if spec.latent_noise == 0.0 {
            // Anchors' and sampled latents are semi-axes too; their weights follow the
            // training ones.
            let mut axes = mixed_axes(&spec.training_indices, &spec.weights[..k]);
            let sampled = spec.sampled.iter().map(|s| &s.latent);
            let extra = sampled.chain(spec.anchors.iter().map(|a| &a.latent));
            for (latent, w) in extra.zip(&spec.weights[k..]) {
                for (a, &z) in axes.iter_mut().zip(latent) {
                    *a += w * f64::from(z);
                }
            }
            axes
        } else {
            let mixture = Mixture {
                indices: spec.training_indices.clone(),
                weights: spec.weights.clone(),
            };
            let z = noisy_latent(&mixture, &training_latents(), spec.latent_noise, spec.seed);
            [0, 1, 2].map(|d| f64::from(z[d]).max(1.0))
        };
        let radius = axes.iter().cloned().fold(0.0, f64::max);
        let mesh = ellipsoid_unit(axes, radius);
        let area_mm2 = mesh.area() * radius.powi(2);
        let volume_mm3 = mesh.signed_volume() * radius.powi(3);
        self.returned.fetch_add(1, Ordering::SeqCst);
        Ok(GeneratedShape {
            mesh_unit: mesh,
            transform: UnitBallTransform {
                centre: CENTRE_MM,
                radius,
            },
            area_mm2,
            volume_mm3,
        })
    }

    fn novelty_reference(
        &self,
        _: &Path,
        _: usize,
        _: &AtomicBool,
    ) -> anyhow::Result<Arc<NoveltyReference>> {
        let surfaces: Vec<TriMesh> = (0..TRAINING_SHAPES)
            .map(|i| {
                let axes = training_axes(i);
                ellipsoid_unit(axes, axes.iter().cloned().fold(0.0, f64::max))
            })
            .collect();
        Ok(Arc::new(NoveltyReference::new(&surfaces, NOVELTY_POINTS)?))
    }

    fn training_surface(
        &self,
        _: &Path,
        index: usize,
        _: usize,
        cancel: &AtomicBool,
    ) -> anyhow::Result<TriMesh> {
        anyhow::ensure!(!cancel.load(Ordering::SeqCst), "setup cancelled");
        anyhow::ensure!(index < TRAINING_SHAPES, "no training shape {index}");
        self.surfaces_built.fetch_add(1, Ordering::SeqCst);
        let axes = training_axes(index);
        Ok(ellipsoid_unit(
            axes,
            axes.iter().cloned().fold(0.0, f64::max),
        ))
    }

    fn novelty_reference_from(
        &self,
        _: &Path,
        _: usize,
        surfaces: &[TriMesh],
    ) -> anyhow::Result<Arc<NoveltyReference>> {
        Ok(Arc::new(NoveltyReference::new(surfaces, NOVELTY_POINTS)?))
    }

    fn pair_chamfer(
        &self,
        meshes: &[(u32, TriMesh)],
        pairs: &[(u32, u32)],
        _: u64,
    ) -> anyhow::Result<Vec<f64>> {
        let mesh = |index: u32| {
            meshes
                .iter()
                .find(|(i, _)| *i == index)
                .map(|(_, m)| m)
                .ok_or_else(|| anyhow::anyhow!("shape {index} was not given"))
        };
        pairs
            .iter()
            .map(|&(i, j)| Ok(chamfer_distance(&mesh(i)?.positions, &mesh(j)?.positions)))
            .collect()
    }

    fn train_model(
        &self,
        spec: &TrainingSpec,
        _: &AtomicBool,
        _: &AtomicU64,
    ) -> anyhow::Result<ModelInfo> {
        let files = std::fs::read_dir(&spec.input_dir)?.count();
        let mut info = self.model_info(&spec.model_dir)?;
        info.training_shapes.truncate(files);
        Ok(info)
    }

    /// The "latent" of a mesh is its bounding box's half extents (the semi-axes of an
    /// ellipsoid); the Chamfer distance compares the mesh with that ellipsoid.
    fn fit_anchor(
        &self,
        _: &Path,
        spec: &FitSpec,
        cancel: &AtomicBool,
        progress: &AtomicU64,
    ) -> anyhow::Result<FittedAnchor> {
        anyhow::ensure!(!cancel.load(Ordering::SeqCst), "fit cancelled");
        let mesh = aortagen::formats::read_mesh_file(&spec.mesh_path)?;
        let bb = mesh.bounding_box().context("empty mesh")?;
        let axes: [f64; 3] = std::array::from_fn(|k| 0.5 * (bb.max[k] - bb.min[k]));
        let (unit, transform) = normalize_to_unit_ball(&mesh);
        let fitted = ellipsoid_unit(axes, transform.radius);
        progress.store(spec.iterations as u64, Ordering::SeqCst);
        Ok(FittedAnchor {
            latent: axes.iter().map(|&a| a as f32).collect(),
            transform,
            chamfer: chamfer_distance(&fitted.positions, &unit.positions),
        })
    }

    fn refit_training_shape(
        &self,
        _: &Path,
        index: usize,
        spec: &RefitSpec,
        cancel: &AtomicBool,
        progress: &AtomicU64,
    ) -> anyhow::Result<FittedAnchor> {
        self.refit_calls.fetch_add(1, Ordering::SeqCst);
        anyhow::ensure!(!cancel.load(Ordering::SeqCst), "refit cancelled");
        anyhow::ensure!(index < TRAINING_SHAPES, "no training shape {index}");
        anyhow::ensure!(
            self.refit_breaks_at != Some(index) || self.refit_mended.load(Ordering::SeqCst),
            "the analytic engine cannot fit ellipsoid-{index}"
        );
        let axes = refitted_axes(index, spec.seed);
        progress.store(spec.iterations as u64, Ordering::SeqCst);
        Ok(FittedAnchor {
            latent: axes.iter().map(|&a| a as f32).collect(),
            transform: UnitBallTransform {
                centre: CENTRE_MM,
                radius: axes.iter().cloned().fold(0.0, f64::max),
            },
            chamfer: 1e-4 * (index + 1) as f64,
        })
    }
}

/// The ellipsoid with semi-axes `axes` (mm) in the unit ball of scale `radius`, with normals.
pub fn ellipsoid_unit(axes: [f64; 3], radius: f64) -> TriMesh {
    let mut mesh = uv_sphere(8, 16);
    for p in &mut mesh.positions {
        for (c, a) in p.iter_mut().zip(axes) {
            *c = (*c as f64 * a / radius) as f32;
        }
    }
    mesh.normals = Some(mesh.compute_vertex_normals());
    mesh
}

/// A unit sphere with `rings` latitude bands and `segments` meridians; outward,
/// counter-clockwise triangles. With even `rings` and `segments` divisible by 4 its
/// bounding box is exactly [-1, 1]³.
pub fn uv_sphere(rings: u32, segments: u32) -> TriMesh {
    use std::f64::consts::PI;
    let mut positions = vec![[0.0, 0.0, 1.0]];
    for i in 1..rings {
        let theta = PI * i as f64 / rings as f64;
        for j in 0..segments {
            let phi = 2.0 * PI * j as f64 / segments as f64;
            let p = [
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ];
            positions.push(p.map(|c| c as f32));
        }
    }
    positions.push([0.0, 0.0, -1.0]);
    let bottom = positions.len() as u32 - 1;
    let ring = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
    let mut triangles = Vec::new();
    for j in 0..segments {
        triangles.push([0, ring(1, j), ring(1, j + 1)]);
        for i in 1..rings - 1 {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            triangles.push([a, c, d]);
            triangles.push([a, d, b]);
        }
        triangles.push([bottom, ring(rings - 1, j + 1), ring(rings - 1, j)]);
    }
    TriMesh::new(positions, triangles)
}

#[test]
fn uv_sphere_is_closed_outward_and_close_to_the_unit_sphere() {
    let s = uv_sphere(8, 16);
    s.validate().unwrap();
    assert!(s.edge_report().is_closed_and_oriented());
    assert_eq!(s.euler_characteristic(), 2);
    // An inscribed polyhedron: volume a little below 4π/3, positive when outward.
    let v = s.signed_volume();
    let ball = 4.0 * std::f64::consts::PI / 3.0;
    assert!(v > 0.85 * ball && v < ball, "{v}");
}
