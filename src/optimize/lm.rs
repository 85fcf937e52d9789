//! Bounded Levenberg–Marquardt for nonlinear least squares (Levenberg 1944, Marquardt 1963).
//!
//! Minimises `cost(x) = Σ_i r_i(x)²` over a box. Each iteration forms a finite-difference
//! Jacobian `J`, the gradient `g = Jᵀr` and solves the damped normal equations
//! `(JᵀJ + λ D) δ = −g` with Marquardt's scaling `D = diag(JᵀJ)` (kept as the running
//! maximum over iterations, as in MINPACK, so the damping is invariant to the parameters'
//! units). Bounds are handled by an active set plus projection: a parameter sitting on a
//! bound with the gradient pushing it outwards is frozen for that iteration, the reduced
//! system is solved for the others, and the trial point is projected onto the box. A step
//! is accepted when it lowers the cost; otherwise, or when the residuals cannot be
//! evaluated at the trial point, it is rejected and `λ` grows.

use super::linalg::{jt_vec, jtj, solve_spd};
use super::{invalid, Bounds, Objective, OptimizeError};

/// A nonlinear least-squares problem: `n_residuals` residuals of `n_params` parameters.
pub trait LeastSquares {
    /// Number of parameters.
    fn n_params(&self) -> usize;
    /// Number of residuals.
    fn n_residuals(&self) -> usize;
    /// Writes the residuals at `x` into `out` (length [`n_residuals`](Self::n_residuals)).
    /// Returns `false` if the model cannot be evaluated at `x` (the contents of `out` are
    /// then ignored). Non-finite residuals are treated the same way.
    fn residuals(&self, x: &[f64], out: &mut [f64]) -> bool;
    /// [`residuals`](Self::residuals) at `x`, a finite-difference step from `base`: a problem
    /// that can reuse its work at `base` (a root solved there, say) does so here. It must give
    /// the residuals at `x` to the accuracy of `residuals`. By default, `residuals`.
    fn residuals_near(&self, base: &[f64], x: &[f64], out: &mut [f64]) -> bool {
        let _ = base;
        self.residuals(x, out)
    }
    /// Whether [`residuals_near`](Self::residuals_near) answers next to `base` by another
    /// scheme than `residuals` (default false). Then [`jacobian_fd`] takes its differences
    /// against `residuals_near(base, base)`, not against the residuals it is given, so that
    /// both ends of a difference carry the same scheme's error: where a derivative is small
    /// (along a flat valley) the two schemes' errors, uncorrelated, would swamp it.
    fn near_at(&self, base: &[f64]) -> bool {
        let _ = base;
        false
    }
}

impl<T: LeastSquares + ?Sized> LeastSquares for &T {
    fn n_params(&self) -> usize {
        (**self).n_params()
    }
    fn n_residuals(&self) -> usize {
        (**self).n_residuals()
    }
    fn residuals(&self, x: &[f64], out: &mut [f64]) -> bool {
        (**self).residuals(x, out)
    }
    fn residuals_near(&self, base: &[f64], x: &[f64], out: &mut [f64]) -> bool {
        (**self).residuals_near(base, x, out)
    }
    fn near_at(&self, base: &[f64]) -> bool {
        (**self).near_at(base)
    }
}

/// Adapter presenting a least-squares problem as an [`Objective`] whose value is the sum
/// of squared residuals (+∞ where the residuals cannot be evaluated), so the same problem
/// can be searched globally by differential evolution and then refined by
/// [`LevenbergMarquardt`].
#[derive(Debug, Clone, Copy)]
pub struct SumOfSquares<P>(pub P);

impl<P: LeastSquares> Objective for SumOfSquares<P> {
    fn dim(&self) -> usize {
        self.0.n_params()
    }
    fn value(&self, x: &[f64]) -> f64 {
        let mut r = vec![0.0; self.0.n_residuals()];
        if eval_ok(&self.0, x, &mut r) {
            sum_sq(&r)
        } else {
            f64::INFINITY
        }
    }
}

