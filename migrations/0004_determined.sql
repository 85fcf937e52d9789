-- pipewave schema, version 4: what the data determine (physics §7.10, issue 9); append-only.
-- For every fitted segment: the soil's compressional and shear speeds with one-sigma errors,
-- 95 % intervals of E_m, ν_m and ξ, the leak-band speed's error, and notes (what the data
-- leave undetermined, as codes with reasons) beside the flags (what a user must act on).
-- `algorithm_version` is the fitting algorithm that made the fit: a fit made by another
-- version is refitted by the next calibrate run (NULL: made before this migration).
ALTER TABLE fits ADD COLUMN soil_p_wave_speed_m_per_s REAL;
ALTER TABLE fits ADD COLUMN soil_p_wave_speed_std_m_per_s REAL;
ALTER TABLE fits ADD COLUMN soil_s_wave_speed_m_per_s REAL;
ALTER TABLE fits ADD COLUMN soil_s_wave_speed_std_m_per_s REAL;
ALTER TABLE fits ADD COLUMN soil_youngs_modulus_lo_pa REAL;
ALTER TABLE fits ADD COLUMN soil_youngs_modulus_hi_pa REAL;
ALTER TABLE fits ADD COLUMN soil_poisson_lo REAL;
ALTER TABLE fits ADD COLUMN soil_poisson_hi REAL;
ALTER TABLE fits ADD COLUMN contact_lo REAL;
ALTER TABLE fits ADD COLUMN contact_hi REAL;
ALTER TABLE fits ADD COLUMN leak_band_speed_m_per_s REAL;
ALTER TABLE fits ADD COLUMN leak_band_speed_std_m_per_s REAL;
ALTER TABLE fits ADD COLUMN notes TEXT NOT NULL DEFAULT '';         -- comma-separated note codes
ALTER TABLE fits ADD COLUMN note_reasons TEXT NOT NULL DEFAULT '';  -- one line per note
ALTER TABLE fits ADD COLUMN algorithm_version INTEGER;

ALTER TABLE curves ADD COLUMN phase_speed_std_m_per_s REAL;
ALTER TABLE curves ADD COLUMN attenuation_std_db_per_m REAL;

-- SQLite expands `f.*` when a view is created: re-create it so it has the new columns.
DROP VIEW latest_fits;
CREATE VIEW latest_fits AS
SELECT f.*
FROM fits f
WHERE f.id = (SELECT MAX(g.id) FROM fits g WHERE g.segment_id = f.segment_id);
