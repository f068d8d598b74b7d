//! Simulation meshes of stored shapes, made once per shape and options and kept in the
//! database: the service's downloads and face tables both come here.
//!
//! The pipeline takes seconds per shape (about ten with remeshing at 256³), so it runs on a
//! background thread, at most [`SimulationWork::new`]'s `slots` at a time; a second request
//! for a mesh being made waits for the same run instead of starting another; and a run
//! continues when the request that started it gives up waiting, so a retry finds the result.
//! Requests may start at most `backlog` runs waiting or running at once (beyond that they
//! are told to come back); background callers (a cohort export) are bounded by the slots
//! only.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use tokio::sync::{Semaphore, watch};

use super::join_error;
use super::priority::spawn_background;
use crate::db;
use crate::db::simulations::{SimulationOutcome, SimulationRow};
use crate::formats::mesh_blob;
use crate::objects::Objects;
use crate::simulation::request::failure_field;
use crate::simulation::{
    PreparedSimulation, SimulationError, SimulationRequest, Step, StoredSimulation,
    simulation_mesh_observed,
};

/// Simulation meshes made at once by a service. Remeshing keeps one core busy for seconds;
/// one run at a time leaves the other cores to requests and cohort jobs.
pub const DEFAULT_SLOTS: usize = 1;

/// Runs requests may start before they are told to retry: a few minutes of remeshing.
pub const DEFAULT_BACKLOG: usize = 16;

/// What the pipeline gave for a shape.
#[derive(Debug, Clone)]
pub enum Prepared {
    /// The simulation mesh.
    Ready(Arc<PreparedSimulation>),
    /// Why there is none, and the parameter to change (`openings` when the shape is at
    /// fault).
    Failed {
        /// The sentence.
        error: String,
        /// The parameter.
        field: String,
    },
}

/// Whether a caller may start a run beyond the backlog bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admission {
    /// A request: refused with [`PrepareError::Busy`] when the backlog is full.
    Bounded,
    /// Background work (a cohort export): always admitted.
    Unbounded,
}

/// Why no answer could be given.
#[derive(Debug, thiserror::Error)]
pub enum PrepareError {
    /// The backlog of runs is full.
    #[error("{0} simulation meshes are being made; retry later")]
    Busy(usize),
    /// The shape is gone.
    #[error("shape {0} does not exist")]
    NoShape(i64),
    /// Storage or a run failed unexpectedly.
    #[error(transparent)]
    Other(#[from] anyhow::Error),
}

type Key = (i64, String, String);
type Answer = Option<Result<Prepared, String>>;

/// The bounded, deduplicated, cached runs of one service.
pub struct SimulationWork {
    objects: Objects,
    max_remesh_triangles: u64,
    slots: Arc<Semaphore>,
    backlog: usize,
    running: Arc<Mutex<HashMap<Key, watch::Receiver<Answer>>>>,
}

impl SimulationWork {
    /// At most `slots` runs at once, and at most `backlog` started by requests; shapes'
    /// meshes are read from `objects`; a remesh making more than `max_remesh_triangles`
    /// triangles is refused before it starts.
    pub fn new(slots: usize, backlog: usize, objects: Objects, max_remesh_triangles: u64) -> Self {
        Self {
            objects,
            max_remesh_triangles,
            slots: Arc::new(Semaphore::new(slots.max(1))),
            backlog: backlog.max(1),
            running: Arc::default(),
        }
    }

    /// Runs waiting or running now.
    pub fn in_progress(&self) -> usize {
        self.lock().len()
    }

    /// The simulation mesh of `shape_id` (whose mesh has digest `mesh_sha256`) for
    /// `request`'s options: from the database when made before by this version from the
    /// same mesh, else made now (or joined, when a run is under way).
    pub async fn prepare(
        &self,
        pool: &db::Pool,
        shape_id: i64,
        mesh_sha256: &str,
        request: &SimulationRequest,
        admission: Admission,
    ) -> Result<Prepared, PrepareError> {
        let options = request.options_key();
        if let Some(found) = stored(pool, shape_id, mesh_sha256, &options).await? {
            return Ok(found);
        }
        let key = (shape_id, mesh_sha256.to_owned(), options);
        let mut answer = self.start_or_join(pool, key, request, admission)?;
        let done = answer
            .wait_for(Option::is_some)
            .await
            .map_err(|_| anyhow::anyhow!("the simulation run ended without an answer"))?;
        match done.clone().expect("waited for an answer") {
            Ok(prepared) => Ok(prepared),
            Err(e) => Err(PrepareError::Other(anyhow::anyhow!(e))),
        }
    }

