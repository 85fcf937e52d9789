-- pipewave schema, version 3: effects switched on for single segments (append-only).
-- `diagnose` records here the missing effect it named for a segment, so that the next
-- `calibrate` fits that segment with the extended model (the run's own --effects are added).
CREATE TABLE segment_effects (
    segment_id  TEXT PRIMARY KEY NOT NULL REFERENCES segments(segment_id) ON DELETE CASCADE,
    effects     TEXT NOT NULL,                     -- comma-separated effect names
    source      TEXT NOT NULL DEFAULT 'diagnose',  -- who set them
    evidence    TEXT NOT NULL DEFAULT '',          -- why (the diagnosis' evidence line)
    created_at  TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
