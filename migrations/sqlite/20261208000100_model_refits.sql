-- no-transaction
-- Re-fitting a model's training shapes in the service: a 'refit' job of one 'refit' task
-- per training shape (item = the shape's index), each fitting that shape with the network
-- frozen as a new patient is fitted. `model_refit` keeps the settings of a model's refit
-- (one per model) and `refit_shape` each fitted latent; a density sampler asked for
-- "latents": "refitted" draws from them once every training shape has one.
-- The job and task tables are rebuilt (SQLite changes their kind CHECKs only this way), with
-- foreign keys off as the SQLite manual's table-rebuild procedure requires; every statement
-- can run a second time on its own result.

pragma foreign_keys = off;

begin;

drop table if exists job_rebuilt;
create table job_rebuilt (
    job_id           integer primary key,
    kind             text not null
                     check (kind in ('cohort', 'training', 'fit', 'validation', 'refit')),
    -- what to do, as JSON (e.g. {"cohort_id": 3})
    payload          text not null,
    status           text not null default 'queued'
                     check (status in ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    -- how many times the job went from queued to running (a retry starts it again)
    attempts         integer not null default 0,
    progress_done    integer not null default 0,
    progress_total   integer not null default 0,
    -- set by a cancel request; workers learn it with their next heartbeat
    cancel_requested integer not null default 0 check (cancel_requested in (0, 1)),
    -- the error chain of the last failure
    error            text,
    created_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    started_at       text,
    finished_at      text,
    updated_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    -- setup results the job stored (training surfaces reconstructed for novelty)
    setup_done       integer not null default 0
);
insert into job_rebuilt (job_id, kind, payload, status, attempts, progress_done, progress_total,
                         cancel_requested, error, created_at, started_at, finished_at,
                         updated_at, setup_done)
    select job_id, kind, payload, status, attempts, progress_done, progress_total,
           cancel_requested, error, created_at, started_at, finished_at, updated_at, setup_done
    from job;
drop table job;
alter table job_rebuilt rename to job;
create index if not exists job_status_idx on job (status, job_id);
create index if not exists job_updated_idx on job (updated_at, job_id);

drop table if exists task_rebuilt;
create table task_rebuilt (
    task_id          integer primary key,
    job_id           integer not null references job (job_id) on delete cascade,
    -- 'surface': a training shape reconstructed at the cohort's resolution (novelty);
    -- 'anatomy': the training shapes measured (targets); 'shape': one generated shape;
    -- 'metrics': the cohort's pairwise statistics; 'refit': one training shape re-fitted;
    -- 'training', 'fit', 'validation': the whole job
    kind             text not null
                     check (kind in ('surface', 'anatomy', 'shape', 'metrics', 'training', 'fit',
                                     'validation', 'refit')),
    -- the shape index (shape), training-shape index (surface, refit), or -1
    item             integer not null default -1,
    status           text not null default 'queued'
                     check (status in ('queued', 'running', 'done', 'failed', 'cancelled')),
    -- claims so far; lease expiries in a row without a result (a task that keeps killing
    -- its worker is failed after a bound)
    attempts         integer not null default 0,
    stalled_attempts integer not null default 0,
    -- the current claim: its token, who holds it (host/pid/worker) and when it expires
    -- (milliseconds since the Unix epoch on the database's clock); null when not running
    lease_token      text,
    lease_owner      text,
    lease_expires_ms integer,
    error            text,
    created_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    unique (job_id, kind, item),
    check ((status = 'running') = (lease_token is not null))
);
insert into task_rebuilt (task_id, job_id, kind, item, status, attempts, stalled_attempts,
                          lease_token, lease_owner, lease_expires_ms, error, created_at,
                          updated_at)
    select task_id, job_id, kind, item, status, attempts, stalled_attempts, lease_token,
           lease_owner, lease_expires_ms, error, created_at, updated_at
    from task;
drop table task;
alter table task_rebuilt rename to task;
create index if not exists task_claim_idx on task (status, job_id, task_id);

create table if not exists model_refit (
    model_id   text primary key references model (model_id) on delete cascade,
    -- the job that fits the shapes still missing (a retry queues a new one)
    job_id     integer not null unique references job (job_id),
    -- Adam steps of every fit, and the seed of shape 0's (shape i uses seed + 2 i)
    iterations integer not null check (iterations > 0),
    seed       integer not null,
    created_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

create table if not exists refit_shape (
    model_id    text not null references model_refit (model_id) on delete cascade,
    -- the training shape's index
    shape_index integer not null check (shape_index >= 0),
    -- little-endian f32 values, the model's latent dimension
    latent      blob not null,
    -- reconstruction Chamfer distance (unit-ball coordinates) of the fitted latent
    chamfer     real not null,
    -- unit ball → mesh units of the fitted mesh: p = p_unit * radius + centre
    centre_x    real not null,
    centre_y    real not null,
    centre_z    real not null,
    radius      real not null,
    created_at  text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    primary key (model_id, shape_index)
);

commit;

pragma foreign_keys = on;
