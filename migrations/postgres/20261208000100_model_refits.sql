-- Re-fitting a model's training shapes in the service (see the SQLite migration of the same
-- version): a 'refit' job of one 'refit' task per training shape, the refit's settings and
-- each fitted latent. PostgreSQL changes the kind CHECKs in place.
alter table job drop constraint job_kind_check;
alter table job add constraint job_kind_check
    check (kind in ('cohort', 'training', 'fit', 'validation', 'refit'));
alter table task drop constraint task_kind_check;
alter table task add constraint task_kind_check
    check (kind in ('surface', 'anatomy', 'shape', 'metrics', 'training', 'fit', 'validation',
                    'refit'));

create table model_refit (
    model_id   text primary key references model (model_id) on delete cascade,
    job_id     bigint not null unique references job (job_id),
    iterations bigint not null check (iterations > 0),
    seed       bigint not null,
    created_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

create table refit_shape (
    model_id    text not null references model_refit (model_id) on delete cascade,
    shape_index bigint not null check (shape_index >= 0),
    latent      bytea not null,
    chamfer     double precision not null,
    centre_x    double precision not null,
    centre_y    double precision not null,
    centre_z    double precision not null,
    radius      double precision not null,
    created_at  text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    primary key (model_id, shape_index)
);
