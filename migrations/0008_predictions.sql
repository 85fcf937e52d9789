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

-- What each fit tells the soil field (physics P79): its information about (ln c_P, ln c_S) with
-- the contact ξ and any effect profiled out, divided by the misfit's variance factor (R_B²,
-- P88), so that the field is rebuilt from the database without refitting.
ALTER TABLE fits ADD COLUMN soil_information_pp REAL;
ALTER TABLE fits ADD COLUMN soil_information_ps REAL;
ALTER TABLE fits ADD COLUMN soil_information_ss REAL;

-- SQLite expands `f.*` when a view is created: re-create it so it has the new columns.
DROP VIEW latest_fits;
CREATE VIEW latest_fits AS
SELECT f.*
FROM fits f
WHERE f.id = (SELECT MAX(g.id) FROM fits g WHERE g.segment_id = f.segment_id);

-- How a prediction's leak-band speed follows the soil (∂c/∂ln c_P, ∂c/∂ln c_S at the field's
-- posterior mean, m/s): what `plan` needs to value a measurement nearby (P83).
ALTER TABLE predictions ADD COLUMN leak_band_speed_gradient_ln_cp REAL;
ALTER TABLE predictions ADD COLUMN leak_band_speed_gradient_ln_cs REAL;

-- One row per update of the network soil field (P78–P80): its hyper-parameters (maximum
-- marginal likelihood, or the stated defaults when too few segments are measured), the
-- leave-one-out summary (P82) and the fingerprint of the inputs it was built from (a run whose
-- fingerprint is unchanged leaves the field and the predictions as they are).
CREATE TABLE field_runs (
    id                        INTEGER PRIMARY KEY AUTOINCREMENT,
    run_id                    INTEGER REFERENCES runs(id),
    fingerprint               TEXT NOT NULL,
    n_segments                INTEGER NOT NULL,
    n_measured                INTEGER NOT NULL,
    n_classes                 INTEGER NOT NULL,
    n_predicted               INTEGER NOT NULL,
    n_class_mean_only         INTEGER NOT NULL,
    n_without_speed           INTEGER NOT NULL,
    neighbours                INTEGER NOT NULL,   -- m of the nearest-neighbour conditioning
    correlation_length_m      REAL,
    correlation_length_lo_m   REAL,               -- bounds of the search: a typical segment
    correlation_length_hi_m   REAL,               -- length and the network's extent
    field_var_ln_cp           REAL,               -- B, the field's 2 × 2 covariance
    field_cov_ln_cp_ln_cs     REAL,
    field_var_ln_cs           REAL,
    scatter_var_ln_cp         REAL,               -- T, the per-pipe scatter (diagonal)
    scatter_var_ln_cs         REAL,
    log_likelihood            REAL,
    hyper_source              TEXT NOT NULL,      -- 'marginal_likelihood' or 'defaults'
    loo_z_std                 REAL,
    n_field_outliers          INTEGER NOT NULL DEFAULT 0,
    n_labels_rejected         INTEGER NOT NULL DEFAULT 0,
    elapsed_s                 REAL,
    created_at                TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

-- Each soil class's mean (μ_k of P78) in one field update, with its posterior error.
CREATE TABLE field_classes (
    field_run_id               INTEGER NOT NULL REFERENCES field_runs(id) ON DELETE CASCADE,
    soil_class                 TEXT NOT NULL,
    n_segments                 INTEGER NOT NULL,
    n_measured                 INTEGER NOT NULL,
    mean_ln_cp                 REAL,
    mean_ln_cs                 REAL,
    std_ln_cp                  REAL,
    std_ln_cs                  REAL,
    PRIMARY KEY (field_run_id, soil_class)
);

-- Every segment as the latest field update saw it: its label, the class it was given (the
-- label, or its neighbourhood's majority when the neighbourhood rejects it), and for a
-- measured segment its leave-one-out prediction and z (P82). Replaced by each update.
CREATE TABLE field_segments (
    segment_id                         TEXT PRIMARY KEY NOT NULL
                                       REFERENCES segments(segment_id) ON DELETE CASCADE,
    field_run_id                       INTEGER REFERENCES field_runs(id),
    label                              TEXT,
    soil_class                         TEXT,
    label_rejected                     INTEGER NOT NULL DEFAULT 0,
    measured                           INTEGER NOT NULL DEFAULT 0,
    field_leak_band_speed_m_per_s      REAL,
    field_leak_band_speed_std_m_per_s  REAL,
    loo_z                              REAL,
    field_outlier                      INTEGER NOT NULL DEFAULT 0,
    note                               TEXT NOT NULL DEFAULT ''
);

-- The next measurement campaign (P83), as `plan` chose it last: best first.
CREATE TABLE plan_picks (
    rank                           INTEGER PRIMARY KEY,
    segment_id                     TEXT NOT NULL REFERENCES segments(segment_id) ON DELETE CASCADE,
    field_run_id                   INTEGER REFERENCES field_runs(id),
    expected_gain                  REAL NOT NULL,
    leak_band_speed_std_m_per_s    REAL,
    weight                         REAL NOT NULL,
    created_at                     TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
