-- Simulation-ready meshes: each shape's openings cut, capped, optionally extended and
-- remeshed, kept per set of options so a remesh that takes seconds runs once and a repeated
-- download or face table is read back instead.

-- One simulation mesh of a shape: the capped labelled surface in mm and what is known
-- about it, or why none could be made. Keyed by the shape and the canonical JSON of the
-- options (kind, opening distances, flow extension, remesh target); both variants and every
-- file format are written from one row. A row made from other mesh bytes or by another
-- software version is stale and made again.
create table if not exists shape_simulation (
    shape_id         integer not null references shape (shape_id) on delete cascade,
    options          text not null,
    mesh_sha256      text not null,
    software_version text not null,
    -- the capped surface (mesh blob, AGM1) and its face id per triangle (u32 little endian)
    mesh             blob,
    face_ids         blob,
    -- openings, face tables and quality of both variants, remesh report (JSON)
    summary          text,
    -- why no simulation mesh could be made (openings not found, a cut missing the surface),
    -- and the parameter to change, when one is to blame
    error            text,
    error_field      text,
    -- how long the pipeline took
    seconds          real not null,
    created_at       text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    primary key (shape_id, options),
    check ((error is null) = (mesh is not null and face_ids is not null and summary is not null))
);
