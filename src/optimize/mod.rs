//! Generic derivative-free and least-squares optimisation.
//!
//! This module knows nothing about pipes: it minimises any [`Objective`] over a box
//! ([`Bounds`]) by differential evolution ([`de`]), refines least-squares problems by a
//! bounded Levenberg–Marquardt method ([`lm`]), searches locally where the objective jumps by
//! the downhill simplex ([`simplex`]), brackets a monotone crossing by bisection ([`bisect()`]),
//! and offers the small dense linear algebra
//! both need, including parameter covariances from a Jacobian ([`linalg`]).
//!
//! The shape follows the `argmin` crate: the problem is a trait the caller implements,
//! solvers are configured through builders whose setters check their input and return
//! [`Result`], the random-number generator is passed in by the caller (so runs are
//! reproducible from a seed), the reason for stopping is returned as data, and progress is
//! reported to an [`Observer`] that may cancel the run. Nothing here prints.
//!
//! Non-finite objective values (NaN, ±∞) are treated as the worst possible value (+∞)
//! everywhere: they never win a comparison, so a region where the model cannot be
//! evaluated is avoided rather than exploited.

pub mod bisect;
pub mod de;
pub mod linalg;
pub mod lm;
pub mod simplex;

pub use bisect::bisect;
pub use de::{DeMethod, DeResult, DifferentialEvolution};
pub use lm::{
    jacobian_fd, FiniteDifference, LeastSquares, LevenbergMarquardt, LmResult, LmStopReason,
    SumOfSquares,
};
pub use simplex::{NelderMead, SimplexResult, SimplexStopReason};

use thiserror::Error;

/// Errors of the optimisation library: invalid settings or inputs, never numerical failure
/// during a run (which is reported through a stop reason instead).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum OptimizeError {
    /// A setting is outside its admissible range.
    #[error("invalid setting `{name}` = {value}: {reason}")]
    InvalidSetting {
        /// Name of the setter.
        name: &'static str,
        /// The rejected value, formatted.
        value: String,
        /// What the admissible range is.
        reason: &'static str,
    },
    /// Lower and upper bound vectors have different lengths.
    #[error("bounds have different lengths: {lower} lower vs {upper} upper")]
    BoundsLength {
        /// Length of the lower-bound vector.
        lower: usize,
        /// Length of the upper-bound vector.
        upper: usize,
    },
    /// A bound is not finite or `lower >= upper` in some dimension.
    #[error("invalid bounds in dimension {index}: lower = {lower}, upper = {upper} (need finite lower < upper)")]
    InvalidBounds {
        /// Index of the offending dimension.
        index: usize,
        /// Lower bound given.
        lower: f64,
        /// Upper bound given.
        upper: f64,
    },
    /// Zero-dimensional problem.
    #[error("the problem has no parameters")]
    EmptyProblem,
    /// Dimensions of problem, bounds or starting point disagree.
    #[error("dimension mismatch: {what} has {found}, expected {expected}")]
    DimensionMismatch {
        /// Which input disagrees.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Length found.
        found: usize,
    },
    /// The evaluation budget cannot even cover the initial population.
    #[error(
        "max_evaluations = {max_evaluations} is smaller than the population size {population}"
    )]
    BudgetTooSmall {
        /// Maximum number of objective evaluations.
        max_evaluations: usize,
        /// Population size that needs evaluating first.
        population: usize,
    },
    /// A least-squares problem could not be evaluated at the starting point.
    #[error("the residuals could not be evaluated at the starting point")]
    StartNotEvaluable,
    /// The finite-difference Jacobian could not be evaluated (both sides of a step failed).
    #[error("finite-difference Jacobian failed for parameter {index}")]
    JacobianFailed {
        /// Parameter whose column could not be formed.
        index: usize,
    },
    /// A point lies outside the bounds it must respect.
    #[error("parameter {index} = {value} lies outside its bounds [{lower}, {upper}]")]
    OutOfBounds {
        /// Index of the offending parameter.
        index: usize,
        /// Its value.
        value: f64,
        /// Its lower bound.
        lower: f64,
        /// Its upper bound.
        upper: f64,
    },
}

/// Shorthand used by the builders' checked setters.
pub(crate) fn invalid(
    name: &'static str,
    value: impl std::fmt::Display,
    reason: &'static str,
) -> OptimizeError {
    OptimizeError::InvalidSetting {
        name,
        value: value.to_string(),
        reason,
    }
}

