-- pipewave schema, version 14: staleness from the stored rows themselves (append-only).
--
-- A segment's inputs_hash now covers every column of its `segments` row and of each of its
-- `measurements` rows, as stored (src/db/staleness.rs), so that an edit made with any tool
-- makes its fit stale. The hashes of the earlier form are cleared here: the next calibrate
-- computes every segment's hash afresh (an empty hash is "not yet hashed", not "edited"), and
-- since no stored fit was made from a hash of the new form, it refits every measured segment
-- once.
UPDATE segments SET inputs_hash = '';
