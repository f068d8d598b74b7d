-- What a cohort needs before its first shape, kept across restarts.
create table novelty_surface (
    model_id    text not null references model (model_id) on delete cascade,
    resolution  bigint not null,
    shape_index bigint not null,
    mesh        bytea not null,
    created_at  text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    primary key (model_id, resolution, shape_index)
);

alter table job add column setup_done bigint not null default 0;
alter table job add column claim_setup bigint not null default 0;