    fn start_or_join(
        &self,
        pool: &db::Pool,
        key: Key,
        request: &SimulationRequest,
        admission: Admission,
    ) -> Result<watch::Receiver<Answer>, PrepareError> {
        let mut running = self.lock();
        if let Some(rx) = running.get(&key) {
            return Ok(rx.clone());
        }
        if admission == Admission::Bounded && running.len() >= self.backlog {
            return Err(PrepareError::Busy(running.len()));
        }
        let (tx, rx) = watch::channel(None);
        running.insert(key.clone(), rx.clone());
        let (pool, request, objects) = (pool.clone(), request.clone(), self.objects.clone());
        let (slots, map) = (self.slots.clone(), self.running.clone());
        let max_triangles = self.max_remesh_triangles;
        // Detached: the run finishes and stores its result even when no one waits any more.
        tokio::spawn(async move {
            let result = match slots.acquire_owned().await {
                Ok(_permit) => run(&pool, &objects, &key, &request, max_triangles).await,
                Err(e) => Err(anyhow::Error::from(e)),
            };
            map.lock().unwrap_or_else(|e| e.into_inner()).remove(&key);
            let _ = tx.send(Some(result.map_err(|e| format!("{e:#}"))));
        });
        Ok(rx)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<Key, watch::Receiver<Answer>>> {
        self.running.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A stored outcome made by this version from the shape's current mesh.
async fn stored(
    pool: &db::Pool,
    shape_id: i64,
    mesh_sha256: &str,
    options: &str,
) -> anyhow::Result<Option<Prepared>> {
    let Some(row) = db::simulations::get(pool, shape_id, options).await? else {
        return Ok(None);
    };
    if row.mesh_sha256 != mesh_sha256 || row.software_version != crate::VERSION {
        return Ok(None);
    }
    Ok(Some(match row.outcome {
        SimulationOutcome::Ready {
            mesh,
            face_ids,
            summary,
        } => {
            let stored = StoredSimulation {
                mesh,
                face_ids,
                summary,
            };
            Prepared::Ready(Arc::new(PreparedSimulation::from_stored(&stored)?))
        }
        SimulationOutcome::Failed { error, field } => Prepared::Failed { error, field },
    }))
}

/// Reads the shape, runs the pipeline in mm on a background thread, stores the outcome.
async fn run(
    pool: &db::Pool,
    objects: &Objects,
    key: &Key,
    request: &SimulationRequest,
    max_remesh_triangles: u64,
) -> anyhow::Result<Prepared> {
    let (shape_id, _, options) = key;
    let stored = objects
        .shape_mesh(pool, *shape_id)
        .await?
        .ok_or(PrepareError::NoShape(*shape_id))
        .map_err(anyhow::Error::from)?;
    let opts = request.options.clone();
    let started = Instant::now();
    let span = tracing::info_span!("simulation_mesh", shape_id, options = %options);
    let task = span.in_scope(|| {
        spawn_background(move || -> anyhow::Result<_> {
            let unit = mesh_blob::decode(&stored.mesh)?;
            let transform = stored.transform();
            let mm = transform.mesh_to_mesh_units(&unit);
            let mut kind = opts.kind;
            let budget = Some(max_remesh_triangles);
            let result = simulation_mesh_observed(&mm, &opts, budget, &mut |step| {
                if let Step::Kind(k) = step {
                    kind = Some(k);
                }
                tracing::debug!(step = step.describe(), "simulation step");
            });
            Ok((
                result.map(PreparedSimulation::new),
                kind,
                stored.row.mesh_sha256,
            ))
        })
    });
    let made = task.await.map_err(join_error)??;
    let (result, kind, mesh_sha256) = made;
    let seconds = started.elapsed().as_secs_f64();
    let (prepared, outcome) = match result {
        Ok(p) => {
            let s = p.to_stored();
            let outcome = SimulationOutcome::Ready {
                mesh: s.mesh,
                face_ids: s.face_ids,
                summary: s.summary,
            };
            (Prepared::Ready(Arc::new(p)), outcome)
        }
        Err(e) => {
            let (error, field) = (e.to_string(), failure_field(kind, &e).to_owned());
            tracing::info!(shape_id, %error, "no simulation mesh");
            let failed = Prepared::Failed {
                error: error.clone(),
                field: field.clone(),
            };
            // The limit is the service's setting, not a property of the shape: not kept,
            // so a service started with a higher limit makes the mesh.
            if matches!(e, SimulationError::OverBudget { .. }) {
                return Ok(failed);
            }
            (failed, SimulationOutcome::Failed { error, field })
        }
    };
    let row = SimulationRow {
        outcome,
        mesh_sha256,
        software_version: crate::VERSION.to_owned(),
        seconds,
    };
    // A result that cannot be kept (read-only database, full disk) is still the answer.
    if let Err(e) = db::simulations::put(pool, *shape_id, options, &row).await {
        tracing::warn!(shape_id, error = %e, "simulation mesh not stored");
    }
    tracing::info!(shape_id, seconds, "simulation mesh made");
    Ok(prepared)
}