/// Relative finite-difference step for forward differences, `sqrt(ε_machine)`: balances
/// truncation error `O(h)` against rounding error `O(ε/h)`.
pub const FD_REL_STEP_FORWARD: f64 = 1.490_116_119_384_765_6e-8;
/// Relative finite-difference step for central differences, `cbrt(ε_machine)`: balances
/// truncation error `O(h²)` against rounding error `O(ε/h)`.
pub const FD_REL_STEP_CENTRAL: f64 = 6.055_454_452_393_343e-6;
/// The step for parameter `q` is `rel_step · max(|x_q|, FD_FLOOR_FRACTION · (upper_q −
/// lower_q))` when bounds are given, and `rel_step · max(|x_q|, 1)` otherwise, so that a
/// parameter at or near zero still gets a usable step.
pub const FD_FLOOR_FRACTION: f64 = 1e-3;

/// Initial damping `λ` (relative to the Marquardt scaling `diag(JᵀJ)`).
pub const LM_INITIAL_DAMPING: f64 = 1e-3;
/// Factor by which `λ` grows after a rejected step (Marquardt 1963 used 10).
pub const LM_DAMPING_UP: f64 = 10.0;
/// Factor by which `λ` shrinks after an accepted step.
pub const LM_DAMPING_DOWN: f64 = 10.0;
/// Lower limit of `λ` (keeps the damped system nonsingular in scaled terms).
pub const LM_DAMPING_MIN: f64 = 1e-12;
/// `λ` above this means no step along the scaled gradient lowers the cost: stop.
pub const LM_DAMPING_MAX: f64 = 1e16;

/// Finite-difference scheme for the Jacobian.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum FiniteDifference {
    /// `(r(x + h e_q) − r(x)) / h`: one extra evaluation per parameter, error `O(h)`.
    /// Steps backwards when `x + h` would leave the box.
    #[default]
    Forward,
    /// `(r(x + h e_q) − r(x − h e_q)) / 2h`: two evaluations per parameter, error `O(h²)`.
    /// Near a bound it switches to the second-order one-sided formula
    /// `(−3 r(x) + 4 r(x ± h) − r(x ± 2h)) / (±2h)`.
    Central,
}

impl FiniteDifference {
    /// The default relative step of this scheme ([`FD_REL_STEP_FORWARD`] or
    /// [`FD_REL_STEP_CENTRAL`]).
    pub fn default_rel_step(self) -> f64 {
        match self {
            FiniteDifference::Forward => FD_REL_STEP_FORWARD,
            FiniteDifference::Central => FD_REL_STEP_CENTRAL,
        }
    }
}

fn eval_ok<P: LeastSquares + ?Sized>(problem: &P, x: &[f64], out: &mut [f64]) -> bool {
    problem.residuals(x, out) && out.iter().all(|v| v.is_finite())
}

/// [`eval_ok`] by [`LeastSquares::residuals_near`] `base`.
fn eval_near_ok<P: LeastSquares + ?Sized>(
    problem: &P,
    base: &[f64],
    x: &[f64],
    out: &mut [f64],
) -> bool {
    problem.residuals_near(base, x, out) && out.iter().all(|v| v.is_finite())
}

