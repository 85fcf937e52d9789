-- pipewave schema, version 13: the field update that made each prediction (append-only).
--
-- A field update now overwrites each predicted segment's row and curve points in place
-- (an upsert) instead of deleting every prediction and inserting them again, which wrote
-- and deleted each of the curves' points twice. The rows it did not write, segments that
-- are measured now or left the inventory, are those with another `field_run_id`; the update
-- deletes them at its end, in the same transaction.
ALTER TABLE predictions ADD COLUMN field_run_id INTEGER;
