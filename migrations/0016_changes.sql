-- pipewave schema, version 16: what changed between a segment's campaigns (append-only).
--
-- Every calibrate fit of a measured segment stores one `changes` row: the change test of its
-- latest campaign against the one before it (model §7.14, P94–P96), or `one_campaign`. The
-- row of a segment's latest calibrate fit is its current finding (view `latest_changes`).
-- `campaign_speeds` holds the leak-band speed of each campaign fitted on its own, by run, so
-- that a segment's speed by campaign can be read (view `speed_history`: each campaign's speed
-- from the latest run that fitted it).
CREATE TABLE changes (
    id                       INTEGER PRIMARY KEY,
    segment_id               TEXT NOT NULL REFERENCES segments(segment_id) ON DELETE CASCADE,
    run_id                   INTEGER NOT NULL REFERENCES runs(id),
    fit_id                   INTEGER REFERENCES fits(id) ON DELETE SET NULL,
    campaign                 TEXT NOT NULL,
    since_campaign           TEXT,
    status                   TEXT NOT NULL
        CHECK (status IN ('changed', 'unchanged', 'one_campaign', 'untested')),
    statistic                REAL,
    dof                      INTEGER,
    p_value                  REAL,
    alpha                    REAL,
    chi2_one_state           REAL,
    chi2_earlier             REAL,
    chi2_latest              REAL,
    effect                   TEXT,
    ambiguous_with           TEXT NOT NULL DEFAULT '',
    effect_value_before      REAL,
    effect_value_after       REAL,
    causes                   TEXT NOT NULL DEFAULT '',
    earlier_soil_youngs_modulus_pa REAL,
    earlier_soil_poisson     REAL,
    earlier_contact          REAL,
    leak_band_speed_pct      REAL,
    leak_band_speed_pct_std  REAL,
    pooled                   INTEGER NOT NULL DEFAULT 0,
    note                     TEXT
);
CREATE INDEX changes_segment ON changes(segment_id, id);

CREATE VIEW latest_changes AS
SELECT c.*
FROM changes c
WHERE c.id = (SELECT MAX(d.id) FROM changes d WHERE d.segment_id = c.segment_id);

CREATE TABLE campaign_speeds (
    id                          INTEGER PRIMARY KEY,
    segment_id                  TEXT NOT NULL REFERENCES segments(segment_id) ON DELETE CASCADE,
    run_id                      INTEGER NOT NULL REFERENCES runs(id),
    campaign                    TEXT NOT NULL,
    measured_on                 TEXT,
    leak_band_speed_m_per_s     REAL,
    leak_band_speed_std_m_per_s REAL,
    chi2                        REAL,
    n_measurements              INTEGER NOT NULL,
    soil_youngs_modulus_pa      REAL,
    soil_poisson                REAL,
    contact                     REAL,
    UNIQUE (segment_id, run_id, campaign)
);

CREATE VIEW speed_history AS
SELECT s.segment_id, s.campaign, s.measured_on, s.leak_band_speed_m_per_s,
       s.leak_band_speed_std_m_per_s, s.chi2, s.n_measurements, s.run_id
FROM campaign_speeds s
WHERE s.run_id = (SELECT MAX(t.run_id) FROM campaign_speeds t
                  WHERE t.segment_id = s.segment_id AND t.campaign = s.campaign);

-- Fits of segments measured in more than one campaign were made before the change test: they
-- are stale, so the next calibrate tests and pools them (one refit each).
UPDATE fits SET inputs_hash = ''
WHERE segment_id IN (SELECT segment_id FROM measurements
                     GROUP BY segment_id HAVING COUNT(DISTINCT campaign) > 1);
