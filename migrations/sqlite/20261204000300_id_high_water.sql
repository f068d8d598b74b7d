-- Ids are never reused. SQLite gives a new row of an `integer primary key` table one above
-- the largest id present, so after the newest job, cohort, shape or anchor is deleted its id
-- (and its URL, served with immutable caching) would go to the next one. Ids are instead
-- allocated from this table, whose `last_id` per resource only goes up (src/db/ids.rs).
-- Seeded with the largest ids present; ids deleted before this migration cannot be known.

create table if not exists id_high_water (
    resource text primary key check (resource in ('job', 'cohort', 'shape', 'anchor')),
    -- the largest id ever allocated for the resource
    last_id  integer not null check (last_id >= 0)
);

insert or ignore into id_high_water (resource, last_id)
    select 'job', coalesce(max(job_id), 0) from job
    union all select 'cohort', coalesce(max(cohort_id), 0) from cohort
    union all select 'shape', coalesce(max(shape_id), 0) from shape
    union all select 'anchor', coalesce(max(anchor_id), 0) from anchor;
