-- Simulation-ready meshes, kept per shape and set of options.
create table shape_simulation (
    shape_id         bigint not null references shape (shape_id) on delete cascade,
    options          text not null,
    mesh_sha256      text not null,
    software_version text not null,
    mesh             bytea,
    face_ids         bytea,
    summary          text,
    error            text,
    error_field      text,
    seconds          double precision not null,
    created_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    primary key (shape_id, options),
    check ((error is null) = (mesh is not null and face_ids is not null and summary is not null))
);