/// Finite-difference Jacobian of `problem` at `x`, written row-major (`m × n`) into `jac`.
///
/// `r0` must hold the residuals at `x`. With `bounds`, every evaluation point stays inside
/// the box (the step is reversed or made one-sided near a bound). `rel_step` is the relative
/// step (see [`FiniteDifference::default_rel_step`] and [`FD_FLOOR_FRACTION`]). If the
/// residuals cannot be evaluated on one side, the other side is tried. The residuals at each
/// step are [`LeastSquares::residuals_near`] `x`. Returns the number of residual evaluations
/// used.
pub fn jacobian_fd<P: LeastSquares + ?Sized>(
    problem: &P,
    x: &[f64],
    r0: &[f64],
    bounds: Option<&Bounds>,
    scheme: FiniteDifference,
    rel_step: f64,
    jac: &mut [f64],
) -> Result<usize, OptimizeError> {
    let n = problem.n_params();
    let m = problem.n_residuals();
    check_len("x", n, x.len())?;
    check_len("r0", m, r0.len())?;
    check_len("jacobian", m * n, jac.len())?;
    if let Some(b) = bounds {
        check_len("bounds", n, b.dim())?;
    }
    if !(rel_step > 0.0 && rel_step.is_finite()) {
        return Err(invalid("rel_step", rel_step, "must be finite and > 0"));
    }
    let mut evals = 0;
    let mut xp = x.to_vec();
    let mut r1 = vec![0.0; m];
    let mut r2 = vec![0.0; m];
    let mut centre = Vec::new();
    if problem.near_at(x) {
        centre.resize(m, 0.0);
        evals += 1;
        if !eval_near_ok(problem, x, x, &mut centre) {
            centre.clear();
        }
    }
    let r0 = if centre.is_empty() { r0 } else { &centre };
    let inside = |q: usize, v: f64| bounds.is_none_or(|b| b.lower()[q] <= v && v <= b.upper()[q]);
    for q in 0..n {
        let floor = bounds.map_or(1.0, |b| FD_FLOOR_FRACTION * b.width(q));
        let h = rel_step * x[q].abs().max(floor);
        // Evaluates r at x + s e_q; returns the step actually taken (after rounding).
        let mut eval_at = |s: f64, out: &mut [f64], evals: &mut usize| -> Option<f64> {
            let v = x[q] + s;
            if !inside(q, v) || v == x[q] {
                return None;
            }
            xp[q] = v;
            *evals += 1;
            let ok = eval_near_ok(problem, x, &xp, out);
            xp[q] = x[q];
            ok.then_some(v - x[q])
        };
        let done = match scheme {
            FiniteDifference::Forward => {
                let mut res = None;
                for s in [h, -h] {
                    if let Some(hh) = eval_at(s, &mut r1, &mut evals) {
                        res = Some(hh);
                        break;
                    }
                }
                res.map(|hh| {
                    for i in 0..m {
                        jac[i * n + q] = (r1[i] - r0[i]) / hh;
                    }
                })
            }
            FiniteDifference::Central => {
                let plus = eval_at(h, &mut r1, &mut evals);
                let minus = if plus.is_some() {
                    eval_at(-h, &mut r2, &mut evals)
                } else {
                    None
                };
                if let (Some(hp), Some(hm)) = (plus, minus) {
                    for i in 0..m {
                        jac[i * n + q] = (r1[i] - r2[i]) / (hp - hm);
                    }
                    Some(())
                } else {
                    // One-sided second-order formula, forward first, then backward.
                    let mut res = None;
                    for s in [h, -h] {
                        let Some(h1) = eval_at(s, &mut r1, &mut evals) else {
                            continue;
                        };
                        let Some(h2) = eval_at(2.0 * s, &mut r2, &mut evals) else {
                            // Only one point fits: fall back to first order.
                            for i in 0..m {
                                jac[i * n + q] = (r1[i] - r0[i]) / h1;
                            }
                            res = Some(());
                            break;
                        };
                        let hh = 0.5 * (h1 + 0.5 * h2);
                        for i in 0..m {
                            jac[i * n + q] = (-3.0 * r0[i] + 4.0 * r1[i] - r2[i]) / (2.0 * hh);
                        }
                        res = Some(());
                        break;
                    }
                    res
                }
            }
        };
        if done.is_none() {
            return Err(OptimizeError::JacobianFailed { index: q });
        }
    }
    Ok(evals)
}

fn check_len(what: &'static str, expected: usize, found: usize) -> Result<(), OptimizeError> {
    if expected == found {
        Ok(())
    } else {
        Err(OptimizeError::DimensionMismatch {
            what,
            expected,
            found,
        })
    }
}

/// Why a Levenberg–Marquardt run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LmStopReason {
    /// The residuals are exactly zero.
    ExactFit,
    /// The (scaled) step fell below `xtol` relative to the (scaled) parameters.
    SmallStep,
    /// An accepted step lowered the cost by less than `ftol` relative to the cost.
    SmallCostDecrease,
    /// The projected gradient is orthogonal to the residuals to within `gtol` (cosine).
    SmallGradient,
    /// The iteration limit was reached.
    MaxIterations,
    /// The damping exceeded [`LM_DAMPING_MAX`] without an acceptable step.
    DampingLimit,
    /// The finite-difference Jacobian could not be evaluated at the current point.
    JacobianFailed,
}

/// Result of a Levenberg–Marquardt run.
#[derive(Debug, Clone, PartialEq)]
pub struct LmResult {
    /// Best parameters found (inside the bounds, if any).
    pub x: Vec<f64>,
    /// Sum of squared residuals at `x`.
    pub cost: f64,
    /// Residuals at `x`.
    pub residuals: Vec<f64>,
    /// Finite-difference Jacobian at `x`, row-major `n_residuals × n_params` (empty if it
    /// could not be evaluated, i.e. stop reason [`LmStopReason::JacobianFailed`], or if it was
    /// not asked for, [`LevenbergMarquardt::final_jacobian`]).
    pub jacobian: Vec<f64>,
    /// Iterations (Jacobian evaluations along the path) performed.
    pub iterations: usize,
    /// Residual evaluations in total, including finite differences.
    pub evaluations: usize,
    /// Why the run ended.
    pub stop_reason: LmStopReason,
}

