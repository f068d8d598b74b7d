-- Rendered preview pictures of generated shapes.
create table shape_thumbnail (
    shape_id    bigint primary key references shape (shape_id) on delete cascade,
    mesh_sha256 text not null,
    size        bigint not null,
    png         bytea not null,
    created_at  text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
