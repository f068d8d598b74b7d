-- Conditioned cohorts: target ranges for anatomical measurements, searched per shape over a
-- bounded number of candidates.

-- The training shapes' measurements in mm (JSON: resolution and one entry per training
-- shape, null where a shape could not be measured), computed once per model on first use.
alter table model add column training_anatomy text;

-- Target ranges keyed by measurement name (JSON), or null for an unconditioned cohort.
alter table cohort add column targets text;
-- Most candidates drawn per shape when targets are set.
alter table cohort add column max_candidates integer
    check (max_candidates is null or max_candidates between 1 and 100);

-- Candidates drawn for the shape (null for an unconditioned cohort).
alter table shape add column candidates integer check (candidates is null or candidates >= 1);
-- 1 when the kept shape meets every target, 0 when no candidate did (the closest was kept).
alter table shape add column targets_met integer check (targets_met in (0, 1));
