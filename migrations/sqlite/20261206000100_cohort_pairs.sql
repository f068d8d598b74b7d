-- A cohort's pairwise statistics are computed by several tasks, each over a part of the
-- pairs (all pairs up to 100 shapes, a random sample of them beyond); each task leaves its
-- distances here, and the last one assembles them into cohort_metric and removes them.
create table cohort_pair (
    cohort_id integer not null references cohort (cohort_id) on delete cascade,
    -- shape indices within the cohort, shape_a < shape_b
    shape_a   integer not null,
    shape_b   integer not null,
    -- Chamfer distance (unit-ball coordinates)
    chamfer   real not null,
    primary key (cohort_id, shape_a, shape_b)
);
