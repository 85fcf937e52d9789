//! pipewave: the leak-noise wavenumber of a buried water pipe, and the inversion of the soil
//! around it from field measurements.
pub mod db;
pub mod physics;
pub mod special;
