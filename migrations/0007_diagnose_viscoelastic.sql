-- pipewave schema, version 7: the exponent n of the viscoelastic wall (physics §8 E7, eq. P70,
-- effect `viscoelastic_wall`, issue 13) and its one-sigma error, beside the other effects'
-- parameters (NULL when the effect is off); append-only.
ALTER TABLE fits ADD COLUMN viscoelastic_exponent REAL;
ALTER TABLE fits ADD COLUMN viscoelastic_exponent_std REAL;

-- SQLite expands `f.*` when a view is created: re-create it so it has the new columns.
DROP VIEW latest_fits;
CREATE VIEW latest_fits AS
SELECT f.*
FROM fits f
WHERE f.id = (SELECT MAX(g.id) FROM fits g WHERE g.segment_id = f.segment_id);
