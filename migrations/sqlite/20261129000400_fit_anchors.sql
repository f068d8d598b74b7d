-- no-transaction
-- Fitting new shapes: a job kind 'fit', the fitted latents ("anchors") and their use in
-- cohorts. SQLite cannot change a CHECK constraint in place, so the job table is rebuilt
-- (with foreign keys off, as the SQLite manual's table-rebuild procedure requires: the
-- cohort table references job) inside one explicit transaction. Every statement can run a
-- second time on its own result (no ALTER TABLE … ADD COLUMN): the migration is recorded
-- after the commit, so a process killed in between runs it again at the next start.

pragma foreign_keys = off;

begin;

drop table if exists job_rebuilt;
create table job_rebuilt (
    job_id           integer primary key,
    kind             text not null check (kind in ('cohort', 'training', 'fit')),
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
    updated_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    -- progress_done when the job was last claimed (compared at recovery)
    claim_progress   integer not null default 0,
    -- consecutive interrupted runs that committed no new progress
    stalled_attempts integer not null default 0
);

insert into job_rebuilt (job_id, kind, payload, status, attempts, progress_done, progress_total,
                         cancel_requested, error, created_at, started_at, finished_at,
                         updated_at, claim_progress, stalled_attempts)
    select job_id, kind, payload, status, attempts, progress_done, progress_total,
           cancel_requested, error, created_at, started_at, finished_at,
           updated_at, claim_progress, stalled_attempts
    from job;

drop table job;
alter table job_rebuilt rename to job;
create index if not exists job_status_idx on job (status, job_id);

-- A latent fitted to an uploaded mesh for a model whose network stays frozen. The row is
-- created with the request ('fitting') and completed by its job ('ready' or 'failed').
create table if not exists anchor (
    anchor_id     integer primary key,
    model_id      text not null references model (model_id) on delete cascade,
    job_id        integer not null unique references job (job_id),
    -- unique per model
    name          text not null,
    status        text not null default 'fitting' check (status in ('fitting', 'ready', 'failed')),
    -- the uploaded file's name and where its bytes wait for the job
    source_name   text not null,
    source_path   text not null,
    iterations    integer not null check (iterations > 0),
    seed          integer not null,
    -- little-endian f32 values, the model's latent dimension; null until ready
    latent        blob,
    -- reconstruction Chamfer distance (unit-ball coordinates) of the fitted latent
    chamfer       real,
    -- unit ball → mesh units of the fitted mesh: p = p_unit * radius + centre
    centre_x      real,
    centre_y      real,
    centre_z      real,
    radius        real,
    error         text,
    created_at    text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at    text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    unique (model_id, name)
);
create index if not exists anchor_model_idx on anchor (model_id, anchor_id);

-- Anchors forced into every shape of a cohort, in request order. An anchor a cohort uses
-- cannot be deleted (no cascade on anchor_id).
create table if not exists cohort_anchor (
    cohort_id integer not null references cohort (cohort_id) on delete cascade,
    position  integer not null,
    anchor_id integer not null references anchor (anchor_id),
    primary key (cohort_id, position)
);
create index if not exists cohort_anchor_anchor_idx on cohort_anchor (anchor_id);

-- The anchors a shape mixed, in mixture order (their weights follow the training ones).
create table if not exists shape_anchor (
    shape_id  integer not null references shape (shape_id) on delete cascade,
    position  integer not null,
    anchor_id integer not null,
    primary key (shape_id, position)
);

commit;

pragma foreign_keys = on;
