-- A job interrupted by a dying process is failed only after several interruptions in a
-- row that made no durable progress: a job that keeps killing the process must not loop
-- forever, but a long job on a host that restarts often must still finish.

-- progress_done when the job was last claimed (compared at recovery)
alter table job add column claim_progress integer not null default 0;
-- consecutive interrupted runs that committed no new progress
alter table job add column stalled_attempts integer not null default 0;
