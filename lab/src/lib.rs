//! pipewave's lab: generators and scorers that judge pipewave's statistics from outside.
//!
//! The lab uses pipewave's forward model only (`pipewave::physics` and the leak-band mean of
//! `pipewave::invert::assemble::leak_band_speed_of`); it imports nothing from pipewave's
//! `synth`, `diagnose`, `invert::fit`, `field` or `batch`, so that a method designed on
//! `pipewave synth` is judged on data it was not designed on.
pub mod campaigns;
pub mod catalogue;
pub mod diagnosis;
pub mod draw;
pub mod score;
pub mod score_diagnosis;
