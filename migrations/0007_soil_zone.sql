-- pipewave schema, version 7: the soil unit a segment lies in (append-only).
-- `soil_zone` is the optional inventory column of segments.csv (docs/interface.md): the zone of
-- a geotechnical map or survey. Informational for the segment's own fit (not in inputs_hash);
-- segments of one zone are also estimated together (physics §7.11).
ALTER TABLE segments ADD COLUMN soil_zone TEXT;
