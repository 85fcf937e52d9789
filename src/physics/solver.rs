//! Root solver for the dispersion relation, model §5: Muller's method (P40) started from the
//! in-vacuo root (P39) and continued in frequency (P41–P42), with failure detection (§5.6)
//! reported as data.

use std::fmt;

use num_complex::Complex64;

use super::dispersion::Evaluator;
use super::inputs::System;
use crate::special::abs;

/// Muller stops when |dx| ≤ tol·|x| (model §5.5).
pub const MULLER_STEP_RTOL: f64 = 1e-13;
/// Muller gives up after this many iterations (model §5.5).
pub const MULLER_MAX_ITER: u32 = 100;
/// Muller's iterations when it is Newton's fallback ([`RootMethod::Newton`], the inversion's
/// fast path); as the primary iteration (model §5.3, [`RootMethod::Muller`]) it keeps
/// [`MULLER_MAX_ITER`]. Converged fallbacks take 1–10 iterations in more than 99 % of cases on
/// realistic networks, while one that does not converge runs all its iterations at each of up
/// to [`MAX_STEP_HALVINGS`] halvings of the continuation's step; so a low cap makes the solves
/// that fail near grazing (P44) cheap without moving the fits (see also [`NEWTON_MAX_ITER`]).
pub const MULLER_FALLBACK_MAX_ITER: u32 = 10;
/// A root is accepted only if |F(k1)| ≤ this; F is O(1) (model §5.5).
pub const RESIDUAL_ATOL: f64 = 1e-10;
/// Jump detector threshold on the correction ratio of eq. P43 (model §5.5).
pub const CONTINUATION_RATIO_MAX: f64 = 0.1;
/// Near-grazing band on |c/c_soil − 1|, eq. P44 (model §5.5).
pub const GRAZING_RTOL: f64 = 0.02;
/// Whether a phase speed c lies in the near-grazing band of the soil's wave speeds c_P and c_S:
/// |c/c_soil − 1| < [`GRAZING_RTOL`] for either, eq. P44 (model §5.5). The `near_grazing` flag
/// of a root, and the fit's test for another gap scan (`invert::probes`).
pub fn near_grazing(c: f64, c_p: f64, c_s: f64) -> bool {
    (c / c_p - 1.0).abs() < GRAZING_RTOL || (c / c_s - 1.0).abs() < GRAZING_RTOL
}
/// How many times a continuation step may be halved before a branch jump is declared (§5.6).
pub const MAX_STEP_HALVINGS: u32 = 10;
/// Growing-wave threshold: Im k1 > this·|k1| with every loss factor ≥ 0 (§5.6).
pub const GROWING_RTOL: f64 = 1e-12;
/// The correction ratio (P43) is not tested when a step moves the root by less than this
/// relative amount: both numerator and denominator are then rounding noise.
pub const RATIO_MIN_STEP_RTOL: f64 = 1e-9;
/// A continuation that fails within this relative distance of a soil wave speed
/// (|c/c_soil − 1|, eq. P44) is restarted beyond the grazing point (`restart_past_grazing`).
pub const GRAZING_RESTART_RTOL: f64 = 0.05;
/// Geometric ramp points below the lowest requested frequency, eq. P41 (the reference's 29).
pub const RAMP_POINTS: usize = 29;
/// Start of the ramp: ω₀ = min(2π·5 rad/s, ω_min/2), eq. P41.
pub const RAMP_START_HZ: f64 = 5.0;

/// Why no root could be reported (model §5.6).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// Muller exceeded its iterations, F became non-finite, or |F| stayed above the tolerance.
    #[error("no convergence at omega = {omega} rad/s (|F| = {residual:e})")]
    NoConvergence {
        /// Angular frequency, rad/s.
        omega: f64,
        /// Last |F| (NaN or inf when F was not finite).
        residual: f64,
    },
    /// The root has Re k1 ≤ 0: not the forward s = 1 wave.
    #[error("wrong root at omega = {omega} rad/s: k1 = {k1}")]
    WrongRoot {
        /// Angular frequency, rad/s.
        omega: f64,
        /// The root found.
        k1: Complex64,
    },
    /// The correction ratio of eq. P43 stayed above the threshold after all step halvings.
    #[error("branch jump at omega = {omega} rad/s (correction ratio {ratio:.3})")]
    BranchJump {
        /// Angular frequency, rad/s.
        omega: f64,
        /// The correction ratio of the last attempt.
        ratio: f64,
    },
    /// The tracked root met a soil wave speed (grazing, P44) and left the proper Riemann
    /// sheet of eq. P3 there, and no root of the proper sheet was found beyond that point.
    #[error(
        "no s = 1 root at omega = {omega} rad/s: the wave reached the soil's {wave} speed \
         ({speed:.1} m/s) at grazing, where the root leaves the proper sheet of the branch rule"
    )]
    Grazing {
        /// Angular frequency, rad/s.
        omega: f64,
        /// "compressional" or "shear".
        wave: &'static str,
        /// That soil wave speed, m/s.
        speed: f64,
    },
    /// The frequency is not a positive finite number.
    #[error("invalid angular frequency {omega} rad/s")]
    InvalidFrequency {
        /// The rejected value.
        omega: f64,
    },
}

