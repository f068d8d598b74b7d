-- Meshes leave the shape table for a content-addressed store (see the SQLite migration of
-- the same version).
create table blob (
    sha256     text primary key,
    bytes      bytea not null,
    created_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

insert into blob (sha256, bytes) select mesh_sha256, mesh from shape
    on conflict (sha256) do nothing;

alter table shape drop column mesh;
create index shape_mesh_idx on shape (mesh_sha256);

alter table model add column digest text;
