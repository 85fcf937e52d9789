-- pipewave schema, version 6: soil zones (physics §7.11, issue 12); append-only.
-- One row per soil zone per estimate: the zone's E_m and ν_m with 95 % profile intervals, its
-- c_P and c_S (at the members' mean soil density) with 95 % intervals, the scatter used
-- between its segments and how it was chosen (`fixed` or `estimated`), the zone's χ²/dof and
-- flags, the segments that disagree with it (`outliers`, comma-separated, with one reason a
-- line), and `members_hash`, the hash of the member fits it was made from: the zone is
-- estimated again when a member's fit changes.
CREATE TABLE zone_fits (
    id INTEGER PRIMARY KEY,
    soil_zone TEXT NOT NULL,
    run_id INTEGER REFERENCES runs(id),
    n_segments INTEGER NOT NULL,
    n_outliers INTEGER NOT NULL,
    soil_youngs_modulus_pa REAL,
    soil_youngs_modulus_lo_pa REAL,
    soil_youngs_modulus_hi_pa REAL,
    soil_poisson REAL,
    soil_poisson_lo REAL,
    soil_poisson_hi REAL,
    soil_density_kg_m3 REAL,
    soil_p_wave_speed_m_per_s REAL,
    soil_p_wave_speed_lo_m_per_s REAL,
    soil_p_wave_speed_hi_m_per_s REAL,
    soil_s_wave_speed_m_per_s REAL,
    soil_s_wave_speed_lo_m_per_s REAL,
    soil_s_wave_speed_hi_m_per_s REAL,
    scatter_youngs_modulus_decades REAL NOT NULL,
    scatter_poisson REAL NOT NULL,
    scatter_source TEXT NOT NULL,
    chi2_per_dof REAL,
    flags TEXT NOT NULL DEFAULT '',
    outliers TEXT NOT NULL DEFAULT '',
    outlier_reasons TEXT NOT NULL DEFAULT '',
    members_hash TEXT NOT NULL,
    elapsed_ms REAL,
    created_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
CREATE INDEX zone_fits_zone ON zone_fits (soil_zone, id);

-- One row per member of a zone estimate: its fit, its values shrunk toward the zone, and the
-- outlier statistic (its misfit at the zone with the scatter allowed for; χ²₂).
CREATE TABLE zone_members (
    zone_fit_id INTEGER NOT NULL REFERENCES zone_fits(id),
    segment_id TEXT NOT NULL,
    fit_id INTEGER NOT NULL,
    shrunk_soil_youngs_modulus_pa REAL,
    shrunk_soil_poisson REAL,
    statistic REAL,
    zone_outlier INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (zone_fit_id, segment_id)
);
