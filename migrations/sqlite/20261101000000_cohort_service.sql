-- The cohort service's tables: registered models, the durable job queue, cohorts,
-- their generated shapes (mesh bytes included) and their pairwise metrics.
-- Timestamps are UTC RFC 3339 text with milliseconds, so they sort and compare as text.

-- A generative model the service can sample from.
create table model (
    model_id   text primary key,
    -- directory holding the model's weights and manifest, as the engine reads it
    dir_path   text not null,
    -- engine-reported facts (architecture, training shapes, reconstruction Chamfer) as JSON
    manifest   text not null,
    -- 'training' while its training job runs; cohorts may only use 'ready' models
    status     text not null default 'ready' check (status in ('training', 'ready', 'failed')),
    created_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

-- The work queue. Workers claim the oldest queued row with one UPDATE … RETURNING.
create table job (
    job_id           integer primary key,
    kind             text not null check (kind in ('cohort', 'training')),
    -- what to do, as JSON (e.g. {"cohort_id": 3})
    payload          text not null,
    status           text not null default 'queued'
                     check (status in ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    -- how many times a worker has claimed it (a restart re-queues interrupted jobs)
    attempts         integer not null default 0,
    progress_done    integer not null default 0,
    progress_total   integer not null default 0,
    -- set by a cancel request; the worker checks it between units of work
    cancel_requested integer not null default 0 check (cancel_requested in (0, 1)),
    -- the error chain of the last failure
    error            text,
    created_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    started_at       text,
    finished_at      text,
    updated_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
create index job_status_idx on job (status, job_id);

-- A requested synthetic cohort; its state is the state of its job.
create table cohort (
    cohort_id       integer primary key,
    model_id        text not null references model (model_id) on delete restrict,
    job_id          integer not null unique references job (job_id),
    count           integer not null check (count > 0),
    arity           integer not null check (arity > 1),
    -- 'equal' or 'dirichlet'; ignored when weights are given
    weighting       text not null check (weighting in ('equal', 'dirichlet')),
    -- explicit weights as a JSON array, or null
    weights         text,
    -- the seed actually used (drawn when the request had none), so a cohort can be replayed
    seed            integer not null,
    resolution      integer not null check (resolution between 32 and 1024),
    -- a retried POST carrying the same key returns this cohort instead of a new one
    idempotency_key text unique,
    -- SHA-256 of the canonical request, to refuse a reused key with a different body
    request_hash    text not null,
    created_at      text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at      text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
create index cohort_model_idx on cohort (model_id, cohort_id);

-- One generated shape. The unit-ball mesh is stored once (compact binary, see
-- src/db/mesh_blob.rs); downloads in mm apply the stored transform.
create table shape (
    shape_id         integer primary key,
    cohort_id        integer not null references cohort (cohort_id) on delete cascade,
    -- position in the cohort, 0-based; unique so a resumed job never duplicates a shape
    shape_index      integer not null,
    training_indices text not null, -- JSON array of the mixed training shapes
    weights          text not null, -- JSON array, same length
    seed             integer not null,
    resolution       integer not null,
    software_version text not null,
    vertex_count     integer not null,
    triangle_count   integer not null,
    area_mm2         real not null,
    volume_mm3       real not null,
    -- unit-ball → mm: p_mm = p_unit * radius + centre
    centre_x         real not null,
    centre_y         real not null,
    centre_z         real not null,
    radius           real not null,
    mesh             blob not null,
    -- SHA-256 of the mesh blob, the basis of download ETags
    mesh_sha256      text not null,
    created_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    unique (cohort_id, shape_index)
);

-- Pairwise Chamfer distances among a cohort's shapes (unit-ball coordinates).
create table cohort_metric (
    cohort_id  integer primary key references cohort (cohort_id) on delete cascade,
    -- full symmetric matrix as a JSON array of rows
    matrix     text not null,
    -- summary statistics as JSON (count, mean, std, quantiles, histogram)
    summary    text not null,
    created_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