impl SolveError {
    /// Short status code for tables (`forward`'s `status` column).
    pub fn code(&self) -> &'static str {
        match self {
            SolveError::NoConvergence { .. } => "no_convergence",
            SolveError::WrongRoot { .. } => "wrong_root",
            SolveError::BranchJump { .. } => "branch_jump",
            SolveError::Grazing { .. } => "grazing",
            SolveError::InvalidFrequency { .. } => "invalid_frequency",
        }
    }
}

/// Warnings attached to a root that was found (model §3.2, §5.6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RootFlags {
    /// Im k1 > 0 although every loss factor is ≥ 0: a growing wave (the known defect of
    /// `printed`, or a bug / branch jump for the other readings).
    pub growing_wave: bool,
    /// The phase speed is within 2 % of a soil wave speed (eq. P44).
    pub near_grazing: bool,
    /// The frequency or the wall is outside the model's validity (eq. P7).
    pub out_of_validity: bool,
    /// The phase speed exceeds the free-field sound speed of the fluid (warning, §5.6 item 2).
    pub faster_than_fluid: bool,
}

impl RootFlags {
    /// Comma-separated codes of the raised flags (empty when none).
    pub fn codes(&self) -> String {
        let mut v = Vec::new();
        if self.growing_wave {
            v.push("growing_wave");
        }
        if self.near_grazing {
            v.push("near_grazing");
        }
        if self.out_of_validity {
            v.push("out_of_validity");
        }
        if self.faster_than_fluid {
            v.push("faster_than_fluid");
        }
        v.join(",")
    }

    /// True when no flag is raised.
    pub fn is_clean(&self) -> bool {
        *self == RootFlags::default()
    }
}

impl fmt::Display for RootFlags {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.codes())
    }
}

/// A root of the dispersion relation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Root {
    /// Angular frequency ω, rad/s.
    pub omega: f64,
    /// The wavenumber k1, rad/m (Im k1 < 0 for a decaying wave).
    pub k1: Complex64,
    /// |F(k1)| at the root.
    pub residual: f64,
    /// Muller iterations used for the final solve.
    pub iterations: u32,
    /// Warnings.
    pub flags: RootFlags,
}

impl Root {
    /// Phase speed c = ω/Re k1, m/s (eq. P2).
    pub fn phase_speed(&self) -> f64 {
        self.omega / self.k1.re
    }
    /// Attenuation −Im k1 in Np/m (eq. P2).
    pub fn attenuation_np(&self) -> f64 {
        -self.k1.im
    }
    /// Attenuation in dB/m (eq. P2).
    pub fn attenuation_db(&self) -> f64 {
        crate::units::np_to_db(-self.k1.im)
    }
}

/// Stopping rule of Muller's method.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerance {
    /// Stop when |dx| ≤ step_rtol·|x| (model §5.5: [`MULLER_STEP_RTOL`]).
    pub step_rtol: f64,
    /// Also stop as soon as |F| ≤ residual_stop. Model §5.3's rule is 0 (stop only on F = 0);
    /// F is well conditioned on the s = 1 branch (k1·dF/dk1 = 2(1 + β₀) = O(1–30)), so
    /// |F| ≤ 1e-12 bounds the relative error of k1 near 1e-12 and saves the confirming step.
    pub residual_stop: f64,
    /// The iteration: Muller's (P40) or Newton's with the analytic dF/dk1.
    pub method: RootMethod,
}

/// The root iteration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RootMethod {
    /// Muller's method, eq. P40 (model §5.3; no derivative; 3 start evaluations).
    Muller,
    /// Newton's method with the analytic derivative of F ([`Evaluator::residual_d`]), which
    /// model §5.3 allows as an alternative "if it passes the same tests". Stops when a step is
    /// below `step_rtol`, or as soon as the convergence is visibly quadratic (a step below
    /// √step_rtol that is under 1 % of the one before), since the next step would then be below
    /// `step_rtol`. Falls back to Muller, for at most [`MULLER_FALLBACK_MAX_ITER`] iterations,
    /// if it does not converge.
    Newton,
}

impl Tolerance {
    /// The rule of model §5.3 and §5.5: the reference precision.
    pub const REFERENCE: Tolerance = Tolerance {
        step_rtol: MULLER_STEP_RTOL,
        residual_stop: 0.0,
        method: RootMethod::Muller,
    };
    /// For the inversion: stop at |dx| ≤ 1e-10|x| or |F| ≤ 1e-12, far below any measurement
    /// noise yet smooth enough for finite-difference Jacobians with relative steps of 1e-6.
    pub const FAST: Tolerance = Tolerance {
        step_rtol: 1e-10,
        residual_stop: 1e-12,
        method: RootMethod::Newton,
    };
    /// For a global search's selection (the DE runs), which only ranks points: stop at
    /// |dx| ≤ 1e-6|x|, or at a step below 1e-3 under 1 % of the one before. Newton's
    /// convergence being quadratic, the root is then within about 1e-6 relative (the next step),
    /// and the misfit far closer than the search's spread test ([`Tolerance::FAST`] takes one
    /// step more, to machine precision, which finite-difference Jacobians need).
    pub const SEARCH: Tolerance = Tolerance {
        step_rtol: 1e-6,
        residual_stop: 1e-12,
        method: RootMethod::Newton,
    };
}

