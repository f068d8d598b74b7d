-- Rendered preview pictures of generated shapes, kept so a grid of thumbnails is drawn once.
-- Keyed by the shape and the digest of the mesh it was drawn from, so a shape id reused after
-- a deletion never shows an old picture; removed with the shape.
create table shape_thumbnail (
    shape_id    integer primary key references shape (shape_id) on delete cascade,
    mesh_sha256 text not null,
    -- side of the square picture, in pixels
    size        integer not null,
    png         blob not null,
    created_at  text not null default (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
