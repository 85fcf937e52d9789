-- pipewave schema, version 1. Append-only: never edit this file once it has landed; add a new
-- numbered file instead. Applied in one exclusive transaction; tracked by PRAGMA user_version.
-- Column names follow docs/interface.md. SI units unless the name says otherwise.

-- The imported inventory, one row per pipe segment, columns as in segments.csv.
CREATE TABLE segments (
    segment_id             TEXT PRIMARY KEY NOT NULL,
    material               TEXT NOT NULL,          -- CI, DI, ST, PVC, MDPE, HDPE, AC (upper case)
    outer_diameter_mm      REAL NOT NULL CHECK (outer_diameter_mm > 0),
    wall_thickness_mm      REAL NOT NULL CHECK (wall_thickness_mm > 0),
    soil_density_kg_m3     REAL NOT NULL,
    pipe_youngs_modulus_pa REAL,                   -- NULL: the material's typical value
    pipe_poisson           REAL,
    pipe_density_kg_m3     REAL,
    pipe_loss_factor       REAL,
    fluid_density_kg_m3    REAL,                   -- NULL: water, 1000
    fluid_bulk_modulus_pa  REAL,                   -- NULL: water, 2.25e9
    length_m               REAL,
    soil_type              TEXT,
    install_year           INTEGER,
    geometry_wkt           TEXT,                   -- LINESTRING (x y, ...) in EPSG:srid
    srid                   INTEGER,
    -- Hash of everything a fit depends on (this row and its measurements); a fit whose
    -- inputs_hash differs is stale and calibrate refits the segment.
    inputs_hash            TEXT NOT NULL DEFAULT '',
    imported_at            TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

-- Field wavenumbers, one row per segment and frequency, as in measurements.csv.
CREATE TABLE measurements (
    id                    INTEGER PRIMARY KEY,
    segment_id            TEXT NOT NULL REFERENCES segments(segment_id) ON DELETE CASCADE,
    omega_rad_s           REAL NOT NULL CHECK (omega_rad_s > 0),
    frequency_hz          REAL NOT NULL CHECK (frequency_hz > 0),
    k_re_rad_per_m        REAL NOT NULL CHECK (k_re_rad_per_m > 0),
    attenuation_np_per_m  REAL NOT NULL CHECK (attenuation_np_per_m >= 0),
    k_re_std              REAL,
    attenuation_std       REAL,
    measured_on           TEXT,
    campaign              TEXT,
    UNIQUE (segment_id, omega_rad_s)
);
CREATE INDEX measurements_segment ON measurements(segment_id);

-- One row per calibrate run.
CREATE TABLE runs (
    id               INTEGER PRIMARY KEY,
    started_at       TEXT NOT NULL,
    finished_at      TEXT,
    status           TEXT NOT NULL DEFAULT 'running',  -- running, finished, interrupted
    seed             INTEGER NOT NULL,
    model            TEXT NOT NULL,                    -- full, seed
    contact_mode     TEXT NOT NULL DEFAULT 'reciprocal',
    method           TEXT NOT NULL DEFAULT 'default',  -- default, paper
    effects          TEXT NOT NULL DEFAULT '',         -- comma-separated effect names
    program_version  TEXT NOT NULL,
    jobs             INTEGER,
    n_segments       INTEGER NOT NULL DEFAULT 0,       -- segments scheduled
    n_ok             INTEGER NOT NULL DEFAULT 0,
    n_flagged        INTEGER NOT NULL DEFAULT 0,
    n_failed         INTEGER NOT NULL DEFAULT 0,
    elapsed_s        REAL
);

-- One row per segment per run.
CREATE TABLE fits (
    id                           INTEGER PRIMARY KEY,
    segment_id                   TEXT NOT NULL REFERENCES segments(segment_id) ON DELETE CASCADE,
    run_id                       INTEGER NOT NULL REFERENCES runs(id),
    status                       TEXT NOT NULL CHECK (status IN ('ok', 'flagged', 'failed')),
    model                        TEXT NOT NULL,
    contact_mode                 TEXT NOT NULL DEFAULT 'reciprocal',
    method                       TEXT NOT NULL DEFAULT 'default',
    effects                      TEXT NOT NULL DEFAULT '',  -- comma-separated effect names
    soil_youngs_modulus_pa       REAL,
    soil_poisson                 REAL,
    contact                      REAL,
    soil_youngs_modulus_std_pa   REAL,   -- NULL where not identifiable
    soil_poisson_std             REAL,
    contact_std                  REAL,
    -- effect parameters and their one-sigma errors (NULL when the effect is off)
    soil_loss_factor             REAL,
    soil_loss_factor_std         REAL,
    air_fraction                 REAL,
    air_fraction_std             REAL,
    wall_thickness_ratio         REAL,
    wall_thickness_ratio_std     REAL,
    pipe_loss_factor             REAL,
    pipe_loss_factor_std         REAL,
    misfit                       REAL,   -- objective value at the optimum
    chi2_per_dof                 REAL,   -- when measurement standard deviations are known
    n_measurements               INTEGER,
    condition_number             REAL,
    correlations                 TEXT,   -- JSON matrix over the fitted parameters
    flags                        TEXT NOT NULL DEFAULT '',  -- comma-separated flag codes
    flag_reasons                 TEXT NOT NULL DEFAULT '',  -- one line per flag
    evaluations                  INTEGER,
    seed                         INTEGER,
    inputs_hash                  TEXT NOT NULL DEFAULT '',
    settings_hash                TEXT NOT NULL DEFAULT '',
    elapsed_ms                   REAL,
    message                      TEXT,   -- why a fit failed
    created_at                   TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    UNIQUE (segment_id, run_id)
);
CREATE INDEX fits_segment ON fits(segment_id, id);

-- Predicted wave speed and attenuation of a fit on the standard frequency grid.
CREATE TABLE curves (
    segment_id            TEXT NOT NULL,
    run_id                INTEGER NOT NULL,
    frequency_hz          REAL NOT NULL,
    phase_speed_m_per_s   REAL,
    attenuation_db_per_m  REAL,
    PRIMARY KEY (segment_id, run_id, frequency_hz),
    FOREIGN KEY (segment_id, run_id) REFERENCES fits(segment_id, run_id) ON DELETE CASCADE
);

-- The newest fit of each segment.
CREATE VIEW latest_fits AS
SELECT f.*
FROM fits f
WHERE f.id = (SELECT MAX(g.id) FROM fits g WHERE g.segment_id = f.segment_id);
