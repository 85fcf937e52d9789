//! The physical model of model §2–§6 and §8: inputs, soil stiffness, dispersion relation, root
//! solver, wave-speed and attenuation curves, the soil's moduli and wave speeds, and the
//! effects that extend the model.
pub mod curves;
pub mod dispersion;
pub mod effects;
pub mod inputs;
pub mod soil;
pub mod solver;

pub use dispersion::{Evaluator, SoilStiffness, SoilWaves};
pub use inputs::{
    ContactMode, Fluid, InputError, Material, MaterialProps, Model, Pipe, Soil, System,
};
pub use solver::{solve_curve, solve_direct, Continuation, Root, RootFlags, SolveError};
