-- Cohort science: diversity controls, novelty and anatomy per shape.
alter table cohort add column latent_noise double precision not null default 0
    check (latent_noise >= 0);
alter table cohort add column selection text not null default 'uniform'
    check (selection in ('uniform', 'spread'));
alter table cohort add column min_novelty double precision check (min_novelty >= 0);

alter table shape add column latent_noise double precision not null default 0;
alter table shape add column selection text not null default 'uniform';
alter table shape add column attempt bigint not null default 0;
alter table shape add column redraws bigint not null default 0;
alter table shape add column novelty_cd double precision;
alter table shape add column nearest_training_index bigint;
alter table shape add column novelty_met bigint check (novelty_met in (0, 1));
alter table shape add column anatomy text;
alter table shape add column anatomy_error text;
