//! pipewave: the leak-noise wavenumber of a buried water pipe, and the inversion of the soil
//! around it from field measurements.
pub mod batch;
pub mod bench;
pub mod change;
pub mod db;
pub mod diagnose;
pub mod export;
pub mod field;
pub mod forward;
pub mod invert;
pub mod locate;
pub mod optimize;
pub mod outfile;
pub mod physics;
pub mod recordings;
pub mod report;
pub mod rows;
pub mod seed;
pub mod special;
pub mod spreadsheet;
pub mod stats;
pub mod synth;
pub mod types;
pub mod units;
pub mod zones;
