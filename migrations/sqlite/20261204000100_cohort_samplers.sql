-- no-transaction
-- Samplers: a cohort may draw its latents from a density model of the training latents
-- instead of convex combinations. Its request's `sampler` is stored as JSON (null: convex),
-- and such a cohort mixes one sampled latent plus its anchors, so its arity may be 1.
-- SQLite cannot relax a CHECK constraint in place, so the cohort table is rebuilt with
-- foreign keys off (the shape, cohort_metric and cohort_anchor tables reference it), as the
-- SQLite manual's table-rebuild procedure requires, inside one explicit transaction. Every
-- statement can run a second time on its own result, so a process killed between the
-- commit and the migration's record runs it again at the next start without harm.

pragma foreign_keys = off;

begin;

drop table if exists cohort_rebuilt;
create table cohort_rebuilt (
    cohort_id       integer primary key,
    model_id        text not null references model (model_id) on delete restrict,
    job_id          integer not null unique references job (job_id),
    count           integer not null check (count > 0),
    -- training shapes mixed (convex sampler, ≥ 2) or 1 + anchors (density sampler)
    arity           integer not null check (arity >= 1),
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
    updated_at      text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    latent_noise    real not null default 0 check (latent_noise >= 0),
    selection       text not null default 'uniform' check (selection in ('uniform', 'spread')),
    min_novelty     real check (min_novelty >= 0),
    targets         text,
    max_candidates  integer check (max_candidates is null or max_candidates between 1 and 100),
    -- the request's sampler as JSON ({"kind": "pca_gaussian", …}), or null for convex
    sampler         text
);

insert into cohort_rebuilt (cohort_id, model_id, job_id, count, arity, weighting, weights, seed,
                            resolution, idempotency_key, request_hash, created_at, updated_at,
                            latent_noise, selection, min_novelty, targets, max_candidates)
    select cohort_id, model_id, job_id, count, arity, weighting, weights, seed,
           resolution, idempotency_key, request_hash, created_at, updated_at,
           latent_noise, selection, min_novelty, targets, max_candidates
    from cohort;

drop table cohort;
alter table cohort_rebuilt rename to cohort;
create index if not exists cohort_model_idx on cohort (model_id, cohort_id);

commit;

pragma foreign_keys = on;
