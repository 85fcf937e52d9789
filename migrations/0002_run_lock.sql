-- pipewave schema, version 2. Append-only: never edit this file once it has landed.
--
-- At most one calibrate run may write to a database at a time. The run holds this single row
-- (id = 1) for its whole duration: it records the operating-system process id of the run and
-- when it started. A row whose process no longer exists (the run was killed) is stale and is
-- taken over by the next run; see src/db/lock.rs.
CREATE TABLE run_lock (
    id          INTEGER PRIMARY KEY CHECK (id = 1),
    pid         INTEGER NOT NULL,
    started_at  TEXT NOT NULL
);