impl Default for Tolerance {
    fn default() -> Self {
        Tolerance::REFERENCE
    }
}

/// Result of Muller's iteration before classification.
struct MullerOut {
    k1: Complex64,
    residual: f64,
    iterations: u32,
}

/// Muller's method on F from the guess g, eq. P40 [R16], for at most `max_iterations`
/// iterations.
fn muller(
    ev: &Evaluator,
    g: Complex64,
    tol: Tolerance,
    max_iterations: u32,
) -> Result<MullerOut, SolveError> {
    let fail = |r: f64| SolveError::NoConvergence {
        omega: ev.omega,
        residual: r,
    };
    let f = |x: Complex64| -> Result<Complex64, SolveError> {
        match ev.residual(x) {
            Ok(v) if v.re.is_finite() && v.im.is_finite() => Ok(v),
            _ => Err(fail(f64::NAN)),
        }
    };
    let mut x0 = g * (1.0 - 1e-3);
    let mut x1 = g * (1.0 + 1e-3) + Complex64::new(0.0, 1e-6 * g.norm());
    let mut x2 = g;
    let (mut f0, mut f1, mut f2) = (f(x0)?, f(x1)?, f(x2)?);
    for it in 1..=max_iterations {
        let h1 = x1 - x0;
        let h2 = x2 - x1;
        let d1 = (f1 - f0) / h1;
        let d2 = (f2 - f1) / h2;
        let a = (d2 - d1) / (h2 + h1);
        let b = a * h2 + d2;
        let disc = (b * b - 4.0 * f2 * a).sqrt();
        let (bp, bm) = (b + disc, b - disc);
        let den = if bp.norm() >= bm.norm() { bp } else { bm };
        let dx = if den == Complex64::new(0.0, 0.0) || !den.is_finite() {
            Complex64::new(1e-6 * (x2.norm() + 1.0), 0.0)
        } else {
            -2.0 * f2 / den
        };
        let x3 = x2 + dx;
        if !x3.is_finite() {
            return Err(fail(f64::NAN));
        }
        let f3 = f(x3)?;
        if dx.norm() <= tol.step_rtol * x3.norm() || f3.norm() <= tol.residual_stop {
            let r = f3.norm();
            if r > RESIDUAL_ATOL {
                return Err(fail(r));
            }
            return Ok(MullerOut {
                k1: x3,
                residual: r,
                iterations: it,
            });
        }
        (x0, x1, x2) = (x1, x2, x3);
        (f0, f1, f2) = (f1, f2, f3);
    }
    Err(fail(f2.norm()))
}

/// Newton iterations before falling back to Muller. A converged Newton solve takes 2–3
/// iterations as a rule, and on realistic networks fewer than one in 30,000 takes more than 12.
/// One that does not converge runs them all, and then Muller's [`MULLER_FALLBACK_MAX_ITER`], at
/// every halving of a continuation step that fails near grazing (P44), where the grazing
/// probe's walks meet hundreds of such solves at several times the usual cost per evaluation.
/// With 12 and 10 such a solve costs 22 residual evaluations instead of 50 (at 30 and 20), and
/// the fits end where they did, to rounding.
pub const NEWTON_MAX_ITER: u32 = 12;

/// Newton's method on F with the analytic derivative, from the guess g.
fn newton(ev: &Evaluator, g: Complex64, tol: Tolerance) -> Result<MullerOut, SolveError> {
    let fail = |r: f64| SolveError::NoConvergence {
        omega: ev.omega,
        residual: r,
    };
    let mut x = g;
    let mut prev_step = f64::INFINITY;
    for it in 1..=NEWTON_MAX_ITER {
        let (f, df) = ev.residual_d(x).map_err(|_| fail(f64::NAN))?;
        if !(f.is_finite() && df.is_finite()) || df == Complex64::new(0.0, 0.0) {
            return Err(fail(f64::NAN));
        }
        let r = abs(f);
        if r <= tol.residual_stop {
            return Ok(MullerOut {
                k1: x,
                residual: r,
                iterations: it,
            });
        }
        let mut dx = -f / df;
        // A step longer than half the root is not trusted: shorten it (a damped Newton step).
        let (dx_abs, x_abs) = (abs(dx), abs(x));
        if dx_abs > 0.5 * x_abs {
            dx *= 0.5 * x_abs / dx_abs;
        }
        let x_new = x + dx;
        let step = abs(dx) / abs(x_new);
        let quadratic = it >= 2 && step <= tol.step_rtol.sqrt() && step <= 0.01 * prev_step;
        if step <= tol.step_rtol || quadratic {
            if !newton_accepts(r, step) {
                return Err(fail(r));
            }
            return Ok(MullerOut {
                k1: x_new,
                residual: r,
                iterations: it,
            });
        }
        prev_step = step;
        x = x_new;
    }
    Err(fail(f64::NAN))
}

