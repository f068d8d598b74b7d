-- The cohort service's tables on PostgreSQL: the same schema as migrations/sqlite (a test
-- compares the two), with PostgreSQL's types: bigint for integers, double precision for
-- reals, bytea for blobs. Timestamps are UTC RFC 3339 text with milliseconds, as on SQLite,
-- so they sort and compare as text and the API shows the same strings on both backends.

-- SQLite's date functions in the forms the queries use, so that one SQL text serves both
-- backends. Like SQLite's 'now', the time is the statement's, read from the server's
-- clock (the one clock every machine of a deployment shares).
create function strftime(format text, timevalue text) returns text
language plpgsql stable as $$
begin
    if format = '%Y-%m-%dT%H:%M:%fZ' and timevalue = 'now' then
        return to_char(statement_timestamp() at time zone 'UTC', 'YYYY-MM-DD"T"HH24:MI:SS.MS"Z"');
    end if;
    raise exception 'strftime(%, %) is not supported', format, timevalue;
end
$$;

create function unixepoch(timevalue text, modifier text) returns double precision
language plpgsql stable as $$
begin
    if timevalue = 'now' and modifier = 'subsec' then
        return round(extract(epoch from statement_timestamp())::numeric, 3)::double precision;
    end if;
    raise exception 'unixepoch(%, %) is not supported', timevalue, modifier;
end
$$;

-- SQLite's json_group_array: the values of a group as a JSON array (text), in the order
-- of an ORDER BY inside the call.
create function json_group_array_step(state jsonb, value anyelement) returns jsonb
language sql immutable as $$ select state || jsonb_build_array(value) $$;

create function json_group_array_final(state jsonb) returns text
language sql immutable as $$ select state::text $$;

create aggregate json_group_array(anyelement) (
    sfunc = json_group_array_step,
    stype = jsonb,
    finalfunc = json_group_array_final,
    initcond = '[]'
);

create table model (
    model_id   text primary key,
    dir_path   text not null,
    manifest   text not null,
    status     text not null default 'ready' check (status in ('training', 'ready', 'failed')),
    created_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

create table job (
    job_id           bigint primary key,
    kind             text not null check (kind in ('cohort', 'training')),
    payload          text not null,
    status           text not null default 'queued'
                     check (status in ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    attempts         bigint not null default 0,
    progress_done    bigint not null default 0,
    progress_total   bigint not null default 0,
    cancel_requested bigint not null default 0 check (cancel_requested in (0, 1)),
    error            text,
    created_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    started_at       text,
    finished_at      text,
    updated_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
create index job_status_idx on job (status, job_id);

create table cohort (
    cohort_id       bigint primary key,
    model_id        text not null references model (model_id) on delete restrict,
    job_id          bigint not null unique references job (job_id),
    count           bigint not null check (count > 0),
    arity           bigint not null check (arity > 1),
    weighting       text not null check (weighting in ('equal', 'dirichlet')),
    weights         text,
    seed            bigint not null,
    resolution      bigint not null check (resolution between 32 and 1024),
    idempotency_key text unique,
    request_hash    text not null,
    created_at      text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at      text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
create index cohort_model_idx on cohort (model_id, cohort_id);

create table shape (
    shape_id         bigint primary key,
    cohort_id        bigint not null references cohort (cohort_id) on delete cascade,
    shape_index      bigint not null,
    training_indices text not null,
    weights          text not null,
    seed             bigint not null,
    resolution       bigint not null,
    software_version text not null,
    vertex_count     bigint not null,
    triangle_count   bigint not null,
    area_mm2         double precision not null,
    volume_mm3       double precision not null,
    centre_x         double precision not null,
    centre_y         double precision not null,
    centre_z         double precision not null,
    radius           double precision not null,
    mesh             bytea not null,
    mesh_sha256      text not null,
    created_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    unique (cohort_id, shape_index)
);

create table cohort_metric (
    cohort_id  bigint primary key references cohort (cohort_id) on delete cascade,
    matrix     text not null,
    summary    text not null,
    created_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