/// A scalar function to minimise.
///
/// `value` receives a point of length [`dim`](Objective::dim) inside the bounds the solver
/// was given. Returning a non-finite number (NaN, ±∞) means "cannot evaluate here"; the
/// solvers treat it as +∞, the worst possible value.
pub trait Objective {
    /// Number of parameters.
    fn dim(&self) -> usize;
    /// Objective value at `x` (lower is better; non-finite = worst).
    fn value(&self, x: &[f64]) -> f64;
    /// Objective value at `x` for a population search's selection, which only ranks points:
    /// an objective may compute it to a lower precision than [`Objective::value`], far below
    /// any difference the search acts on. Default: [`Objective::value`].
    fn search_value(&self, x: &[f64]) -> f64 {
        self.value(x)
    }
}

impl<T: Objective + ?Sized> Objective for &T {
    fn dim(&self) -> usize {
        (**self).dim()
    }
    fn value(&self, x: &[f64]) -> f64 {
        (**self).value(x)
    }
    fn search_value(&self, x: &[f64]) -> f64 {
        (**self).search_value(x)
    }
}

/// Adapter turning a closure `Fn(&[f64]) -> f64` of known dimension into an [`Objective`].
#[derive(Debug, Clone, Copy)]
pub struct FnObjective<F> {
    dim: usize,
    f: F,
}

impl<F: Fn(&[f64]) -> f64> FnObjective<F> {
    /// Wraps `f`, a function of `dim` parameters.
    pub fn new(dim: usize, f: F) -> Self {
        Self { dim, f }
    }
}

impl<F: Fn(&[f64]) -> f64> Objective for FnObjective<F> {
    fn dim(&self) -> usize {
        self.dim
    }
    fn value(&self, x: &[f64]) -> f64 {
        (self.f)(x)
    }
}

/// Maps any non-finite objective value to +∞ so that it loses every comparison.
#[inline]
pub(crate) fn sanitize(f: f64) -> f64 {
    if f.is_finite() {
        f
    } else {
        f64::INFINITY
    }
}

/// A box `lower[i] <= x[i] <= upper[i]`, checked on construction: both vectors have the
/// same non-zero length, every bound is finite and `lower[i] < upper[i]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Bounds {
    lower: Vec<f64>,
    upper: Vec<f64>,
}

impl Bounds {
    /// Builds a box from lower and upper bound vectors (same units as the parameters).
    pub fn new(lower: Vec<f64>, upper: Vec<f64>) -> Result<Self, OptimizeError> {
        if lower.len() != upper.len() {
            return Err(OptimizeError::BoundsLength {
                lower: lower.len(),
                upper: upper.len(),
            });
        }
        if lower.is_empty() {
            return Err(OptimizeError::EmptyProblem);
        }
        for (index, (&lo, &hi)) in lower.iter().zip(&upper).enumerate() {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(OptimizeError::InvalidBounds {
                    index,
                    lower: lo,
                    upper: hi,
                });
            }
        }
        Ok(Self { lower, upper })
    }

    /// Builds a box from `(lower, upper)` pairs.
    pub fn from_pairs(pairs: &[(f64, f64)]) -> Result<Self, OptimizeError> {
        let (lower, upper) = pairs.iter().copied().unzip();
        Self::new(lower, upper)
    }

    /// The same interval `[lower, upper]` in each of `dim` dimensions.
    pub fn uniform(dim: usize, lower: f64, upper: f64) -> Result<Self, OptimizeError> {
        Self::new(vec![lower; dim], vec![upper; dim])
    }

    /// Number of dimensions.
    pub fn dim(&self) -> usize {
        self.lower.len()
    }

    /// Lower bounds.
    pub fn lower(&self) -> &[f64] {
        &self.lower
    }

    /// Upper bounds.
    pub fn upper(&self) -> &[f64] {
        &self.upper
    }

    /// Width `upper[i] - lower[i]` of dimension `i`.
    pub fn width(&self, i: usize) -> f64 {
        self.upper[i] - self.lower[i]
    }

    /// Whether `x` lies in the (closed) box.
    pub fn contains(&self, x: &[f64]) -> bool {
        x.len() == self.dim()
            && x.iter()
                .zip(self.lower.iter().zip(&self.upper))
                .all(|(&v, (&lo, &hi))| lo <= v && v <= hi)
    }

    /// Projects `x` onto the box in place (component-wise clamping).
    pub fn clamp(&self, x: &mut [f64]) {
        for ((v, &lo), &hi) in x.iter_mut().zip(&self.lower).zip(&self.upper) {
            *v = v.clamp(lo, hi);
        }
    }

    /// Returns an error naming the first component of `x` outside the box.
    pub fn check_contains(&self, x: &[f64]) -> Result<(), OptimizeError> {
        if x.len() != self.dim() {
            return Err(OptimizeError::DimensionMismatch {
                what: "point",
                expected: self.dim(),
                found: x.len(),
            });
        }
        for (index, &value) in x.iter().enumerate() {
            let (lower, upper) = (self.lower[index], self.upper[index]);
            if !(lower <= value && value <= upper) {
                return Err(OptimizeError::OutOfBounds {
                    index,
                    value,
                    lower,
                    upper,
                });
            }
        }
        Ok(())
    }
}

