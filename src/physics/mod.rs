//! The physical model of spec §2–§6 and §8: inputs, soil stiffness, dispersion relation, root
//! solver, wave-speed and attenuation curves, and the effects that extend the model.
pub mod inputs;

pub use inputs::{
    ContactMode, Fluid, InputError, Material, MaterialProps, Model, Pipe, Soil, System,
};
