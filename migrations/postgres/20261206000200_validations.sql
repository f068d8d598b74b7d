-- Validation of cohorts against real populations, in the service: a model's reference
-- populations (uploaded patient meshes or a measurements table) and validation runs of a
-- cohort against a reference, each a one-task 'validation' job whose report is kept here.

alter table id_high_water drop constraint id_high_water_resource_check;
alter table id_high_water add constraint id_high_water_resource_check
    check (resource in ('job', 'cohort', 'shape', 'anchor', 'reference', 'validation'));

create table reference_population (
    reference_id  bigint primary key,
    model_id      text not null references model (model_id) on delete cascade,
    name          text not null,
    kind          text not null check (kind in ('meshes', 'measurements')),
    shapes        bigint not null check (shapes > 0),
    object_sha256 text not null,
    ignored       text not null default '[]',
    created_at    text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    unique (model_id, name)
);
create index reference_population_model_idx on reference_population (model_id, reference_id);

create table validation (
    validation_id bigint primary key,
    cohort_id     bigint not null references cohort (cohort_id) on delete cascade,
    reference     text not null,
    reference_id  bigint references reference_population (reference_id),
    request       text not null,
    job_id        bigint not null unique references job (job_id),
    report        text,
    verdict       text,
    created_at    text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
create index validation_cohort_idx on validation (cohort_id, validation_id);
create index validation_reference_idx on validation (reference_id);
