-- Fitting new shapes: a job kind 'fit', the fitted latents ("anchors") and their use in
-- cohorts. PostgreSQL changes the kind's CHECK constraint in place.
alter table job drop constraint job_kind_check;
alter table job add constraint job_kind_check check (kind in ('cohort', 'training', 'fit'));

create table anchor (
    anchor_id     bigint primary key,
    model_id      text not null references model (model_id) on delete cascade,
    job_id        bigint not null unique references job (job_id),
    name          text not null,
    status        text not null default 'fitting' check (status in ('fitting', 'ready', 'failed')),
    source_name   text not null,
    source_path   text not null,
    iterations    bigint not null check (iterations > 0),
    seed          bigint not null,
    latent        bytea,
    chamfer       double precision,
    centre_x      double precision,
    centre_y      double precision,
    centre_z      double precision,
    radius        double precision,
    error         text,
    created_at    text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at    text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    unique (model_id, name)
);
create index anchor_model_idx on anchor (model_id, anchor_id);

create table cohort_anchor (
    cohort_id bigint not null references cohort (cohort_id) on delete cascade,
    position  bigint not null,
    anchor_id bigint not null references anchor (anchor_id),
    primary key (cohort_id, position)
);
create index cohort_anchor_anchor_idx on cohort_anchor (anchor_id);

create table shape_anchor (
    shape_id  bigint not null references shape (shape_id) on delete cascade,
    position  bigint not null,
    anchor_id bigint not null,
    primary key (shape_id, position)
);
