-- Pair distances left by the metrics tasks until the last one assembles them (see the
-- SQLite migration of the same version).
create table cohort_pair (
    cohort_id bigint not null references cohort (cohort_id) on delete cascade,
    shape_a   bigint not null,
    shape_b   bigint not null,
    chamfer   double precision not null,
    primary key (cohort_id, shape_a, shape_b)
);