/// Bounded Levenberg–Marquardt solver (Marquardt 1963) configured through checked setters.
#[derive(Debug, Clone, PartialEq)]
pub struct LevenbergMarquardt {
    max_iterations: usize,
    xtol: f64,
    ftol: f64,
    gtol: f64,
    scheme: FiniteDifference,
    rel_step: Option<f64>,
    initial_damping: f64,
    final_jacobian: bool,
}

impl Default for LevenbergMarquardt {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            xtol: 1e-10,
            ftol: 1e-12,
            gtol: 1e-10,
            scheme: FiniteDifference::Forward,
            rel_step: None,
            initial_damping: LM_INITIAL_DAMPING,
            final_jacobian: true,
        }
    }
}

fn check_tol(name: &'static str, v: f64) -> Result<f64, OptimizeError> {
    if v >= 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(invalid(name, v, "must be finite and >= 0"))
    }
}

impl LevenbergMarquardt {
    /// Solver with the defaults: 100 iterations, `xtol = 1e-10`, `ftol = 1e-12`,
    /// `gtol = 1e-10`, forward differences with [`FD_REL_STEP_FORWARD`].
    pub fn new() -> Self {
        Self::default()
    }

    /// Maximum number of iterations (≥ 1).
    pub fn max_iterations(mut self, n: usize) -> Result<Self, OptimizeError> {
        if n == 0 {
            return Err(invalid("max_iterations", n, "must be >= 1"));
        }
        self.max_iterations = n;
        Ok(self)
    }

    /// Stop when `‖D^½ δ‖ ≤ xtol · ‖D^½ x‖` (scaled step small; `≥ 0`).
    pub fn xtol(mut self, v: f64) -> Result<Self, OptimizeError> {
        self.xtol = check_tol("xtol", v)?;
        Ok(self)
    }

    /// Stop when an accepted step lowers the cost by at most `ftol · cost` (`≥ 0`).
    pub fn ftol(mut self, v: f64) -> Result<Self, OptimizeError> {
        self.ftol = check_tol("ftol", v)?;
        Ok(self)
    }

    /// Stop when `max_q |g_q| / (‖J_q‖ ‖r‖) ≤ gtol` over the free parameters (`≥ 0`).
    pub fn gtol(mut self, v: f64) -> Result<Self, OptimizeError> {
        self.gtol = check_tol("gtol", v)?;
        Ok(self)
    }

    /// Finite-difference scheme for the Jacobian.
    pub fn finite_difference(mut self, scheme: FiniteDifference) -> Self {
        self.scheme = scheme;
        self
    }

    /// Relative finite-difference step (default: the scheme's own, see
    /// [`FiniteDifference::default_rel_step`]); must be in `(0, 0.1]`.
    pub fn fd_rel_step(mut self, h: f64) -> Result<Self, OptimizeError> {
        if !(h > 0.0 && h <= 0.1) {
            return Err(invalid("fd_rel_step", h, "must be in (0, 0.1]"));
        }
        self.rel_step = Some(h);
        Ok(self)
    }

    /// Initial damping `λ₀` (relative to `diag(JᵀJ)`; `> 0`).
    pub fn initial_damping(mut self, l: f64) -> Result<Self, OptimizeError> {
        if !(l > 0.0 && l.is_finite()) {
            return Err(invalid("initial_damping", l, "must be finite and > 0"));
        }
        self.initial_damping = l;
        Ok(self)
    }

    /// Whether the result carries the Jacobian at its `x` (default true). The last accepted
    /// step leaves the Jacobian of the point before it, so a run whose caller only wants the
    /// minimum saves the `n` (forward) or `2n` (central) evaluations of a fresh one.
    pub fn final_jacobian(mut self, v: bool) -> Self {
        self.final_jacobian = v;
        self
    }

