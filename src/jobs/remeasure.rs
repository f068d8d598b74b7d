//! Stored shape measurements brought to today's method. When the measurement method changes
//! ([`MEASUREMENT_VERSION`]), shapes stored by an earlier version keep their old values:
//! validations measure them again on the fly, but shape responses and the cohort summaries
//! show what is stored. [`remeasure_stored_shapes`] (`aortagen migrate --remeasure`) measures
//! every such shape again from its stored mesh, once after the upgrade; the service may keep
//! running meanwhile, since a row's measurements are replaced in one statement.
//!
//! [`MEASUREMENT_VERSION`]: crate::anatomy::shape::MEASUREMENT_VERSION

use anyhow::Context;
use rayon::prelude::*;

use super::priority::spawn_background;
use crate::anatomy::shape::{ShapeAnatomy, measure_shape};
use crate::db;
use crate::formats::mesh_blob;
use crate::objects::{Objects, StoredMesh};

/// Shapes read, measured and written per batch.
const BATCH: i64 = 32;

/// What a pass did, running totals.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct RemeasureCounts {
    /// Shapes looked at.
    pub examined: u64,
    /// Shapes whose stored values today's method took: left as they are.
    pub current: u64,
    /// Shapes measured again that now have measurements.
    pub measured: u64,
    /// Shapes measured again whose measurement failed (the reason is stored instead).
    pub failed: u64,
    /// Shapes whose mesh could not be read: left as they are, each logged.
    pub unreadable: u64,
}

/// Measures again every stored shape whose anatomy an earlier method took, or that has no
/// measurements (a failure's reason carries no version, so it is tried again), in batches
/// measured in parallel off the executor. `progress` sees the running counts after each batch.
pub async fn remeasure_stored_shapes(
    pool: &db::Pool,
    objects: &Objects,
    progress: &mut (dyn FnMut(&RemeasureCounts) + Send),
) -> anyhow::Result<RemeasureCounts> {
    let mut counts = RemeasureCounts::default();
    let mut after = i64::MIN;
    loop {
        let rows = db::shapes::measurements_after(pool, after, BATCH).await?;
        let Some(last) = rows.last() else {
            break;
        };
        after = last.mesh.shape_id;
        counts.examined += rows.len() as u64;
        let mut stale = Vec::new();
        for row in rows {
            let shape_id = row.mesh.shape_id;
            match row.anatomy {
                Some(anatomy) if anatomy.0.is_current() => counts.current += 1,
                _ => match objects.load(row.mesh).await {
                    Ok(stored) => stale.push(stored),
                    Err(e) => {
                        counts.unreadable += 1;
                        let error = format!("{e:#}");
                        tracing::warn!(shape_id, error, "mesh unreadable; measurements left");
                    }
                },
            }
        }
        let measured = spawn_background(move || {
            stale
                .par_iter()
                .map(|s| (s.row.shape_id, measure_stored(s)))
                .collect::<Vec<_>>()
        })
        .await
        .context("measuring stored shapes")?;
        let mut tx = db::begin_write(pool).await?;
        for (shape_id, measured) in &measured {
            let anatomy = match measured {
                Ok(Ok(anatomy)) => Ok(anatomy),
                Ok(Err(reason)) => Err(reason.as_str()),
                Err(e) => {
                    counts.unreadable += 1;
                    let error = format!("{e:#}");
                    tracing::warn!(shape_id, error, "mesh undecodable; measurements left");
                    continue;
                }
            };
            // A shape deleted meanwhile is simply gone.
            if db::shapes::set_anatomy(&mut *tx, *shape_id, anatomy).await? {
                match anatomy {
                    Ok(_) => counts.measured += 1,
                    Err(_) => counts.failed += 1,
                }
            }
        }
        tx.commit()
            .await
            .context("cannot store the new measurements")?;
        progress(&counts);
    }
    Ok(counts)
}

/// Today's measurements of a stored mesh (or why they failed); Err when the mesh does not
/// decode.
fn measure_stored(stored: &StoredMesh) -> anyhow::Result<Result<ShapeAnatomy, String>> {
    let unit = mesh_blob::decode(&stored.mesh)
        .with_context(|| format!("the mesh of shape {}", stored.row.shape_id))?;
    let mesh_mm = stored.transform().mesh_to_mesh_units(&unit);
    Ok(measure_shape(&mesh_mm).map_err(|e| e.to_string()))
}
