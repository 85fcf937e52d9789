//! Inversion of one segment: fit the soil's Young's modulus E_m, Poisson's ratio ν_m and the
//! contact coefficient ξ (and any switched-on effect parameters) to measured wavenumbers, with
//! uncertainty and flags (spec §7; issue 3).
//!
//! * `paper` method: the paper's DE/rand/1/bin exactly (P51–P59), its objective and bounds.
//! * default method: SHADE over (log10 E_m, ν_m, ξ, …), chi-square in the measurement standard
//!   deviations when given (otherwise the paper's relative errors, squared), a
//!   Levenberg–Marquardt polish, restarts to detect separated minima, standard errors and
//!   correlations from the Jacobian at the optimum.
pub mod fit;
pub mod flags;
pub mod problem;

pub use fit::{fit_segment, Estimate, FitResult, FitSettings, FitStatus};
pub use flags::{Flag, FlagCode};
pub use problem::{Measurement, Method, Param, Problem, SegmentData, Weighting};
