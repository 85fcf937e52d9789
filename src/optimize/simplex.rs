//! Nelder–Mead's downhill simplex (Nelder & Mead 1965) inside a box: a local, derivative-free
//! search for objectives with jumps, where a finite-difference Jacobian (and so
//! Levenberg–Marquardt, [`super::lm`]) fails. An optimum on the edge of a cliff, where the
//! objective falls towards a jump, is one: the simplex creeps along the edge, while a
//! Gauss–Newton step points across it.
//!
//! Points outside the box count as +∞ and are not evaluated; so are points where the
//! objective is not finite. Reflection 1, expansion 2, contraction ½ (inside or outside),
//! shrink ½ towards the best vertex.

use super::{invalid, sanitize, Bounds, Objective, OptimizeError};

/// Why a simplex run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SimplexStopReason {
    /// The vertices' values agree to `f_tol` (relative to 1 + |f_best|) and the simplex is
    /// smaller than `x_tol` times the initial steps in every coordinate.
    Converged,
    /// The best value improved by less than `stall_tol` over the last `stall_evaluations`
    /// evaluations.
    Stalled,
    /// The evaluation budget was used up.
    MaxEvaluations,
}

/// Result of a simplex run.
#[derive(Debug, Clone, PartialEq)]
pub struct SimplexResult {
    /// The best vertex (inside the box).
    pub x: Vec<f64>,
    /// The objective there (+∞ if no vertex could be evaluated).
    pub f: f64,
    /// Objective evaluations (points outside the box not counted).
    pub evaluations: usize,
    /// Why the run ended.
    pub stop_reason: SimplexStopReason,
}

/// The downhill simplex, configured through checked setters.
#[derive(Debug, Clone, PartialEq)]
pub struct NelderMead {
    max_evaluations: usize,
    f_tol: f64,
    x_tol: f64,
    stall_evaluations: usize,
    stall_tol: f64,
}

impl Default for NelderMead {
    fn default() -> Self {
        Self {
            max_evaluations: 1000,
            f_tol: 1e-7,
            x_tol: 1e-4,
            stall_evaluations: 0,
            stall_tol: 0.0,
        }
    }
}

impl NelderMead {
    /// Defaults: 1,000 evaluations, `f_tol = 1e-7`, `x_tol = 1e-4`, no stall test.
    pub fn new() -> Self {
        Self::default()
    }

    /// Evaluation budget (≥ 1).
    pub fn max_evaluations(mut self, n: usize) -> Result<Self, OptimizeError> {
        if n == 0 {
            return Err(invalid("max_evaluations", n, "must be >= 1"));
        }
        self.max_evaluations = n;
        Ok(self)
    }

    /// Stop when the best value improved by less than `tol` over the last `evaluations`
    /// evaluations (`evaluations ≥ 1`, `tol ≥ 0`).
    pub fn stall(mut self, evaluations: usize, tol: f64) -> Result<Self, OptimizeError> {
        if evaluations == 0 {
            return Err(invalid("stall evaluations", evaluations, "must be >= 1"));
        }
        if !(tol >= 0.0 && tol.is_finite()) {
            return Err(invalid("stall tol", tol, "must be finite and >= 0"));
        }
        self.stall_evaluations = evaluations;
        self.stall_tol = tol;
        Ok(self)
    }

