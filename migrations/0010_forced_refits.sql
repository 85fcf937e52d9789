-- pipewave schema: segments a `calibrate --force` run was asked to refit and has not refitted
-- yet. Append-only: never edit this file once it has landed.
--
-- A forced run lists its segments here when it starts; storing a segment's next fit removes its
-- row. A forced run that is stopped (Ctrl-C, killed) therefore leaves the segments it did not
-- reach, and the next calibrate run treats them as stale and fits them, as its summary line
-- says.
CREATE TABLE forced_refits (
    segment_id TEXT PRIMARY KEY NOT NULL REFERENCES segments(segment_id) ON DELETE CASCADE,
    run_id     INTEGER NOT NULL REFERENCES runs(id)
);