/// Whether a Newton step that stopped the iteration (relative length `step`, from a point
/// where |F| = `r`) ends at a root: |F| ≤ [`RESIDUAL_ATOL`], or, since F' = O(1) on the s = 1
/// branch (see [`Tolerance::residual_stop`]), |F| of the order of the step (≤ 1e3 · step).
fn newton_accepts(r: f64, step: f64) -> bool {
    r <= RESIDUAL_ATOL.max(1e3 * step)
}

/// The root from guess g by the chosen iteration (Newton falls back to Muller on failure).
fn iterate(ev: &Evaluator, g: Complex64, tol: Tolerance) -> Result<MullerOut, SolveError> {
    match tol.method {
        RootMethod::Muller => muller(ev, g, tol, MULLER_MAX_ITER),
        RootMethod::Newton => {
            newton(ev, g, tol).or_else(|_| muller(ev, g, tol, MULLER_FALLBACK_MAX_ITER))
        }
    }
}

/// Classify a converged root: wrong root (error) or flags (model §5.6, §3.2).
fn classify(system: &System, ev: &Evaluator, out: MullerOut) -> Result<Root, SolveError> {
    let k1 = out.k1;
    if k1.re <= 0.0 {
        return Err(SolveError::WrongRoot {
            omega: ev.omega,
            k1,
        });
    }
    let c = ev.omega / k1.re;
    let mut flags = RootFlags {
        growing_wave: k1.im > GROWING_RTOL * abs(k1),
        faster_than_fluid: c > system.fluid.sound_speed(),
        ..RootFlags::default()
    };
    if !system.soil.is_absent() {
        let (cp, cs) = system.soil.wave_speeds();
        flags.near_grazing = near_grazing(c, cp, cs);
    }
    flags.out_of_validity = out_of_validity(system, ev.omega);
    Ok(Root {
        omega: ev.omega,
        k1,
        residual: out.residual,
        iterations: out.iterations,
        flags,
    })
}

/// Validity of the membrane-shell, single-fluid-mode model, eq. P7: f ≤ f_ring/2,
/// f ≤ f_cut/2 with f_cut = 3.8317·c_f/(2πa), and h/a ≤ 0.25.
pub fn out_of_validity(system: &System, omega: f64) -> bool {
    let f = omega / (2.0 * std::f64::consts::PI);
    let p = &system.pipe;
    let f_ring = p.ring_frequency_hz();
    let f_cut = 3.8317 * system.fluid.sound_speed() / (2.0 * std::f64::consts::PI * p.mean_radius);
    f > f_ring / 2.0 || f > f_cut / 2.0 || p.wall_thickness / p.mean_radius > 0.25
}

/// Solve at one frequency from a guess (no continuation). Used by continuation and for
/// direct solves; classification of the result as in §5.6.
pub fn solve_from_guess(system: &System, omega: f64, guess: Complex64) -> Result<Root, SolveError> {
    solve_from_guess_tol(system, omega, guess, Tolerance::REFERENCE)
}

/// [`solve_from_guess`] with another stopping rule. The residual acceptance [`RESIDUAL_ATOL`]
/// is unchanged.
pub fn solve_from_guess_tol(
    system: &System,
    omega: f64,
    guess: Complex64,
    tol: Tolerance,
) -> Result<Root, SolveError> {
    if !(omega.is_finite() && omega > 0.0) {
        return Err(SolveError::InvalidFrequency { omega });
    }
    let ev = Evaluator::new(system, omega);
    let out = iterate(&ev, guess, tol)?;
    classify(system, &ev, out)
}

/// Largest relative Newton step [`refine_near`] accepts. From a start that close to the root,
/// Newton's quadratic convergence leaves an error of order 1e-10 relative after the step, as
/// [`Tolerance::FAST`]'s quadratic stopping rule does.
pub const NEAR_STEP_RTOL: f64 = 1e-5;

/// The root at `omega` next to `guess`, the root of a system a finite-difference step away (a
/// Jacobian's neighbour): one Newton step on the residual F(k1) of eq. P32, accepted when it
/// moves the root by at most [`NEAR_STEP_RTOL`] relative, ends at a root as a converged Newton
/// iteration does, and leaves it classified as [`solve_from_guess`] would. `None`
/// otherwise: across a cliff of the misfit (a branch cut of q_P or q_S moving past the root,
/// where F jumps) the step is long, and the caller solves on its usual path.
///
/// A Newton start from the continuation takes 2–4 steps at the inversion's tolerance
/// ([`Tolerance::FAST`]), each one [`Evaluator::residual_d`]; this takes one.
pub fn refine_near(system: &System, omega: f64, guess: Complex64) -> Option<Root> {
    if !(omega.is_finite() && omega > 0.0) {
        return None;
    }
    let ev = Evaluator::new(system, omega);
    let (f, df) = ev.residual_d(guess).ok()?;
    if !(f.is_finite() && df.is_finite()) || df == Complex64::new(0.0, 0.0) {
        return None;
    }
    let k1 = guess - f / df;
    let step = abs(k1 - guess) / abs(k1);
    let r = abs(f);
    // A NaN step fails the first test.
    let short = step <= NEAR_STEP_RTOL;
    if !short || !newton_accepts(r, step) {
        return None;
    }
    classify(
        system,
        &ev,
        MullerOut {
            k1,
            residual: r,
            iterations: 1,
        },
    )
    .ok()
}

