-- pipewave schema, version 8: a speed for every segment (physics §7.12); append-only.
-- A segment without measurements gets a prediction from the network soil field: the field's
-- posterior soil at its midpoint, averaged with its contact's prior through the forward model
-- (P81). Predictions are never fits: `latest_fits`, staleness, diagnosis and zones read fits
-- only. One row per segment, replaced by each run that updates the field (the run is named).
CREATE TABLE predictions (
    segment_id                     TEXT PRIMARY KEY NOT NULL
                                   REFERENCES segments(segment_id) ON DELETE CASCADE,
    run_id                         INTEGER REFERENCES runs(id),
    soil_p_wave_speed_m_per_s      REAL,
    soil_p_wave_speed_std_m_per_s  REAL,
    soil_s_wave_speed_m_per_s      REAL,
    soil_s_wave_speed_std_m_per_s  REAL,
    soil_youngs_modulus_pa         REAL,
    soil_youngs_modulus_lo_pa      REAL,
    soil_youngs_modulus_hi_pa      REAL,
    soil_poisson                   REAL,
    soil_poisson_lo                REAL,
    soil_poisson_hi                REAL,
    leak_band_speed_m_per_s        REAL,
    leak_band_speed_std_m_per_s    REAL,
    soil_class                     TEXT,      -- the class (soil_type or soil_zone) it was predicted in
    n_neighbours                   INTEGER,   -- measured segments it was conditioned on
    note                           TEXT NOT NULL DEFAULT '',  -- what the prediction rests on
    created_at                     TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

-- The predicted curve of each predicted segment, as `curves` holds a fit's.
CREATE TABLE prediction_curves (
    segment_id                TEXT NOT NULL REFERENCES predictions(segment_id) ON DELETE CASCADE,
    frequency_hz              REAL NOT NULL,
    phase_speed_m_per_s       REAL,
    phase_speed_std_m_per_s   REAL,
    attenuation_db_per_m      REAL,
    attenuation_std_db_per_m  REAL,
    PRIMARY KEY (segment_id, frequency_hz)
);
