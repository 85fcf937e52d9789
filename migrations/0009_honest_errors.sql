-- pipewave schema, version 9: honest errors where the model does not explain the data
-- (physics §7.13); append-only.
-- A fit whose misfit is significant stores the model plus a discrepancy fitted to its
-- residuals as its curve (`curve_source` 'model+discrepancy'); the model-only curve stays in
-- the curves table for the diagnosis. `leak_band_extrapolation_octaves`: how far the leak band
-- (100-800 Hz) reaches beyond the measured frequencies, in octaves (0: inside them).
ALTER TABLE fits ADD COLUMN curve_source TEXT NOT NULL DEFAULT 'model';
ALTER TABLE fits ADD COLUMN leak_band_extrapolation_octaves REAL;
ALTER TABLE curves ADD COLUMN model_phase_speed_m_per_s REAL;
ALTER TABLE curves ADD COLUMN model_attenuation_db_per_m REAL;
