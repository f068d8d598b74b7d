-- Ids are never reused: allocated from this table, whose mark per resource only goes up.
create table id_high_water (
    resource text primary key check (resource in ('job', 'cohort', 'shape', 'anchor')),
    last_id  bigint not null check (last_id >= 0)
);

insert into id_high_water (resource, last_id)
    select 'job', coalesce(max(job_id), 0) from job
    union all select 'cohort', coalesce(max(cohort_id), 0) from cohort
    union all select 'shape', coalesce(max(shape_id), 0) from shape
    union all select 'anchor', coalesce(max(anchor_id), 0) from anchor
    on conflict do nothing;
