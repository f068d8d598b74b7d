-- Conditioned cohorts: target ranges for anatomical measurements.
alter table model add column training_anatomy text;
alter table cohort add column targets text;
alter table cohort add column max_candidates bigint
    check (max_candidates is null or max_candidates between 1 and 100);
alter table shape add column candidates bigint check (candidates is null or candidates >= 1);
alter table shape add column targets_met bigint check (targets_met in (0, 1));
