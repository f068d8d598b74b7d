-- One row that the readiness probe rewrites to check that the database takes writes.
create table storage_probe (
    id bigint primary key check (id = 1),
    checked_at text not null
);
