-- pipewave schema, version 12: two optional inventory columns for the soil field (append-only).
--
-- `risk_weight`: how much a segment's speed error matters to the utility (finite, >= 0). `plan`
-- weights the segment's relative speed variance by it in P83 instead of by its length; blank:
-- its length.
-- `soil_class_override`: the soil class the engineer has checked for this segment. The field
-- (P78-P81) uses it as the segment's class without the neighbourhood test that may reject a
-- label; it also counts as the segment's label in its neighbours' votes.
-- Neither column enters inputs_hash: changing them never refits a segment.
ALTER TABLE segments ADD COLUMN risk_weight REAL;
ALTER TABLE segments ADD COLUMN soil_class_override TEXT;
-- Whether the latest field update took the segment's class from `soil_class_override`.
ALTER TABLE field_segments ADD COLUMN class_overridden INTEGER NOT NULL DEFAULT 0;
