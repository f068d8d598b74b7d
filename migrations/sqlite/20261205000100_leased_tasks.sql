-- no-transaction
-- Work any process on any machine may take: a job becomes tasks (a cohort's setup steps,
-- one task per shape, its metrics step; a training; a fit). A worker claims a task with a
-- lease: a random token and an expiry on the database's clock, extended by heartbeats. A
-- task whose lease expired is taken over by another worker; a result is committed only
-- under the token of the lease it was claimed with, so a worker that was paused past its
-- lease cannot commit late. Processes no longer re-queue each other's work at start-up, so
-- the job columns that did (claim_progress, claim_setup, stalled_attempts) go.
-- The job table is rebuilt (SQLite drops those columns and changes the kind CHECK, which
-- gains 'validation', only this way), with foreign keys off as the SQLite manual's
-- table-rebuild procedure requires; every statement can run a second time on its own
-- result.

pragma foreign_keys = off;

begin;

drop table if exists job_rebuilt;
create table job_rebuilt (
    job_id           integer primary key,
    kind             text not null check (kind in ('cohort', 'training', 'fit', 'validation')),
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

create table if not exists task (
    task_id          integer primary key,
    job_id           integer not null references job (job_id) on delete cascade,
    -- 'surface': a training shape reconstructed at the cohort's resolution (novelty);
    -- 'anatomy': the training shapes measured (targets); 'shape': one generated shape;
    -- 'metrics': the cohort's pairwise statistics; 'training', 'fit', 'validation': the
    -- whole job
    kind             text not null
                     check (kind in ('surface', 'anatomy', 'shape', 'metrics', 'training', 'fit',
                                     'validation')),
    -- the shape index (shape), training-shape index (surface), or -1
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
create index if not exists task_claim_idx on task (status, job_id, task_id);

-- Jobs that were running when this version started are queued again; their tasks are
-- created when a worker next looks at them.
update job set status = 'queued' where status = 'running';

commit;

pragma foreign_keys = on;