/// Solve directly at one frequency from the in-vacuo root (P39), without continuation.
/// Fine for iron in soft soil; for plastics in stiff soil prefer [`solve_curve`].
pub fn solve_direct(system: &System, omega: f64) -> Result<Root, SolveError> {
    solve_direct_tol(system, omega, Tolerance::REFERENCE)
}

fn solve_direct_tol(system: &System, omega: f64, tol: Tolerance) -> Result<Root, SolveError> {
    if !(omega.is_finite() && omega > 0.0) {
        return Err(SolveError::InvalidFrequency { omega });
    }
    let ev = Evaluator::new(system, omega);
    let g = ev.in_vacuo_root();
    classify(system, &ev, iterate(&ev, g, tol)?)
}

/// Options of the frequency continuation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Continuation {
    /// Number of geometric ramp points below the lowest requested frequency (P41).
    /// 0 means no ramp: the lowest frequency is solved directly from its in-vacuo root.
    pub ramp_points: usize,
    /// Muller's stopping rule (default: the reference's, [`Tolerance::REFERENCE`]).
    pub tolerance: Tolerance,
}

impl Default for Continuation {
    fn default() -> Self {
        Self {
            ramp_points: RAMP_POINTS,
            tolerance: Tolerance::REFERENCE,
        }
    }
}

/// One accepted point of a continuation path.
#[derive(Clone, Copy)]
struct PathPoint {
    omega: f64,
    k1: Complex64,
}

/// Linear extrapolation guess of eq. P42 from the last two accepted points.
fn extrapolate(hist: &[PathPoint], omega: f64) -> Complex64 {
    match hist {
        [] => unreachable_guess(),
        [p] => p.k1 * (omega / p.omega),
        [.., p2, p1] => {
            if p1.omega == p2.omega {
                p1.k1
            } else {
                p1.k1 + (p1.k1 - p2.k1) * ((omega - p1.omega) / (p1.omega - p2.omega))
            }
        }
    }
}

#[inline]
fn unreachable_guess() -> Complex64 {
    // The path always starts with the in-vacuo root, so the history is never empty when a
    // guess is needed; a NaN here would surface as NoConvergence, never as a wrong number.
    Complex64::new(f64::NAN, f64::NAN)
}

/// Roots along a continuation in frequency, eqs. P41–P43, for the requested angular frequencies
/// in any order (repeats allowed). Returns one result per requested ω, in the input order.
///
/// After a failure the following frequencies are not trusted: they are reported with the same
/// error, since a continuation that lost the branch cannot say which root it would track.
pub fn solve_curve(
    system: &System,
    omegas: &[f64],
    opts: Continuation,
) -> Vec<Result<Root, SolveError>> {
    let mut out: Vec<Option<Result<Root, SolveError>>> = vec![None; omegas.len()];
    let mut order: Vec<usize> = Vec::with_capacity(omegas.len());
    for (i, &w) in omegas.iter().enumerate() {
        if w.is_finite() && w > 0.0 {
            order.push(i);
        } else {
            out[i] = Some(Err(SolveError::InvalidFrequency { omega: w }));
        }
    }
    order.sort_by(|&i, &j| omegas[i].total_cmp(&omegas[j]));
    if order.is_empty() {
        return out.into_iter().map(|r| r.expect("filled")).collect();
    }
    let w_min = omegas[order[0]];
    let w0 = (2.0 * std::f64::consts::PI * RAMP_START_HZ).min(w_min / 2.0);
    let mut hist: Vec<PathPoint> = Vec::with_capacity(opts.ramp_points + order.len() + 4);
    let mut failure: Option<SolveError> = None;

    // Ramp: geometric points w0 … w_min (w_min itself excluded), P41.
    let n = opts.ramp_points;
    let tol = opts.tolerance;
    for j in 0..n {
        let w = w0 * (w_min / w0).powf(j as f64 / n as f64);
        let r = if hist.is_empty() {
            solve_direct_tol(system, w, tol)
        } else {
            advance(system, &mut hist, w, tol)
        };
        match r {
            Ok(root) => {
                if hist.is_empty() {
                    hist.push(PathPoint {
                        omega: w,
                        k1: root.k1,
                    });
                }
            }
            Err(e) => {
                failure = Some(e);
                break;
            }
        }
    }
    for &i in &order {
        let w = omegas[i];
        if let Some(e) = failure {
            out[i] = Some(Err(e));
            continue;
        }
        let r = if hist.is_empty() {
            // No ramp: the lowest requested frequency straight from its in-vacuo root.
            solve_direct_tol(system, w, tol).inspect(|root| {
                hist.push(PathPoint {
                    omega: w,
                    k1: root.k1,
                })
            })
        } else {
            advance(system, &mut hist, w, tol)
        };
        if let Err(e) = r {
            failure = Some(e);
        }
        out[i] = Some(r);
    }
    out.into_iter().map(|r| r.expect("filled")).collect()
}

