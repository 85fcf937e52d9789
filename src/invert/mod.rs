//! Inversion of one segment: fit the soil's Young's modulus E_m, Poisson's ratio ν_m and the
//! contact coefficient ξ (and any switched-on effect parameters) to measured wavenumbers, with
//! uncertainty and flags (model §7).
//!
//! * `paper` method: the paper's DE/rand/1/bin exactly (P51–P59), its objective and bounds.
//! * default method: SHADE over (ln c_P, c_S/c_P, ξ, …) and (log10 E_m, ν_m, ξ, …), chi-square in the measurement standard
//!   deviations when given (otherwise the paper's relative errors, squared), a
//!   Levenberg–Marquardt polish, restarts to detect separated minima.
//! * what the data determine (model §7.10, `uncertainty`): the soil's c_P and c_S with errors,
//!   95 % intervals of every parameter, the predicted curve with errors;
//! * findings (`flags`): flags to act on, notes on what the data leave undetermined.
//!
//! `fit` searches and checks its optima on the reference path; `assemble` builds the result
//! (`result`) once from them; `speed_search` holds the search's speed coordinates and the
//! faces of their box (ν_m → ½, the faces of ξ); `probes` looks for the basins a search leaves
//! unvisited across a grazing cliff, and steps an optimum off a cliff's edge; `uncertainty` and
//! `flags` are pure functions of what the search found; `provenance` records which stage found
//! the answer and why each stage stopped; `speed` is the image of the search box in
//! (ln c_P, c_S/c_P); `yardstick` is the independent dense-grid search `bench --verify` judges
//! the fit against.
pub mod assemble;
pub mod discrepancy;
pub mod fit;
pub mod flags;
pub mod probes;
pub mod problem;
pub mod provenance;
pub mod result;
pub mod speed;
pub mod speed_search;
pub mod uncertainty;
pub mod yardstick;

pub use fit::{fit_extended, fit_segment, fit_with_effects, refit_from, BaseOptimum, FitSettings};
pub use flags::{Flag, FlagCode, Severity};
pub use problem::{Measurement, Method, Param, Problem, SegmentData, Weighting};
pub use provenance::{Provenance, SearchError, Stage, StageStatistics, StageStop};
pub use result::{CurveSource, Estimate, FitResult, PredictedPoint};
pub use uncertainty::{Interval, WithError};
