-- What a cohort needs before its first shape, kept across restarts: the training shapes
-- as the model reconstructs them at a resolution (the surfaces novelty is measured
-- against), stored one by one as they are computed, so a process that is stopped often
-- still completes them over several runs.
create table novelty_surface (
    model_id    text not null references model (model_id) on delete cascade,
    resolution  integer not null,
    shape_index integer not null,
    -- the unit-ball mesh in the stored mesh encoding (src/formats/mesh_blob.rs)
    mesh        blob not null,
    created_at  text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    primary key (model_id, resolution, shape_index)
);

-- setup results a job stored (they count as progress when a restart looks for stalls)
alter table job add column setup_done integer not null default 0;
-- setup_done when the job was last claimed
alter table job add column claim_setup integer not null default 0;
