-- pipewave schema: what the soil field (field algorithm 2) needs to be rebuilt exactly from the
-- stored fits. Append-only: never edit this file once it has landed.
--
-- Each class's multipliers of the field covariance B and of the per-pipe scatter T (P78 with a
-- class-dependent amplitude, chosen by the marginal likelihood with a prior near 1), and each
-- measured segment's information scale: 1 when the field explains its fit, below 1 when its
-- fitted soil is beyond χ²₂ = 13.8 of its leave-one-out prediction (P79–P80), with that χ².
ALTER TABLE field_classes ADD COLUMN field_scale REAL;
ALTER TABLE field_classes ADD COLUMN scatter_scale REAL;
ALTER TABLE field_segments ADD COLUMN information_scale REAL;
ALTER TABLE field_segments ADD COLUMN screen_chi2 REAL;
