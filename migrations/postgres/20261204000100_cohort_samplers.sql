-- Samplers: a cohort's request may name a density sampler (stored as JSON, null: convex);
-- such a cohort mixes one sampled latent plus its anchors, so its arity may be 1.
alter table cohort drop constraint cohort_arity_check;
alter table cohort add constraint cohort_arity_check check (arity >= 1);
alter table cohort add column sampler text;
