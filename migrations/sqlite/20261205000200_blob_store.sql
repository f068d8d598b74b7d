-- Meshes leave the shape table for a content-addressed store: with AORTAGEN_BLOB_STORE=db
-- (the default) the `blob` table below, else a directory or an S3 bucket; a shape row keeps
-- the SHA-256 that names its mesh. Reading a cohort's rows no longer reads its mesh bytes.
-- Objects are written before the rows that name them; objects no row names are swept.
create table blob (
    -- hex SHA-256 of the bytes: the object's name
    sha256     text primary key,
    bytes      blob not null,
    created_at text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

insert into blob (sha256, bytes) select mesh_sha256, mesh from shape where true
    on conflict (sha256) do nothing;

alter table shape drop column mesh;
create index shape_mesh_idx on shape (mesh_sha256);

-- A model's files as one bundle in the blob store (the digest of its manifest object), so
-- a worker on another machine fetches the model instead of needing its directory; null for
-- a model whose files exist only where it was registered.
alter table model add column digest text;