/// Why a population-based run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StopReason {
    /// The population's objective values agree to within the spread tolerance
    /// (`f_worst − f_best ≤ atol + rtol·|f_best|`).
    Converged,
    /// The best value improved by less than ε over the last `t` generations (the paper's
    /// test P59).
    Stagnated,
    /// The generation limit was reached.
    MaxGenerations,
    /// The objective-evaluation budget was used up.
    MaxEvaluations,
    /// An [`Observer`] asked to stop.
    Cancelled,
}

/// What an [`Observer`] wants the solver to do next.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Control {
    /// Keep going.
    #[default]
    Continue,
    /// Stop now; the run ends with [`StopReason::Cancelled`].
    Cancel,
}

/// Snapshot handed to an [`Observer`] after each generation (generation 0 is the initial
/// population).
#[derive(Debug, Clone, Copy)]
pub struct Progress<'a> {
    /// Generations completed (0 = only the initial population exists).
    pub generation: usize,
    /// Objective evaluations so far.
    pub evaluations: usize,
    /// Best objective value in the population (+∞ if none is finite).
    pub best_f: f64,
    /// Parameters of the best member.
    pub best_x: &'a [f64],
    /// Spread of the population's objective values, `f_worst − f_best` (+∞ when any member
    /// is non-finite).
    pub spread: f64,
}

/// Receives progress reports; may cancel the run.
///
/// Any `FnMut(&Progress) -> Control` closure is an observer.
pub trait Observer {
    /// Called once for the initial population (generation 0) and after every generation.
    fn observe(&mut self, progress: &Progress<'_>) -> Control;
}

/// Observer that ignores every report and never cancels.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoObserver;

impl Observer for NoObserver {
    fn observe(&mut self, _progress: &Progress<'_>) -> Control {
        Control::Continue
    }
}

impl<F: FnMut(&Progress<'_>) -> Control> Observer for F {
    fn observe(&mut self, progress: &Progress<'_>) -> Control {
        self(progress)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_are_checked() {
        assert!(Bounds::new(vec![0.0, 1.0], vec![1.0, 2.0]).is_ok());
        assert_eq!(
            Bounds::new(vec![0.0], vec![1.0, 2.0]),
            Err(OptimizeError::BoundsLength { lower: 1, upper: 2 })
        );
        assert_eq!(
            Bounds::new(vec![], vec![]),
            Err(OptimizeError::EmptyProblem)
        );
        assert!(matches!(
            Bounds::new(vec![0.0, 2.0], vec![1.0, 2.0]),
            Err(OptimizeError::InvalidBounds { index: 1, .. })
        ));
        assert!(Bounds::new(vec![3.0], vec![1.0]).is_err());
        assert!(Bounds::new(vec![f64::NAN], vec![1.0]).is_err());
        assert!(Bounds::new(vec![0.0], vec![f64::INFINITY]).is_err());
        assert!(Bounds::from_pairs(&[(0.0, 1.0), (-1.0, 1.0)]).is_ok());
    }

    #[test]
    fn bounds_contain_and_clamp() {
        let b = Bounds::uniform(2, -1.0, 1.0).unwrap();
        assert!(b.contains(&[-1.0, 1.0]));
        assert!(!b.contains(&[-1.0, 1.5]));
        assert!(!b.contains(&[0.0]));
        let mut x = [2.0, -3.0];
        b.clamp(&mut x);
        assert_eq!(x, [1.0, -1.0]);
        assert!(matches!(
            b.check_contains(&[0.0, f64::NAN]),
            Err(OptimizeError::OutOfBounds { index: 1, .. })
        ));
        assert_eq!(b.width(0), 2.0);
    }

    #[test]
    fn sanitize_maps_non_finite_to_worst() {
        assert_eq!(sanitize(1.5), 1.5);
        assert_eq!(sanitize(f64::NAN), f64::INFINITY);
        assert_eq!(sanitize(f64::NEG_INFINITY), f64::INFINITY);
    }
}
