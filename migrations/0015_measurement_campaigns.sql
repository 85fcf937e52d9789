-- pipewave schema, version 15: measurements keep their history (append-only).
--
-- A measurement is identified by its segment, its campaign and its frequency: importing the
-- same campaign again updates its rows, a new campaign adds rows, and the earlier campaigns
-- stay. Rows without a campaign belong to the campaign `unnamed`, so that re-importing the same
-- file updates them and adds nothing. Every existing row is kept with its id (the order in
-- which a segment's campaigns were first imported is the order of their smallest row id), its
-- label kept as it was and a blank label becoming `unnamed`. `note` holds what the wavenumber
-- estimate says of a band (`reflection_suspected`, ...), which used to be written into the
-- campaign label. A segment whose frequencies carried several labels has several campaigns
-- from now on.
--
-- The frequency key is exact here (UNIQUE on ω); import keeps its relative tolerance of one
-- part in 10⁹ (src/db/import/measurements.rs) when it matches a row to a stored one.
CREATE TABLE measurements_v15 (
    id                    INTEGER PRIMARY KEY,
    segment_id            TEXT NOT NULL REFERENCES segments(segment_id) ON DELETE CASCADE,
    campaign              TEXT NOT NULL DEFAULT 'unnamed' CHECK (campaign <> ''),
    omega_rad_s           REAL NOT NULL CHECK (omega_rad_s > 0),
    frequency_hz          REAL NOT NULL CHECK (frequency_hz > 0),
    k_re_rad_per_m        REAL NOT NULL CHECK (k_re_rad_per_m > 0),
    attenuation_np_per_m  REAL NOT NULL CHECK (attenuation_np_per_m >= 0),
    k_re_std              REAL,
    attenuation_std       REAL,
    measured_on           TEXT,
    note                  TEXT,
    UNIQUE (segment_id, campaign, omega_rad_s)
);
INSERT INTO measurements_v15 (id, segment_id, campaign, omega_rad_s, frequency_hz,
    k_re_rad_per_m, attenuation_np_per_m, k_re_std, attenuation_std, measured_on, note)
SELECT id, segment_id, COALESCE(NULLIF(TRIM(campaign), ''), 'unnamed'), omega_rad_s,
    frequency_hz, k_re_rad_per_m, attenuation_np_per_m, k_re_std, attenuation_std, measured_on,
    NULL
FROM measurements;
DROP TABLE measurements;
ALTER TABLE measurements_v15 RENAME TO measurements;
CREATE INDEX measurements_segment ON measurements(segment_id, campaign);

-- The campaigns a fit was made from, comma-separated (the latest first).
ALTER TABLE fits ADD COLUMN campaigns TEXT NOT NULL DEFAULT '';

-- SQLite expands `f.*` when a view is created: re-create it so it has the new column.
DROP VIEW latest_fits;
CREATE VIEW latest_fits AS
SELECT f.*
FROM fits f
WHERE f.id = (SELECT MAX(g.id) FROM fits g WHERE g.segment_id = f.segment_id);

-- Every stored measurement, of every campaign, with its campaign's place in the segment's
-- history (1 = the first imported), for reading a segment's history with any SQL tool.
CREATE VIEW measurement_history AS
SELECT m.segment_id, m.campaign, m.frequency_hz, m.k_re_rad_per_m,
       6.283185307179586 * m.frequency_hz / m.k_re_rad_per_m AS phase_speed_m_per_s,
       m.attenuation_np_per_m, m.k_re_std, m.attenuation_std, m.measured_on, m.note,
       (SELECT COUNT(DISTINCT c.campaign) FROM measurements c
        WHERE c.segment_id = m.segment_id
          AND (SELECT MIN(id) FROM measurements d WHERE d.segment_id = m.segment_id
               AND d.campaign = c.campaign)
              <= (SELECT MIN(id) FROM measurements e WHERE e.segment_id = m.segment_id
                  AND e.campaign = m.campaign)) AS campaign_import_order
FROM measurements m;
