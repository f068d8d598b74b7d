-- Cohort science: diversity controls on the request, novelty against the training shapes
-- and anatomical measurements per generated shape.

-- Gaussian noise added to the mixed latent, in units of the training latents' per-dimension
-- standard deviation (0 = plain convex combinations).
alter table cohort add column latent_noise real not null default 0 check (latent_noise >= 0);
-- How the mixed training latents are picked: 'uniform' or 'spread' (k-means++ style).
alter table cohort add column selection text not null default 'uniform'
    check (selection in ('uniform', 'spread'));
-- Smallest accepted Chamfer distance to the nearest training shape, or null for no bound.
alter table cohort add column min_novelty real check (min_novelty >= 0);

-- The diversity settings the shape was drawn with (copied from its cohort).
alter table shape add column latent_noise real not null default 0;
alter table shape add column selection text not null default 'uniform';
-- Which draw was kept (0 = the first); `seed` is that draw's seed.
alter table shape add column attempt integer not null default 0;
-- Draws rejected for being too close to a training shape.
alter table shape add column redraws integer not null default 0;
-- Chamfer distance (unit-ball coordinates) to the nearest training shape, and its index.
alter table shape add column novelty_cd real;
alter table shape add column nearest_training_index integer;
-- 1 when the shape meets the cohort's min_novelty (or there is none), 0 when no draw did.
alter table shape add column novelty_met integer check (novelty_met in (0, 1));
-- Anatomical measurements in mm as JSON, or null with the reason in anatomy_error.
alter table shape add column anatomy text;
alter table shape add column anatomy_error text;