    /// Minimises `Σ r_i(x)²` from `x0`, inside `bounds` if given (`x0` is projected onto the
    /// box first).
    pub fn minimize<P: LeastSquares + ?Sized>(
        &self,
        problem: &P,
        x0: &[f64],
        bounds: Option<&Bounds>,
    ) -> Result<LmResult, OptimizeError> {
        let n = problem.n_params();
        let m = problem.n_residuals();
        if n == 0 {
            return Err(OptimizeError::EmptyProblem);
        }
        check_len("x0", n, x0.len())?;
        if let Some(b) = bounds {
            check_len("bounds", n, b.dim())?;
        }
        if x0.iter().any(|v| !v.is_finite()) {
            return Err(OptimizeError::StartNotEvaluable);
        }
        let rel_step = self.rel_step.unwrap_or(self.scheme.default_rel_step());
        let project = |x: &mut [f64]| {
            if let Some(b) = bounds {
                b.clamp(x);
            }
        };

        let mut x = x0.to_vec();
        project(&mut x);
        let mut r = vec![0.0; m];
        let mut evaluations = 1;
        if !eval_ok(problem, &x, &mut r) {
            return Err(OptimizeError::StartNotEvaluable);
        }
        let mut cost = sum_sq(&r);
        let mut jac = vec![0.0; m * n];
        let mut jac_current = false; // whether `jac` belongs to the current `x`
        let mut lambda = self.initial_damping;
        let mut diag_scale = vec![0.0f64; n];
        let mut iterations = 0;
        let mut r_trial = vec![0.0; m];
        let mut x_trial = vec![0.0; n];

        let stop_reason = 'outer: loop {
            if cost == 0.0 {
                break LmStopReason::ExactFit;
            }
            if iterations >= self.max_iterations {
                break LmStopReason::MaxIterations;
            }
            match jacobian_fd(problem, &x, &r, bounds, self.scheme, rel_step, &mut jac) {
                Ok(e) => evaluations += e,
                Err(_) => {
                    jac.clear();
                    break LmStopReason::JacobianFailed;
                }
            }
            jac_current = true;
            iterations += 1;
            let a = jtj(&jac, m, n);
            let g = jt_vec(&jac, m, n, &r);
            for q in 0..n {
                diag_scale[q] = diag_scale[q].max(a[q * n + q]);
            }
            // Active set: parameters on a bound whose descent direction −g points outwards.
            let free: Vec<usize> = (0..n)
                .filter(|&q| match bounds {
                    Some(b) => {
                        !((x[q] <= b.lower()[q] && g[q] > 0.0)
                            || (x[q] >= b.upper()[q] && g[q] < 0.0))
                    }
                    None => true,
                })
                .collect();
            let rnorm = cost.sqrt();
            let gcos = free
                .iter()
                .map(|&q| {
                    let cn = a[q * n + q].sqrt();
                    if cn > 0.0 {
                        g[q].abs() / (cn * rnorm)
                    } else {
                        0.0
                    }
                })
                .fold(0.0f64, f64::max);
            if gcos <= self.gtol {
                break LmStopReason::SmallGradient;
            }
            let k = free.len();
            let xnorm: f64 = (0..n)
                .map(|q| diag_scale[q] * x[q] * x[q])
                .sum::<f64>()
                .sqrt();
            loop {
                let mut sys = vec![0.0; k * k];
                let mut rhs = vec![0.0; k];
                for (i, &p) in free.iter().enumerate() {
                    for (j, &q) in free.iter().enumerate() {
                        sys[i * k + j] = a[p * n + q];
                    }
                    sys[i * k + i] += lambda * diag_scale[p];
                    rhs[i] = -g[p];
                }
                let delta = solve_spd(&sys, k, &rhs);
                x_trial.copy_from_slice(&x);
                for (i, &p) in free.iter().enumerate() {
                    x_trial[p] += delta[i];
                }
                project(&mut x_trial);
                let step_norm: f64 = (0..n)
                    .map(|q| diag_scale[q] * (x_trial[q] - x[q]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                if step_norm <= self.xtol * xnorm || step_norm == 0.0 || !step_norm.is_finite() {
                    break 'outer LmStopReason::SmallStep;
                }
                evaluations += 1;
                let ok = eval_ok(problem, &x_trial, &mut r_trial);
                let new_cost = if ok { sum_sq(&r_trial) } else { f64::INFINITY };
                if new_cost < cost {
                    let decrease = (cost - new_cost) / cost;
                    x.copy_from_slice(&x_trial);
                    r.copy_from_slice(&r_trial);
                    cost = new_cost;
                    jac_current = false;
                    lambda = (lambda / LM_DAMPING_DOWN).max(LM_DAMPING_MIN);
                    if cost == 0.0 {
                        break 'outer LmStopReason::ExactFit;
                    }
                    if decrease <= self.ftol {
                        break 'outer LmStopReason::SmallCostDecrease;
                    }
                    if step_norm <= self.xtol * (xnorm + step_norm) {
                        break 'outer LmStopReason::SmallStep;
                    }
                    break;
                }
                lambda *= LM_DAMPING_UP;
                if lambda > LM_DAMPING_MAX {
                    break 'outer LmStopReason::DampingLimit;
                }
            }
        };

        if !self.final_jacobian {
            jac.clear();
        } else if !jac_current && stop_reason != LmStopReason::JacobianFailed {
            match jacobian_fd(problem, &x, &r, bounds, self.scheme, rel_step, &mut jac) {
                Ok(e) => evaluations += e,
                Err(_) => jac.clear(),
            }
        }
        Ok(LmResult {
            x,
            cost,
            residuals: r,
            jacobian: jac,
            iterations,
            evaluations,
            stop_reason,
        })
    }
}

fn sum_sq(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

#[cfg(test)]
mod tests {
    use std::cell::{Cell, RefCell};

    use super::*;

    /// `y = a exp(−b t) + c` sampled at `t = 0, 0.5, …, 10`.
    struct ExpFit {
        t: Vec<f64>,
        y: Vec<f64>,
    }

    impl ExpFit {
        fn new(p: [f64; 3]) -> Self {
            let t: Vec<f64> = (0..=20).map(|k| 0.5 * k as f64).collect();
            let y = t.iter().map(|&t| Self::model(&p, t)).collect();
            Self { t, y }
        }
        fn model(p: &[f64], t: f64) -> f64 {
            p[0] * (-p[1] * t).exp() + p[2]
        }
        fn analytic_jacobian(&self, p: &[f64]) -> Vec<f64> {
            self.t
                .iter()
                .flat_map(|&t| {
                    let e = (-p[1] * t).exp();
                    [e, -p[0] * t * e, 1.0]
                })
                .collect()
        }
    }

    impl LeastSquares for ExpFit {
        fn n_params(&self) -> usize {
            3
        }
        fn n_residuals(&self) -> usize {
            self.t.len()
        }
        fn residuals(&self, x: &[f64], out: &mut [f64]) -> bool {
            for ((o, &t), &y) in out.iter_mut().zip(&self.t).zip(&self.y) {
                *o = Self::model(x, t) - y;
            }
            true
        }
    }

    struct Rosenbrock;

    impl LeastSquares for Rosenbrock {
        fn n_params(&self) -> usize {
            2
        }
        fn n_residuals(&self) -> usize {
            2
        }
        fn residuals(&self, x: &[f64], out: &mut [f64]) -> bool {
            out[0] = 10.0 * (x[1] - x[0] * x[0]);
            out[1] = 1.0 - x[0];
            true
        }
    }

    #[test]
    fn recovers_exponential_parameters_exactly() {
        let truth = [2.5, 0.7, 0.3];
        let p = ExpFit::new(truth);
        for scheme in [FiniteDifference::Forward, FiniteDifference::Central] {
            let lm = LevenbergMarquardt::new().finite_difference(scheme);
            let r = lm.minimize(&p, &[1.0, 0.2, 0.0], None).unwrap();
            for (x, t) in r.x.iter().zip(truth) {
                assert!(
                    (x - t).abs() < 1e-8,
                    "{scheme:?}: {:?} ({:?})",
                    r.x,
                    r.stop_reason
                );
            }
            assert!(r.cost < 1e-18, "{}", r.cost);
            assert!(r.iterations < 50);
            assert_eq!(r.jacobian.len(), 21 * 3);
            // The returned Jacobian is the one at the optimum.
            let exact = p.analytic_jacobian(&r.x);
            for (a, e) in r.jacobian.iter().zip(&exact) {
                assert!((a - e).abs() < 1e-5 * (1.0 + e.abs()));
            }
        }
    }

    #[test]
    fn a_run_without_the_final_jacobian_ends_at_the_same_point_for_fewer_evaluations() {
        let p = ExpFit::new([2.5, 0.7, 0.3]);
        // Three iterations: the run ends at its cap, on an accepted step.
        let lm = LevenbergMarquardt::new().max_iterations(3).unwrap();
        let with = lm.clone().minimize(&p, &[1.0, 0.2, 0.0], None).unwrap();
        let without = lm
            .final_jacobian(false)
            .minimize(&p, &[1.0, 0.2, 0.0], None)
            .unwrap();
        assert_eq!(with.stop_reason, LmStopReason::MaxIterations);
        assert_eq!(with.x, without.x);
        assert_eq!(with.cost, without.cost);
        assert_eq!(with.iterations, without.iterations);
        assert_eq!(with.jacobian.len(), 21 * 3);
        assert!(without.jacobian.is_empty());
        // The full result paid for a fresh Jacobian at its end (3 forward differences).
        assert_eq!(with.evaluations, without.evaluations + 3);
    }

    #[test]
    fn solves_rosenbrock_least_squares() {
        let r = LevenbergMarquardt::new()
            .minimize(&Rosenbrock, &[-1.2, 1.0], None)
            .unwrap();
        assert!(
            (r.x[0] - 1.0).abs() < 1e-8 && (r.x[1] - 1.0).abs() < 1e-8,
            "{:?}",
            r
        );
        assert!(r.cost < 1e-16);
    }

    /// `y = a t + c` with data from `a = 3, c = 1`; records every evaluated point.
    struct Line {
        points: RefCell<Vec<Vec<f64>>>,
    }

    impl LeastSquares for Line {
        fn n_params(&self) -> usize {
            2
        }
        fn n_residuals(&self) -> usize {
            5
        }
        fn residuals(&self, x: &[f64], out: &mut [f64]) -> bool {
            self.points.borrow_mut().push(x.to_vec());
            for (k, o) in out.iter_mut().enumerate() {
                let t = k as f64;
                *o = x[0] * t + x[1] - (3.0 * t + 1.0);
            }
            true
        }
    }

    #[test]
    fn respects_bounds_and_ends_on_the_active_bound() {
        let p = Line {
            points: RefCell::new(Vec::new()),
        };
        let b = Bounds::from_pairs(&[(0.0, 2.0), (-10.0, 10.0)]).unwrap();
        for scheme in [FiniteDifference::Forward, FiniteDifference::Central] {
            p.points.borrow_mut().clear();
            let r = LevenbergMarquardt::new()
                .finite_difference(scheme)
                .minimize(&p, &[0.5, 0.0], Some(&b))
                .unwrap();
            assert!(p.points.borrow().iter().all(|x| b.contains(x)));
            // With a = 2 fixed, the best c is mean(y − 2t) = mean(t + 1) = 3.
            assert_eq!(r.x[0], 2.0, "{r:?}");
            assert!((r.x[1] - 3.0).abs() < 1e-8, "{r:?}");
            assert!(b.contains(&r.x));
        }
        // A start outside the box is projected onto it.
        let r = LevenbergMarquardt::new()
            .minimize(&p, &[7.0, 0.0], Some(&b))
            .unwrap();
        assert_eq!(r.x[0], 2.0);
    }

    /// `r = exp(x) − e³`, which cannot be evaluated for `x > 5`.
    struct Fragile {
        failures: Cell<usize>,
    }

    impl LeastSquares for Fragile {
        fn n_params(&self) -> usize {
            1
        }
        fn n_residuals(&self) -> usize {
            1
        }
        fn residuals(&self, x: &[f64], out: &mut [f64]) -> bool {
            if x[0] > 5.0 {
                self.failures.set(self.failures.get() + 1);
                return false;
            }
            out[0] = x[0].exp() - 3f64.exp();
            true
        }
    }

    #[test]
    fn failed_evaluations_are_rejected_steps() {
        let p = Fragile {
            failures: Cell::new(0),
        };
        // From x = 0 the Gauss–Newton step (≈ +19) lands where the model fails.
        let r = LevenbergMarquardt::new()
            .minimize(&p, &[0.0], None)
            .unwrap();
        assert!(p.failures.get() > 0);
        assert!((r.x[0] - 3.0).abs() < 1e-9, "{r:?}");
        // Not evaluable at the start: an error, not a result.
        assert_eq!(
            LevenbergMarquardt::new().minimize(&p, &[6.0], None),
            Err(OptimizeError::StartNotEvaluable)
        );
    }

    #[test]
    fn finite_difference_jacobian_accuracy_and_bounds() {
        let p = ExpFit::new([2.5, 0.7, 0.3]);
        let x = [2.0, 0.5, 0.1];
        let mut r0 = vec![0.0; 21];
        p.residuals(&x, &mut r0);
        let exact = p.analytic_jacobian(&x);
        let err = |j: &[f64]| {
            j.iter()
                .zip(&exact)
                .map(|(a, e)| (a - e).abs() / (1.0 + e.abs()))
                .fold(0.0, f64::max)
        };
        let mut j = vec![0.0; 63];
        let n = jacobian_fd(
            &p,
            &x,
            &r0,
            None,
            FiniteDifference::Forward,
            FD_REL_STEP_FORWARD,
            &mut j,
        )
        .unwrap();
        assert_eq!(n, 3);
        assert!(err(&j) < 1e-6, "{}", err(&j));
        let n = jacobian_fd(
            &p,
            &x,
            &r0,
            None,
            FiniteDifference::Central,
            FD_REL_STEP_CENTRAL,
            &mut j,
        )
        .unwrap();
        assert_eq!(n, 6);
        assert!(err(&j) < 1e-9, "{}", err(&j));
        // At the upper bound of every parameter: steps go inwards, still accurate.
        let b = Bounds::from_pairs(&[(0.0, 2.0), (0.0, 0.5), (-1.0, 0.1)]).unwrap();
        for (scheme, tol) in [
            (FiniteDifference::Forward, 1e-6),
            (FiniteDifference::Central, 1e-8),
        ] {
            let rec = RecordingFit {
                inner: &p,
                points: RefCell::new(Vec::new()),
            };
            jacobian_fd(
                &rec,
                &x,
                &r0,
                Some(&b),
                scheme,
                scheme.default_rel_step(),
                &mut j,
            )
            .unwrap();
            assert!(rec.points.borrow().iter().all(|pt| b.contains(pt)));
            assert!(err(&j) < tol, "{scheme:?}: {}", err(&j));
        }
        assert!(jacobian_fd(&p, &x, &r0, None, FiniteDifference::Forward, 0.0, &mut j).is_err());
        assert!(jacobian_fd(
            &p,
            &x,
            &r0,
            None,
            FiniteDifference::Forward,
            1e-8,
            &mut j[..5]
        )
        .is_err());
    }

    struct RecordingFit<'a> {
        inner: &'a ExpFit,
        points: RefCell<Vec<Vec<f64>>>,
    }

    impl LeastSquares for RecordingFit<'_> {
        fn n_params(&self) -> usize {
            3
        }
        fn n_residuals(&self) -> usize {
            self.inner.n_residuals()
        }
        fn residuals(&self, x: &[f64], out: &mut [f64]) -> bool {
            self.points.borrow_mut().push(x.to_vec());
            self.inner.residuals(x, out)
        }
    }

