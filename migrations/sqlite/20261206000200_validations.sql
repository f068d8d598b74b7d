-- Validation of cohorts against real populations, in the service: a model's reference
-- populations (uploaded patient meshes or a measurements table) and validation runs of a
-- cohort against a reference, each a one-task 'validation' job whose report is kept here.

-- Ids of references and validations are never reused either: the resource list of
-- id_high_water gains them (SQLite changes a CHECK only by rebuilding the table).
create table id_high_water_rebuilt (
    resource text primary key
             check (resource in ('job', 'cohort', 'shape', 'anchor', 'reference', 'validation')),
    last_id  integer not null check (last_id >= 0)
);
insert into id_high_water_rebuilt (resource, last_id)
    select resource, last_id from id_high_water;
drop table id_high_water;
alter table id_high_water_rebuilt rename to id_high_water;

create table reference_population (
    reference_id  integer primary key,
    model_id      text not null references model (model_id) on delete cascade,
    -- unique per model
    name          text not null,
    -- 'meshes' (surfaces and their measurements) or 'measurements' (a table)
    kind          text not null check (kind in ('meshes', 'measurements')),
    -- shapes (meshes) or rows (table)
    shapes        integer not null check (shapes > 0),
    -- the uploaded content as an object: a bundle of the meshes, or the table's text
    object_sha256 text not null,
    -- table columns accepted but not compared, as JSON [[column, why], …]
    ignored       text not null default '[]',
    created_at    text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    unique (model_id, name)
);
create index reference_population_model_idx on reference_population (model_id, reference_id);

create table validation (
    validation_id integer primary key,
    cohort_id     integer not null references cohort (cohort_id) on delete cascade,
    -- 'heldout', 'training', or a reference population's id as text
    reference     text not null,
    reference_id  integer references reference_population (reference_id),
    -- the request as given, defaults filled in (JSON)
    request       text not null,
    job_id        integer not null unique references job (job_id),
    -- the report (JSON) once the job succeeded, and its overall verdict
    report        text,
    verdict       text,
    created_at    text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
create index validation_cohort_idx on validation (cohort_id, validation_id);
create index validation_reference_idx on validation (reference_id);
