-- Interrupted jobs fail only after several interruptions in a row without progress.
alter table job add column claim_progress bigint not null default 0;
alter table job add column stalled_attempts bigint not null default 0;