    #[test]
    fn setters_reject_bad_input() {
        let lm = LevenbergMarquardt::new();
        assert!(lm.clone().max_iterations(0).is_err());
        assert!(lm.clone().xtol(-1.0).is_err());
        assert!(lm.clone().ftol(f64::NAN).is_err());
        assert!(lm.clone().gtol(f64::INFINITY).is_err());
        assert!(lm.clone().fd_rel_step(0.0).is_err());
        assert!(lm.clone().fd_rel_step(0.5).is_err());
        assert!(lm.clone().initial_damping(0.0).is_err());
        assert!(lm.clone().max_iterations(3).is_ok());
        assert!(matches!(
            lm.minimize(&Rosenbrock, &[1.0], None),
            Err(OptimizeError::DimensionMismatch { .. })
        ));
    }

    #[test]
    fn iteration_limit_is_reported() {
        let r = LevenbergMarquardt::new()
            .max_iterations(2)
            .unwrap()
            .minimize(&Rosenbrock, &[-1.2, 1.0], None)
            .unwrap();
        assert_eq!(r.stop_reason, LmStopReason::MaxIterations);
        assert_eq!(r.iterations, 2);
    }

    #[test]
    fn sum_of_squares_objective() {
        let f = SumOfSquares(Rosenbrock);
        assert_eq!(f.dim(), 2);
        assert_eq!(f.value(&[1.0, 1.0]), 0.0);
        assert_eq!(f.value(&[0.0, 0.0]), 1.0);
        let g = SumOfSquares(Fragile {
            failures: Cell::new(0),
        });
        assert_eq!(g.value(&[6.0]), f64::INFINITY);
    }
}