/// [`step_to`], and when it fails next to a soil wave speed, [`restart_past_grazing`].
fn advance(
    system: &System,
    hist: &mut Vec<PathPoint>,
    target: f64,
    tol: Tolerance,
) -> Result<Root, SolveError> {
    match step_to(system, hist, target, tol) {
        Ok(root) => Ok(root),
        Err(e @ SolveError::InvalidFrequency { .. }) => Err(e),
        Err(e) => match grazing_wave(system, hist[hist.len() - 1]) {
            Some(wave) => restart_past_grazing(system, hist, target, tol, wave),
            None => Err(e),
        },
    }
}

/// The soil wave (name, speed) whose speed the root at `p` is within
/// [`GRAZING_RESTART_RTOL`] of, if any.
fn grazing_wave(system: &System, p: PathPoint) -> Option<(&'static str, f64)> {
    if system.soil.is_absent() || p.k1.re <= 0.0 {
        return None;
    }
    let c = p.omega / p.k1.re;
    let (cp, cs) = system.soil.wave_speeds();
    [("compressional", cp), ("shear", cs)]
        .into_iter()
        .find(|&(_, v)| (c / v - 1.0).abs() < GRAZING_RESTART_RTOL)
}

/// The tracked root reached a soil wave speed (grazing, P44): there the branch point of
/// q = √(k_soil² − k1²) (P15) meets the root, which leaves the proper sheet of the branch rule
/// (P3) and cannot be followed further. The s = 1 wave continues on the proper sheet as
/// another root, clear of the soil speed (e.g. a thin plastic pipe whose speed falls below
/// the soil's compressional speed as the frequency rises). Look for it at `target` from the
/// in-vacuo root (P39) and from either side of the grazing wavenumber, and restart the
/// continuation there.
///
/// A root clear of the grazing band, or on the other side of the soil speed from the last
/// accepted point, is preferred: it cannot be the lost root. When every guess ends inside the
/// band on the lost root's side, the wave is still grazing at `target` (a fit whose optimum
/// puts the lowest frequency right at the transition from leaky to trapped). That root is a
/// converged zero of the proper-sheet dispersion function (residual ≤ `RESIDUAL_ATOL`), so it
/// is returned, carrying the `near_grazing` flag of P44 (model §5.6 item 5: meaningful but
/// fragile), rather than no answer at all.
fn restart_past_grazing(
    system: &System,
    hist: &mut Vec<PathPoint>,
    target: f64,
    tol: Tolerance,
    (wave, speed): (&'static str, f64),
) -> Result<Root, SolveError> {
    let last = hist[hist.len() - 1];
    let k_soil = target / speed;
    let ev = Evaluator::new(system, target);
    let guesses = [
        ev.in_vacuo_root(),
        Complex64::new(k_soil * (1.0 + GRAZING_RESTART_RTOL), last.k1.im),
        Complex64::new(k_soil * (1.0 - GRAZING_RESTART_RTOL), last.k1.im),
    ];
    let side = |c: f64| (c / speed - 1.0).signum();
    let mut in_band: Option<Root> = None;
    for g in guesses {
        let Ok(root) = solve_from_guess_tol(system, target, g, tol) else {
            continue;
        };
        if root.flags.growing_wave {
            continue;
        }
        let c = target / root.k1.re;
        let clear = (c / speed - 1.0).abs() >= GRAZING_RTOL;
        let crossed = side(c) != side(last.omega / last.k1.re);
        if clear || crossed {
            return Ok(restart_at(hist, root));
        }
        in_band.get_or_insert(root);
    }
    match in_band {
        Some(root) => Ok(restart_at(hist, root)),
        None => Err(SolveError::Grazing {
            omega: target,
            wave,
            speed,
        }),
    }
}

/// Restart the continuation history at `root`.
fn restart_at(hist: &mut Vec<PathPoint>, root: Root) -> Root {
    hist.clear();
    hist.push(PathPoint {
        omega: root.omega,
        k1: root.k1,
    });
    root
}

/// Advance the continuation to `target`, eq. P43: accept the root when the correction ratio
/// ρ = |k − g|/|k − k_prev| is at most [`CONTINUATION_RATIO_MAX`]; otherwise insert a midpoint
/// between the last accepted point and the target, and retry, up to [`MAX_STEP_HALVINGS`] times.
///
/// The midpoint is accepted once Muller converges there, without its own ratio test: its purpose
/// is to shorten the previous spacing as well as the step. With linear extrapolation
/// ρ ≈ ½|k″/k′|(h + h_prev), so halving the step alone cannot lower ρ below ½|k″/k′|·h_prev
/// after a long ramp step (the 29-point geometric ramp grows ω by 19 % a step; for the MDPE
/// pipe at 800 Hz ρ = 0.11 there). A midpoint on another branch would show up as a persisting
/// ratio at the target, and so as a `BranchJump`, never as a silent wrong root.
fn step_to(
    system: &System,
    hist: &mut Vec<PathPoint>,
    target: f64,
    tol: Tolerance,
) -> Result<Root, SolveError> {
    let last = hist[hist.len() - 1];
    if target == last.omega {
        // A repeated ω gives the previous root (P42).
        return solve_from_guess_tol(system, target, last.k1, tol);
    }
    let mut halvings = 0u32;
    loop {
        let prev = hist[hist.len() - 1];
        let guess = extrapolate(hist, target);
        let attempt = solve_from_guess_tol(system, target, guess, tol);
        let mut ratio = f64::NAN;
        match attempt {
            Ok(root) => {
                // Skipped when the step moved the root by less than rounding can resolve.
                let moved = abs(root.k1 - prev.k1);
                ratio = if hist.len() >= 2 && moved > RATIO_MIN_STEP_RTOL * abs(root.k1) {
                    abs(root.k1 - guess) / moved
                } else {
                    0.0
                };
                if ratio <= CONTINUATION_RATIO_MAX {
                    hist.push(PathPoint {
                        omega: target,
                        k1: root.k1,
                    });
                    return Ok(root);
                }
            }
            Err(SolveError::WrongRoot { .. }) | Err(SolveError::NoConvergence { .. }) => {}
            Err(e) => return Err(e),
        }
        // Insert a point between the last accepted one and the target; move it closer to the
        // last accepted point while Muller does not converge there.
        let mut frac = 0.5;
        loop {
            halvings += 1;
            if halvings > MAX_STEP_HALVINGS {
                return match attempt {
                    Ok(_) => Err(SolveError::BranchJump {
                        omega: target,
                        ratio,
                    }),
                    Err(e) => Err(e),
                };
            }
            let m = prev.omega + frac * (target - prev.omega);
            if let Ok(r) = solve_from_guess_tol(system, m, extrapolate(hist, m), tol) {
                hist.push(PathPoint { omega: m, k1: r.k1 });
                break;
            }
            frac *= 0.5;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{ContactMode, Fluid, Material, Model, Pipe, Soil};

    /// The near-grazing band of P44: within 2 % of c_P or of c_S, on either side, and nowhere
    /// else.
    #[test]
    fn the_near_grazing_band_is_two_percent_either_side_of_either_soil_speed() {
        let (c_p, c_s) = (400.0, 150.0);
        for c in [400.0, 392.1, 407.9, 150.0, 147.1, 152.9] {
            assert!(near_grazing(c, c_p, c_s), "{c}");
        }
        for c in [391.9, 408.1, 146.9, 153.1, 250.0, 1300.0] {
            assert!(!near_grazing(c, c_p, c_s), "{c}");
        }
    }

    /// A thin HDPE pipe (OD 90 mm, wall 5.4 mm) in a near-incompressible soft soil,
    /// the optimum of a fit that failed. Its s = 1 wave is faster than the soil's compressional
    /// wave (363.5 m/s) at 136 Hz and slower from about 259 Hz: the tracked root meets the
    /// branch point there. The reference continuation restarts past it and finds the root of
    /// the proper sheet that the direct solve (no ramp) finds; before, it ended in a
    /// branch jump and the fit failed.
    #[test]
    fn reference_continuation_restarts_past_grazing() {
        let pipe = Pipe::from_outside_diameter(Material::Hdpe.typical(), 0.090, 0.0054).unwrap();
        let soil = Soil::new(4.975_393_44e6, 0.496_719_830_7, 1930.0, 0.0).unwrap();
        let sys = System::new(
            Fluid::water(),
            pipe,
            soil,
            0.734_144_601_3,
            Model::Full,
            ContactMode::Reciprocal,
        )
        .unwrap();
        let (cp, _) = sys.soil.wave_speeds();
        assert!((cp - 363.5).abs() < 0.1, "{cp}");
        let w: Vec<f64> = [136.0, 260.0, 390.0, 520.0, 717.0]
            .iter()
            .map(|f| f * std::f64::consts::TAU)
            .collect();
        let reference = solve_curve(&sys, &w, Continuation::default());
        let direct = solve_curve(
            &sys,
            &w,
            Continuation {
                ramp_points: 0,
                tolerance: Tolerance::REFERENCE,
            },
        );
        for (r, d) in reference.iter().zip(&direct) {
            let (r, d) = (r.as_ref().unwrap(), d.as_ref().unwrap());
            assert!(
                (r.k1 - d.k1).norm() < 1e-10 * d.k1.norm(),
                "{} vs {}",
                r.k1,
                d.k1
            );
        }
        let r = reference[0].as_ref().unwrap();
        assert!(r.phase_speed() > cp);
        let r = reference[1].as_ref().unwrap();
        assert!(r.phase_speed() < cp * (1.0 - GRAZING_RTOL));
        assert!((r.k1 - Complex64::new(4.635_094_676, -0.308_124_806)).norm() < 1e-8);
    }

    /// The other way to lose the root: an MDPE pipe (OD 90 mm, wall 8.2 mm) at the
    /// optimum of a stress-network fit, where the lowest measured frequency (73 Hz) lies right
    /// at the transition from leaky to trapped (c ≈ c_P = 555.8 m/s). The continuation loses
    /// the root there and every restart guess converges to the one root inside the grazing
    /// band, on the lost root's side. Before, the fit failed ("no s = 1 root"); now that root is
    /// returned, flagged near grazing, and it is the root the direct solve from the in-vacuo
    /// start finds, on the proper sheet (not growing).
    #[test]
    fn a_root_still_grazing_after_the_restart_is_returned_and_flagged() {
        let pipe = Pipe::from_outside_diameter(Material::Mdpe.typical(), 0.090, 0.0082).unwrap();
        let soil = Soil::new(456_112_330.665_659, 0.321_992_398_981_503_3, 2127.0, 0.0).unwrap();
        let sys = System::new(
            Fluid::water(),
            pipe,
            soil,
            0.003_050_427_123_886_769_4,
            Model::Full,
            ContactMode::Reciprocal,
        )
        .unwrap();
        let (cp, _) = sys.soil.wave_speeds();
        assert!((cp - 555.8).abs() < 0.1, "{cp}");
        let w: Vec<f64> = [73.0, 212.0, 358.0, 492.0, 584.0]
            .iter()
            .map(|f| f * std::f64::consts::TAU)
            .collect();
        let reference = solve_curve(&sys, &w, Continuation::default());
        let r = reference[0].as_ref().expect("a root at 73 Hz");
        assert!(r.flags.near_grazing && !r.flags.growing_wave);
        assert!(
            (r.phase_speed() / cp - 0.9968).abs() < 1e-3,
            "{}",
            r.phase_speed() / cp
        );
        let direct = solve_from_guess(&sys, w[0], Evaluator::new(&sys, w[0]).in_vacuo_root())
            .expect("the direct solve");
        assert!((r.k1 - direct.k1).norm() < 1e-10 * direct.k1.norm());
        // Above the band the curve continues clear of grazing.
        for r in &reference[1..] {
            let r = r.as_ref().expect("a root");
            assert!(r.phase_speed() < cp * (1.0 - GRAZING_RTOL));
        }
    }

    /// Without a soil wave speed nearby a failure is not turned into a restart: the grazing
    /// test names the wave only within its band.
    #[test]
    fn grazing_wave_is_named_only_inside_its_band() {
        let pipe = Pipe::from_outside_diameter(Material::Hdpe.typical(), 0.090, 0.0054).unwrap();
        let soil = Soil::new(1.8e7, 0.32, 1930.0, 0.0).unwrap();
        let sys = System::new(
            Fluid::water(),
            pipe,
            soil,
            0.3,
            Model::Full,
            ContactMode::Reciprocal,
        )
        .unwrap();
        let (cp, cs) = sys.soil.wave_speeds();
        let at = |c: f64| PathPoint {
            omega: 1000.0,
            k1: Complex64::new(1000.0 / c, -0.1),
        };
        assert_eq!(
            grazing_wave(&sys, at(cp * 1.03)).map(|g| g.0),
            Some("compressional")
        );
        assert_eq!(
            grazing_wave(&sys, at(cs * 0.97)).map(|g| g.0),
            Some("shear")
        );
        assert_eq!(grazing_wave(&sys, at(cp * 1.2)), None);
    }

    /// The root a Jacobian step away, one Newton step from the root at the centre: within the
    /// reference tolerance of the root the reference path finds there, for a soil changed by
    /// 1e-6 (relative) at each measured frequency of a thin MDPE pipe; a soil changed by 10 %
    /// moves the roots too far for one step, and the caller solves afresh.
    #[test]
    fn one_newton_step_refines_a_neighbour_root_and_refuses_a_far_one() {
        let pipe = Pipe::from_outside_diameter(Material::Mdpe.typical(), 0.090, 0.0082).unwrap();
        let system = |e: f64| {
            let soil = Soil::new(e, 0.32, 2127.0, 0.0).unwrap();
            System::new(
                Fluid::water(),
                pipe,
                soil,
                0.4,
                Model::Full,
                ContactMode::Reciprocal,
            )
            .unwrap()
        };
        let w: Vec<f64> = [212.0, 358.0, 492.0, 584.0]
            .iter()
            .map(|f| f * std::f64::consts::TAU)
            .collect();
        let roots = |sys: &System| -> Vec<Complex64> {
            solve_curve(sys, &w, Continuation::default())
                .into_iter()
                .map(|r| r.expect("a root").k1)
                .collect()
        };
        let e0 = 5.0e7;
        let centre = roots(&system(e0));
        let near = system(e0 * (1.0 + 1e-6));
        let exact = roots(&near);
        for ((&omega, &k0), &k) in w.iter().zip(&centre).zip(&exact) {
            // The soil moves the roots by about 5e-8 (relative), and one step lands within 1e-13
            // of the reference path's root (the error measured is 1e-15).
            assert!((k - k0).norm() > 1e-8 * k.norm(), "{k} {k0}");
            let r = refine_near(&near, omega, k0).expect("one step suffices");
            assert!((r.k1 - k).norm() < 1e-13 * k.norm(), "{} against {k}", r.k1);
            assert_eq!(r.iterations, 1);
        }
        let far = system(e0 * 1.1);
        assert!(w
            .iter()
            .zip(&centre)
            .all(|(&omega, &k0)| refine_near(&far, omega, k0).is_none()));
    }
}