    /// Minimises `objective` from `x0` inside `bounds`, the initial simplex being `x0` and
    /// `x0 + steps[j] e_j` (a step that would leave the box is taken the other way).
    pub fn minimize<O: Objective + ?Sized>(
        &self,
        objective: &O,
        bounds: &Bounds,
        x0: &[f64],
        steps: &[f64],
    ) -> Result<SimplexResult, OptimizeError> {
        let n = objective.dim();
        if n == 0 {
            return Err(OptimizeError::EmptyProblem);
        }
        for (what, len) in [
            ("bounds", bounds.dim()),
            ("x0", x0.len()),
            ("steps", steps.len()),
        ] {
            if len != n {
                return Err(OptimizeError::DimensionMismatch {
                    what,
                    expected: n,
                    found: len,
                });
            }
        }
        bounds.check_contains(x0)?;
        if let Some(&s) = steps.iter().find(|s| !(s.is_finite() && **s != 0.0)) {
            return Err(invalid("steps", s, "must be finite and non-zero"));
        }
        let count = std::cell::Cell::new(0usize);
        let eval = |x: &[f64]| {
            if !bounds.contains(x) {
                return f64::INFINITY;
            }
            count.set(count.get() + 1);
            sanitize(objective.value(x))
        };
        let mut simplex: Vec<(Vec<f64>, f64)> = Vec::with_capacity(n + 1);
        simplex.push((x0.to_vec(), eval(x0)));
        for (j, &s) in steps.iter().enumerate() {
            let mut y = x0.to_vec();
            y[j] += s;
            if !bounds.contains(&y) {
                y[j] = x0[j] - s;
            }
            let f = eval(&y);
            simplex.push((y, f));
        }
        // The best value after each iteration, for the stall test.
        let mut history: Vec<(usize, f64)> = Vec::new();
        let stop_reason = loop {
            let evaluations = count.get();
            simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
            let (best, worst) = (simplex[0].1, simplex[n].1);
            let size = (1..=n)
                .flat_map(|i| (0..n).map(move |j| (i, j)))
                .map(|(i, j)| ((simplex[i].0[j] - simplex[0].0[j]) / steps[j]).abs())
                .fold(0.0, f64::max);
            if worst - best <= self.f_tol * (1.0 + best.abs()) && size <= self.x_tol {
                break SimplexStopReason::Converged;
            }
            if evaluations >= self.max_evaluations {
                break SimplexStopReason::MaxEvaluations;
            }
            if self.stall_evaluations > 0 {
                let before = history
                    .iter()
                    .rev()
                    .find(|(e, _)| e + self.stall_evaluations <= evaluations);
                if before.is_some_and(|&(_, f)| f - best < self.stall_tol) {
                    break SimplexStopReason::Stalled;
                }
            }
            history.push((evaluations, best));
            let centroid: Vec<f64> = (0..n)
                .map(|j| simplex[..n].iter().map(|v| v.0[j]).sum::<f64>() / n as f64)
                .collect();
            let (xw, fw) = simplex[n].clone();
            // The point c + t (x_worst − c).
            let along = |t: f64| -> Vec<f64> {
                centroid
                    .iter()
                    .zip(&xw)
                    .map(|(c, w)| c + t * (w - c))
                    .collect()
            };
            let xr = along(-1.0);
            let fr = eval(&xr);
            if fr < best {
                let xe = along(-2.0);
                let fe = eval(&xe);
                simplex[n] = if fe < fr { (xe, fe) } else { (xr, fr) };
            } else if fr < simplex[n - 1].1 {
                simplex[n] = (xr, fr);
            } else {
                let xc = along(if fr < fw { -0.5 } else { 0.5 });
                let fc = eval(&xc);
                if fc < fw.min(fr) {
                    simplex[n] = (xc, fc);
                } else {
                    let xb = simplex[0].0.clone();
                    for v in simplex.iter_mut().skip(1) {
                        let y: Vec<f64> = xb
                            .iter()
                            .zip(&v.0)
                            .map(|(b, x)| b + 0.5 * (x - b))
                            .collect();
                        let f = eval(&y);
                        *v = (y, f);
                    }
                }
            }
        };
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let (x, f) = simplex.swap_remove(0);
        Ok(SimplexResult {
            x,
            f,
            evaluations: count.get(),
            stop_reason,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optimize::FnObjective;

    #[test]
    fn finds_the_minimum_of_rosenbrock() {
        let f = FnObjective::new(2, |x: &[f64]| {
            (1.0 - x[0]).powi(2) + 100.0 * (x[1] - x[0] * x[0]).powi(2)
        });
        let b = Bounds::uniform(2, -2.0, 2.0).unwrap();
        let r = NelderMead::new()
            .max_evaluations(2000)
            .unwrap()
            .minimize(&f, &b, &[-1.2, 1.0], &[0.1, 0.1])
            .unwrap();
        assert_eq!(r.stop_reason, SimplexStopReason::Converged);
        assert!(
            (r.x[0] - 1.0).abs() < 1e-3 && (r.x[1] - 1.0).abs() < 2e-3,
            "{:?}",
            r.x
        );
    }

    /// A valley x₁ = x₀ whose floor falls towards (1, 1), cut by a cliff at x₁ > x₀ + 0.1 x₀²
    /// (+10 beyond it): the minimum over the region below the cliff lies on its edge, which
    /// the simplex follows from (0, 0) to near (1, 1.1).
    #[test]
    fn creeps_along_the_edge_of_a_cliff() {
        let f = FnObjective::new(2, |x: &[f64]| {
            let cliff = if x[1] > x[0] + 0.1 * x[0] * x[0] {
                10.0
            } else {
                0.0
            };
            (x[0] - 1.0).powi(2) + (x[1] - x[0] - 1.0).powi(2) + cliff
        });
        let b = Bounds::uniform(2, -1.0, 1.0).unwrap();
        let r = NelderMead::new()
            .max_evaluations(3000)
            .unwrap()
            .minimize(&f, &b, &[0.0, -0.01], &[0.01, 0.01])
            .unwrap();
        // On the edge at x₀ = 1 (the box's face): x₁ = 1.1 is outside the box, so the best
        // point lies where the edge leaves the box, x₁ = 1, x₀ = 0.916.
        let edge_x0 = (-1.0 + (1.0f64 + 0.4).sqrt()) / 0.2;
        assert!((r.x[1] - 1.0).abs() < 1e-3, "{:?}", r.x);
        assert!((r.x[0] - edge_x0).abs() < 2e-3, "{:?} vs {edge_x0}", r.x);
        let at_corner = (edge_x0 - 1.0).powi(2) + edge_x0.powi(2);
        assert!((r.f - at_corner).abs() < 1e-3, "{} vs {at_corner}", r.f);
    }

    #[test]
    fn the_stall_test_stops_a_run_that_gains_nothing() {
        let f = FnObjective::new(2, |x: &[f64]| x[0].abs() + x[1].abs());
        let b = Bounds::uniform(2, -1.0, 1.0).unwrap();
        let r = NelderMead::new()
            .stall(30, 1e-3)
            .unwrap()
            .minimize(&f, &b, &[0.0, 0.0], &[0.5, 0.5])
            .unwrap();
        assert_eq!(r.stop_reason, SimplexStopReason::Stalled);
        assert!(r.evaluations < 60, "{}", r.evaluations);
        assert_eq!(r.x, vec![0.0, 0.0]);
    }

    #[test]
    fn settings_and_inputs_are_checked() {
        let f = FnObjective::new(2, |x: &[f64]| (x[0] - 0.2).powi(2) + (x[1] - 0.3).powi(2));
        let b = Bounds::uniform(2, 0.0, 1.0).unwrap();
        assert!(NelderMead::new().max_evaluations(0).is_err());
        assert!(NelderMead::new().stall(0, 1.0).is_err());
        assert!(NelderMead::new().stall(5, f64::NAN).is_err());
        let nm = NelderMead::new();
        assert!(nm.minimize(&f, &b, &[0.5], &[0.1, 0.1]).is_err());
        assert!(nm.minimize(&f, &b, &[2.0, 0.5], &[0.1, 0.1]).is_err());
        assert!(nm.minimize(&f, &b, &[0.5, 0.5], &[0.0, 0.1]).is_err());
        // A step that would leave the box is taken the other way.
        let r = nm.minimize(&f, &b, &[0.95, 0.5], &[0.1, -0.1]).unwrap();
        assert!(
            (r.x[0] - 0.2).abs() < 1e-4 && (r.x[1] - 0.3).abs() < 1e-4,
            "{r:?}"
        );
    }
}
