//! The inversion problem of one segment: the measurements, the parameter space and the
//! objective (model §7.1–7.2 for the paper's method; chi-square for the default).

use std::cell::{Cell, RefCell};

use num_complex::Complex64;

use crate::optimize::{Bounds, LeastSquares, Objective, OptimizeError};
use crate::physics::effects::Effect;
use crate::physics::inputs::{
    ValidRange, ATTENUATION_RANGE, K_RE_RANGE, MAX_SOIL_POISSON, MEASUREMENT_STD_RANGE, OMEGA_RANGE,
};
use crate::physics::solver::{refine_near, solve_curve, Continuation, Tolerance};
use crate::physics::{ContactMode, Fluid, InputError, Material, Model, Pipe, Soil, System};

/// One measured wavenumber (P5: k = k_re − i·att).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Angular frequency ω, rad/s.
    pub omega: f64,
    /// Re k, rad/m (> 0).
    pub k_re: f64,
    /// Attenuation −Im k, Np/m (≥ 0).
    pub attenuation: f64,
    /// One standard deviation of `k_re`, rad/m.
    pub k_re_std: Option<f64>,
    /// One standard deviation of `attenuation`, Np/m.
    pub attenuation_std: Option<f64>,
}

impl Measurement {
    /// A checked measurement.
    pub fn new(
        omega: f64,
        k_re: f64,
        attenuation: f64,
        k_re_std: Option<f64>,
        attenuation_std: Option<f64>,
    ) -> Result<Self, InputError> {
        OMEGA_RANGE.check(omega)?;
        K_RE_RANGE.check(k_re)?;
        ATTENUATION_RANGE.check(attenuation)?;
        for (name, s) in [("k_re_std", k_re_std), ("attenuation_std", attenuation_std)] {
            if let Some(v) = s {
                ValidRange {
                    name,
                    ..MEASUREMENT_STD_RANGE
                }
                .check(v)?;
            }
        }
        Ok(Self {
            omega,
            k_re,
            attenuation,
            k_re_std,
            attenuation_std,
        })
    }

    /// Phase speed ω/k_re, m/s.
    pub fn phase_speed(&self) -> f64 {
        self.omega / self.k_re
    }
}

/// Everything known about a segment before the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentData {
    /// The water (with the inventory's overrides).
    pub fluid: Fluid,
    /// The pipe wall (nominal thickness, material values or overrides).
    pub pipe: Pipe,
    /// Soil density ρ_m from a soil test, kg/m³ (fixed, never fitted: model §7.5).
    pub soil_density: f64,
    /// The material, when known (used to judge whether measured speeds are plausible).
    pub material: Option<Material>,
    /// The field measurements.
    pub measurements: Vec<Measurement>,
}

/// Two frequencies of two campaigns are one when they differ by less than this relative amount
/// (import's tolerance, docs/interface.md).
pub const SAME_FREQUENCY_RTOL: f64 = 1e-9;

/// Both campaigns as one set of measurements (P96): at a frequency both measured, the
/// inverse-variance mean of the two, with the error of the mean; elsewhere each campaign's own.
/// Under one state the χ² of both campaigns is the pooled χ² plus `consistency_chi2`, the
/// misfit between the campaigns at their shared frequencies, which no state changes.
#[derive(Debug, Clone, PartialEq)]
pub struct Pooled {
    /// The pooled measurements (the later campaign's pipe and water).
    pub data: SegmentData,
    /// Σ over shared frequencies of (k_A − k_B)²/(σ_A² + σ_B²), both parts.
    pub consistency_chi2: f64,
    /// Frequencies both campaigns measured.
    pub shared: usize,
}

/// Pool two campaigns (P96); `None` unless every measurement of both has its standard
/// deviations.
pub fn pool(earlier: &SegmentData, later: &SegmentData) -> Option<Pooled> {
    let stds = |m: &Measurement| Some((m.k_re_std?, m.attenuation_std?));
    if earlier
        .measurements
        .iter()
        .chain(&later.measurements)
        .any(|m| stds(m).is_none())
    {
        return None;
    }
    let mut out: Vec<Measurement> = Vec::new();
    let (mut consistency, mut shared) = (0.0, 0usize);
    let mut used = vec![false; earlier.measurements.len()];
    for b in &later.measurements {
        let same = earlier.measurements.iter().enumerate().find(|(i, a)| {
            !used[*i] && (a.omega - b.omega).abs() <= SAME_FREQUENCY_RTOL * b.omega.abs()
        });
        let Some((i, a)) = same else {
            out.push(*b);
            continue;
        };
        used[i] = true;
        shared += 1;
        let (sa, ta) = stds(a)?;
        let (sb, tb) = stds(b)?;
        // Two independent measurements x_A ± σ_A, x_B ± σ_B of one value m: Σ (x − m)²/σ² =
        // (x̄ − m)²/σ̄² + (x_A − x_B)²/(σ_A² + σ_B²), x̄ the inverse-variance mean, σ̄⁻² = σ_A⁻² + σ_B⁻².
        let mean = |xa: f64, sa: f64, xb: f64, sb: f64| {
            let (wa, wb) = (1.0 / (sa * sa), 1.0 / (sb * sb));
            ((wa * xa + wb * xb) / (wa + wb), (wa + wb).recip().sqrt())
        };
        let (k, sk) = mean(a.k_re, sa, b.k_re, sb);
        let (t, st) = mean(a.attenuation, ta, b.attenuation, tb);
        consistency += (a.k_re - b.k_re).powi(2) / (sa * sa + sb * sb)
            + (a.attenuation - b.attenuation).powi(2) / (ta * ta + tb * tb);
        out.push(Measurement {
            omega: b.omega,
            k_re: k,
            attenuation: t,
            k_re_std: Some(sk),
            attenuation_std: Some(st),
        });
    }
    out.extend(
        earlier
            .measurements
            .iter()
            .zip(&used)
            .filter(|(_, u)| !**u)
            .map(|(a, _)| *a),
    );
    out.sort_by(|a, b| a.omega.total_cmp(&b.omega));
    Some(Pooled {
        data: SegmentData {
            measurements: out,
            ..later.clone()
        },
        consistency_chi2: consistency,
        shared,
    })
}

/// The inversion method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Method {
    /// Chi-square (or relative least squares) over (log10 E_m, ν_m, ξ, effects), SHADE with a
    /// Levenberg–Marquardt polish, restarts for a multiple-minima check.
    #[default]
    Default,
    /// The paper's algorithm exactly (model §7.1–7.3).
    Paper,
}

impl Method {
    /// Name used in the database and the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            Method::Default => "default",
            Method::Paper => "paper",
        }
    }
}

impl std::str::FromStr for Method {
    type Err = InputError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "default" => Ok(Method::Default),
            "paper" => Ok(Method::Paper),
            _ => Err(InputError::Unknown {
                what: "method",
                value: s.to_string(),
                expected: "default, paper",
            }),
        }
    }
}

/// Paper weights of the objective (P53).
pub const PAPER_W_RE: f64 = 1.0;
/// Paper weight of the attenuation term (P53).
pub const PAPER_W_IM: f64 = 5.0;
/// Objective value of a failed forward solve in the paper's objective (the reference's 1e3,
/// model §5.6).
pub const FAILED_SOLVE_OBJECTIVE: f64 = 1e3;
/// Paper bounds on E_m, Pa (P51).
pub const E_BOUNDS: (f64, f64) = (1e3, 1e10);
/// Relative deviation from the in-vacuo root above which the fast evaluation (no ramp) is not
/// trusted at the lowest frequency and the continuation ramp is used instead.
pub const DIRECT_START_MAX_DEVIATION: f64 = 0.1;
/// Ramp used when the direct start is not trusted (the reference inversion's 8 points).
pub const INVERSION_RAMP_POINTS: usize = 8;

/// How a coordinate of the search space maps to the physical parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scale {
    /// The coordinate is the parameter.
    Linear,
    /// The coordinate is log10 of the parameter.
    Log10,
}

/// What a coordinate of the search space is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Param {
    /// Soil Young's modulus E_m, Pa.
    SoilModulus,
    /// Soil Poisson's ratio ν_m.
    SoilPoisson,
    /// Contact coefficient ξ.
    Contact,
    /// An effect's parameter.
    Effect(Effect),
}

impl Param {
    /// Column name in `fits`.
    pub fn name(self) -> &'static str {
        match self {
            Param::SoilModulus => "soil_youngs_modulus_pa",
            Param::SoilPoisson => "soil_poisson",
            Param::Contact => "contact",
            Param::Effect(e) => e.parameter().map(|p| p.name).unwrap_or("none"),
        }
    }
}

/// One coordinate of the search space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamSpec {
    /// What it is.
    pub param: Param,
    /// How the coordinate maps to the parameter.
    pub scale: Scale,
    /// Lower bound of the coordinate.
    pub lower: f64,
    /// Upper bound of the coordinate.
    pub upper: f64,
}

impl ParamSpec {
    /// Physical value of coordinate `x`.
    pub fn value(&self, x: f64) -> f64 {
        match self.scale {
            Scale::Linear => x,
            Scale::Log10 => 10f64.powf(x),
        }
    }
    /// One-sigma error of the physical value from that of the coordinate (first order).
    pub fn value_std(&self, x: f64, sx: f64) -> f64 {
        match self.scale {
            Scale::Linear => sx,
            Scale::Log10 => 10f64.powf(x) * std::f64::consts::LN_10 * sx,
        }
    }
    /// Coordinate of a physical value.
    pub fn coordinate(&self, v: f64) -> f64 {
        match self.scale {
            Scale::Linear => v,
            Scale::Log10 => v.log10(),
        }
    }
}

/// Lower bound of log10 of the air fraction: φ = 1e-7 softens water by 0.06 %, i.e. no air.
pub const AIR_LOG10_MIN: f64 = -7.0;

/// The search space for a method and a set of effects.
pub fn parameter_space(method: Method, effects: &[Effect]) -> Vec<ParamSpec> {
    let mut v = Vec::new();
    match method {
        Method::Paper => {
            // P51: E linear; ν ≤ 0.499 (the reference's choice: 0.5 is singular).
            v.push(ParamSpec {
                param: Param::SoilModulus,
                scale: Scale::Linear,
                lower: E_BOUNDS.0,
                upper: E_BOUNDS.1,
            });
        }
        Method::Default => v.push(ParamSpec {
            param: Param::SoilModulus,
            scale: Scale::Log10,
            lower: E_BOUNDS.0.log10(),
            upper: E_BOUNDS.1.log10(),
        }),
    }
    v.push(ParamSpec {
        param: Param::SoilPoisson,
        scale: Scale::Linear,
        lower: 0.0,
        upper: MAX_SOIL_POISSON,
    });
    v.push(ParamSpec {
        param: Param::Contact,
        scale: Scale::Linear,
        lower: 0.0,
        upper: 1.0,
    });
    for &e in effects {
        if let Some(p) = e.parameter() {
            let spec = if e == Effect::AirInWater {
                ParamSpec {
                    param: Param::Effect(e),
                    scale: Scale::Log10,
                    lower: AIR_LOG10_MIN,
                    upper: p.upper.log10(),
                }
            } else {
                ParamSpec {
                    param: Param::Effect(e),
                    scale: Scale::Linear,
                    lower: p.lower,
                    upper: p.upper,
                }
            };
            v.push(spec);
        }
    }
    v
}

/// Which misfit the default method minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Weighting {
    /// Residuals divided by the measurement standard deviations: chi-square.
    ChiSquare,
    /// No standard deviations: relative residuals with the paper's weights, w_re = 1 on
    /// (model − measured)/measured for Re k and w_im = 5 for the attenuation (P52–P53),
    /// squared and summed.
    Relative,
}

/// The inversion of one segment as an optimisation problem. Counts its evaluations.
pub struct Problem<'a> {
    /// The segment.
    pub data: &'a SegmentData,
    /// Model variant.
    pub model: Model,
    /// Contact reading.
    pub contact_mode: ContactMode,
    /// Effects switched on (their parameters are coordinates; `full_model` switches the model).
    pub effects: Vec<Effect>,
    /// The search space.
    pub specs: Vec<ParamSpec>,
    /// The method (its objective).
    pub method: Method,
    /// The default method's weighting.
    pub weighting: Weighting,
    /// How the forward model is solved during the search.
    pub path: SolvePath,
    omegas: Vec<f64>,
    evaluations: Cell<usize>,
    /// The last point [`Problem::predict`] solved on the fast path and its wavenumbers: the
    /// start of the roots a finite-difference step away ([`LeastSquares::residuals_near`]).
    last: RefCell<Option<(Vec<f64>, Vec<Complex64>)>>,
}

/// How the inversion solves the forward model at each candidate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolvePath {
    /// Every frequency by continuation from the lowest one, solved directly from its in-vacuo
    /// root (no ramp); an 8-point ramp only if that fails at the lowest frequency
    /// ([`predict_fast`]); Muller, Newton's fallback, capped at
    /// [`MULLER_FALLBACK_MAX_ITER`](crate::physics::solver::MULLER_FALLBACK_MAX_ITER) iterations.
    /// Fast; may track another root for thin plastic pipes in stiff soil, so the fit checks
    /// its optimum by the reference path.
    Fast,
    /// As `Fast`, but the ramp is also used whenever the lowest root is more than 10 % from
    /// its in-vacuo value ([`predict`]).
    Safe,
    /// The reference path (29-point ramp, reference tolerance, restarts past grazing), on
    /// which answers are reported; the slowest. Used where the search paths cannot solve
    /// next to an optimum the reference path has accepted (a root at grazing).
    Reference,
}

impl<'a> Problem<'a> {
    /// Set up the problem.
    pub fn new(
        data: &'a SegmentData,
        method: Method,
        model: Model,
        contact_mode: ContactMode,
        effects: &[Effect],
    ) -> Self {
        let weighting = if data
            .measurements
            .iter()
            .all(|m| m.k_re_std.is_some() && m.attenuation_std.is_some())
        {
            Weighting::ChiSquare
        } else {
            Weighting::Relative
        };
        Self {
            data,
            model: if effects.contains(&Effect::FullModel) {
                Model::Full
            } else {
                model
            },
            contact_mode,
            effects: effects.to_vec(),
            specs: parameter_space(method, effects),
            method,
            weighting,
            path: SolvePath::Fast,
            omegas: data.measurements.iter().map(|m| m.omega).collect(),
            evaluations: Cell::new(0),
            last: RefCell::new(None),
        }
    }

    /// The same problem solved on another path (evaluations counted afresh).
    pub fn on_path(&self, path: SolvePath) -> Problem<'a> {
        Problem {
            data: self.data,
            model: self.model,
            contact_mode: self.contact_mode,
            effects: self.effects.clone(),
            specs: self.specs.clone(),
            method: self.method,
            weighting: self.weighting,
            path,
            omegas: self.omegas.clone(),
            evaluations: Cell::new(0),
            last: RefCell::new(None),
        }
    }

    /// Count `n` evaluations made on this problem's behalf (by [`Problem::on_path`]'s copy).
    pub fn add_evaluations(&self, n: usize) {
        self.evaluations.set(self.evaluations.get() + n);
    }

    /// Forward-model evaluations so far.
    pub fn evaluations(&self) -> usize {
        self.evaluations.get()
    }

    /// The search box.
    pub fn bounds(&self) -> Result<Bounds, OptimizeError> {
        Bounds::new(
            self.specs.iter().map(|s| s.lower).collect(),
            self.specs.iter().map(|s| s.upper).collect(),
        )
    }

    /// Physical value of every coordinate of x.
    pub fn values(&self, x: &[f64]) -> Vec<f64> {
        self.specs.iter().zip(x).map(|(s, &v)| s.value(v)).collect()
    }

    /// The system at search point x, or `None` if x gives a non-physical input.
    pub fn system_at(&self, x: &[f64]) -> Option<System> {
        let d = self.data;
        let (mut e, mut nu, mut xi) = (0.0, 0.0, 0.0);
        let mut extra = Vec::new();
        for (s, &v) in self.specs.iter().zip(x) {
            let val = s.value(v);
            match s.param {
                Param::SoilModulus => e = val,
                Param::SoilPoisson => nu = val,
                Param::Contact => xi = val,
                Param::Effect(eff) => extra.push((eff, val)),
            }
        }
        let soil = Soil::new_unbounded(e, nu.min(MAX_SOIL_POISSON), d.soil_density, 0.0).ok()?;
        let mut sys = System::new(
            d.fluid,
            d.pipe,
            soil,
            xi.clamp(0.0, 1.0),
            self.model,
            self.contact_mode,
        )
        .ok()?;
        for (eff, val) in extra {
            let val = match eff {
                Effect::AirInWater if val <= 10f64.powf(AIR_LOG10_MIN) => 0.0,
                _ => val,
            };
            sys = eff.apply(&sys, val).ok()?;
        }
        Some(sys)
    }

    /// Model wavenumbers at the measured frequencies for system `sys`, or `None` when a root
    /// is not found (or is a growing wave under `reciprocal`/`blend`).
    pub fn predict_system(&self, sys: &System) -> Option<Vec<Complex64>> {
        match self.path {
            SolvePath::Fast => predict_fast(sys, &self.omegas),
            SolvePath::Safe => predict(sys, &self.omegas),
            SolvePath::Reference => self
                .reference_roots(sys)
                .map(|r| r.iter().map(|x| x.k1).collect()),
        }
    }

    /// The roots at the measured frequencies by the reference path (29-point ramp, reference
    /// tolerance, model §5.3–5.4), for checking and reporting the search's answer; `None` when
    /// one is not found or is a growing wave under `reciprocal`/`blend`.
    pub fn reference_roots(&self, sys: &System) -> Option<Vec<crate::physics::Root>> {
        let res = solve_curve(sys, &self.omegas, Continuation::default());
        accept_roots(sys, &res)?;
        res.into_iter().collect::<Result<Vec<_>, _>>().ok()
    }

    /// Why the reference path finds no acceptable root for `sys` (the first solver error, or a
    /// growing wave), or `None` when it does.
    pub fn reference_failure(&self, sys: &System) -> Option<String> {
        let res = solve_curve(sys, &self.omegas, Continuation::default());
        if let Some(e) = res.iter().find_map(|r| r.as_ref().err()) {
            return Some(e.to_string());
        }
        let growing = res
            .iter()
            .filter_map(|r| r.as_ref().ok())
            .find(|r| r.flags.growing_wave && sys.contact_mode != ContactMode::Printed);
        growing.map(|r| {
            format!(
                "a growing wave at {:.0} Hz (k1 = {:.4})",
                r.omega / std::f64::consts::TAU,
                r.k1
            )
        })
    }

    /// The method's objective for model wavenumbers `k` at the measured frequencies: the
    /// paper's f (P52–P53) or the default method's sum of squared weighted residuals.
    pub fn objective_of(&self, k: &[Complex64]) -> f64 {
        match self.method {
            Method::Paper => self.paper_objective(k),
            Method::Default => self.sum_of_squares(k),
        }
    }

    /// Model wavenumbers at the measured frequencies at search point x. Counts one evaluation,
    /// except at the last point solved on the fast path, whose wavenumbers it returns again:
    /// the probes take a scan's or a polish's answer, often the point LM solved last (on a
    /// realistic network, about 16 such repeats a fit).
    pub fn predict(&self, x: &[f64]) -> Option<Vec<Complex64>> {
        if self.path == SolvePath::Fast {
            if let Some((_, lk)) = self.last.borrow().as_ref().filter(|(lx, _)| lx == x) {
                return Some(lk.clone());
            }
        }
        let k = self.predict_unremembered(x)?;
        if self.path == SolvePath::Fast {
            let mut last = self.last.borrow_mut();
            let (lx, lk) = last.get_or_insert_with(Default::default);
            lx.clear();
            lx.extend_from_slice(x);
            lk.clear();
            lk.extend_from_slice(&k);
        }
        Some(k)
    }

    /// [`Problem::predict`] without remembering the point for [`Problem::predict_near`].
    fn predict_unremembered(&self, x: &[f64]) -> Option<Vec<Complex64>> {
        self.evaluations.set(self.evaluations.get() + 1);
        self.predict_system(&self.system_at(x)?)
    }

    /// The wavenumbers at `x`, a finite-difference step from `base`, when `base` is the last
    /// point predicted on the fast path: each root one Newton step from the root there
    /// ([`refine_near`]). `None` when `base` is another point or a root's step is not short
    /// (the caller predicts on its path). Counts an evaluation when it answers.
    fn predict_near(&self, base: &[f64], x: &[f64]) -> Option<Vec<Complex64>> {
        let last = self.last.borrow();
        let (lx, lk) = last.as_ref().filter(|(lx, _)| lx.as_slice() == base)?;
        debug_assert_eq!(lx.len(), x.len());
        let sys = self.system_at(x)?;
        let mut k = Vec::with_capacity(lk.len());
        for (&w, &g) in self.omegas.iter().zip(lk) {
            let root = refine_near(&sys, w, g).filter(|r| acceptable(&sys, r))?;
            k.push(root.k1);
        }
        self.evaluations.set(self.evaluations.get() + 1);
        Some(k)
    }

    /// Number of residuals (two per measurement).
    pub fn n_residuals(&self) -> usize {
        2 * self.data.measurements.len()
    }

    /// Weighted residuals of a prediction: (model − measured)/σ for Re k, then for the
    /// attenuation, per measurement.
    pub fn residuals_of(&self, k: &[Complex64], out: &mut [f64]) {
        for (i, (m, k)) in self.data.measurements.iter().zip(k).enumerate() {
            let (d_re, d_att) = (k.re - m.k_re, -k.im - m.attenuation);
            let (s_re, s_att) = match self.weighting {
                Weighting::ChiSquare => (
                    m.k_re_std.unwrap_or(f64::NAN),
                    m.attenuation_std.unwrap_or(f64::NAN),
                ),
                Weighting::Relative => (m.k_re / PAPER_W_RE, m.attenuation.max(1e-12) / PAPER_W_IM),
            };
            out[2 * i] = d_re / s_re;
            out[2 * i + 1] = d_att / s_att;
        }
    }

    /// The paper's objective f of P52–P53 for a prediction.
    pub fn paper_objective(&self, k: &[Complex64]) -> f64 {
        let m = self.data.measurements.len() as f64;
        let (mut f_re, mut f_im) = (0.0, 0.0);
        for (meas, k) in self.data.measurements.iter().zip(k) {
            f_re += (meas.k_re - k.re).abs() / meas.k_re;
            f_im += (meas.attenuation - (-k.im)).abs() / meas.attenuation.max(1e-12);
        }
        ((PAPER_W_RE * f_re / m).powi(2) + (PAPER_W_IM * f_im / m).powi(2)).sqrt()
    }

    /// Sum of squared weighted residuals for a prediction.
    pub fn sum_of_squares(&self, k: &[Complex64]) -> f64 {
        let mut r = vec![0.0; self.n_residuals()];
        self.residuals_of(k, &mut r);
        r.iter().map(|v| v * v).sum()
    }
}

/// The roots as wavenumbers, or `None` if one failed or is a growing wave under `reciprocal` or
/// `blend` (a bug or a branch jump there, model §5.6).
fn accept_roots(
    sys: &System,
    res: &[Result<crate::physics::Root, crate::physics::SolveError>],
) -> Option<Vec<Complex64>> {
    res.iter()
        .map(|r| r.as_ref().ok().filter(|r| acceptable(sys, r)).map(|r| r.k1))
        .collect()
}

/// Whether a root is an answer: not a growing wave, unless the contact is read as printed
/// (model §5.6).
fn acceptable(sys: &System, root: &crate::physics::Root) -> bool {
    !root.flags.growing_wave || sys.contact_mode == ContactMode::Printed
}

/// [`SolvePath::Fast`]: no ramp, fast tolerance; the 8-point ramp only if that failed at the
/// lowest frequency.
///
/// The ramp changes only the path up to the lowest frequency: where the direct start there
/// took another root, it can help; where the lowest frequency was solved and a higher one
/// failed, the ramp arrives at the same root and the continuation above fails again. On four
/// realistic networks the ramp ran 584 times: it answered 12 times, each after a failure at the
/// lowest frequency, and never in the 572 runs after a failure higher up, which each cost about
/// 1 ms (9 % of a plastic-heavy network's fitting time).
pub fn predict_fast(sys: &System, omegas: &[f64]) -> Option<Vec<Complex64>> {
    predict_fast_to(sys, omegas, Tolerance::FAST)
}

/// [`predict_fast`] to another tolerance.
fn predict_fast_to(sys: &System, omegas: &[f64], tolerance: Tolerance) -> Option<Vec<Complex64>> {
    let fast = Continuation {
        ramp_points: 0,
        tolerance,
    };
    let res = solve_curve(sys, omegas, fast);
    if let Some(k) = accept_roots(sys, &res) {
        return Some(k);
    }
    let lowest = (0..omegas.len()).min_by(|&a, &b| omegas[a].total_cmp(&omegas[b]))?;
    if accept_roots(sys, &res[lowest..=lowest]).is_some() {
        return None;
    }
    let ramp = Continuation {
        ramp_points: INVERSION_RAMP_POINTS,
        tolerance,
    };
    accept_roots(sys, &solve_curve(sys, omegas, ramp))
}

/// Wavenumbers of `sys` at `omegas` with the inversion's solver settings: the lowest frequency
/// straight from its in-vacuo root when the root stays within 10 % of it, otherwise (or if any
/// solve fails) an 8-point continuation ramp (model §5.4 allows a shorter ramp for the inversion).
pub fn predict(sys: &System, omegas: &[f64]) -> Option<Vec<Complex64>> {
    // Muller rather than Newton on this path: it is the fallback when the fast path tracked
    // another root, and Muller's start from three points is the validated iteration of model §5.3.
    let tolerance = Tolerance {
        method: crate::physics::solver::RootMethod::Muller,
        ..Tolerance::FAST
    };
    let fast = Continuation {
        ramp_points: 0,
        tolerance,
    };
    let accept =
        |res: &[Result<crate::physics::Root, crate::physics::SolveError>]| accept_roots(sys, res);
    let res = solve_curve(sys, omegas, fast);
    let w_min = omegas.iter().copied().fold(f64::INFINITY, f64::min);
    let trusted = res
        .iter()
        .zip(omegas)
        .find(|(_, &w)| w == w_min)
        .and_then(|(r, _)| r.as_ref().ok())
        .map(|r| {
            let kv = crate::physics::dispersion::in_vacuo_root(sys, w_min);
            (r.k1 - kv).norm() <= DIRECT_START_MAX_DEVIATION * kv.norm()
        })
        .unwrap_or(false);
    if trusted {
        if let Some(k) = accept(&res) {
            return Some(k);
        }
    }
    let ramp = Continuation {
        ramp_points: INVERSION_RAMP_POINTS,
        tolerance,
    };
    accept(&solve_curve(sys, omegas, ramp))
}

impl Objective for Problem<'_> {
    fn dim(&self) -> usize {
        self.specs.len()
    }

    fn value(&self, x: &[f64]) -> f64 {
        self.value_of(self.predict(x))
    }

    /// On the fast path, the misfit with roots to [`Tolerance::SEARCH`] (not remembered as the
    /// centre of a Jacobian's steps); otherwise [`Objective::value`]. Counts one evaluation.
    fn search_value(&self, x: &[f64]) -> f64 {
        if self.path != SolvePath::Fast {
            return self.value(x);
        }
        self.evaluations.set(self.evaluations.get() + 1);
        self.value_of(
            self.system_at(x)
                .and_then(|sys| predict_fast_to(&sys, &self.omegas, Tolerance::SEARCH)),
        )
    }
}

impl LeastSquares for Problem<'_> {
    fn n_params(&self) -> usize {
        self.specs.len()
    }
    fn n_residuals(&self) -> usize {
        Problem::n_residuals(self)
    }
    fn residuals(&self, x: &[f64], out: &mut [f64]) -> bool {
        self.residuals_into(self.predict(x), out)
    }

    /// Whether `base` is the last point predicted on the fast path. Only then: a problem
    /// made afresh (the diagnosis's score tests take a Jacobian of one at a fit's optimum,
    /// against residuals of their own) differences against the residuals it is given, as
    /// before; recomputing them there on the fast path moved the score statistics of
    /// `tests/diagnose_groups.rs` by 3–6 and raised a false alarm.
    fn near_at(&self, base: &[f64]) -> bool {
        self.last
            .borrow()
            .as_ref()
            .is_some_and(|(lx, _)| lx.as_slice() == base)
    }

    /// The roots one Newton step from those at `base` when `base` is the last point predicted
    /// on the fast path (`Problem::predict_near`), else [`Self::residuals`]. The point is
    /// not remembered, so every step of a Jacobian starts from its centre.
    fn residuals_near(&self, base: &[f64], x: &[f64], out: &mut [f64]) -> bool {
        let k = self
            .predict_near(base, x)
            .or_else(|| self.predict_unremembered(x));
        self.residuals_into(k, out)
    }
}

impl Problem<'_> {
    /// The objective of a prediction; where there is none, the method's value for a failed
    /// solve.
    fn value_of(&self, k: Option<Vec<Complex64>>) -> f64 {
        match (k, self.method) {
            (Some(k), _) => self.objective_of(&k),
            (None, Method::Paper) => FAILED_SOLVE_OBJECTIVE,
            (None, Method::Default) => f64::INFINITY,
        }
    }

    /// The residuals of a prediction into `out`; false when there is none or one is not finite.
    fn residuals_into(&self, k: Option<Vec<Complex64>>, out: &mut [f64]) -> bool {
        k.is_some_and(|k| {
            self.residuals_of(&k, out);
            out.iter().all(|v| v.is_finite())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::invert::FitSettings;
    use crate::synth::bench::{bench_network, MaterialMix};

    /// A search value (the DE's, roots to [`Tolerance::SEARCH`]) is the value to far below
    /// the DE's spread test (1e-2 in χ², 1e-3 relative): on 40 segments of each material mix
    /// at 25 points each, drawn uniformly in the search box, within 1e-5 of it relative
    /// (measured at 10,000 points: at most 4.9e-6, 9.7e-3 on a χ² of 2,000), and another
    /// number at most points (each root one Newton step short of machine precision). Where one
    /// is finite the other is, at all but a few points (3 in 10,000 measured).
    #[test]
    fn a_search_value_is_the_value_to_a_lower_precision() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let (mut both, mut differ, mut one) = (0, 0, 0);
        for mix in [MaterialMix::Default, MaterialMix::PlasticHeavy] {
            for seg in bench_network(40, 848899, mix) {
                let s = FitSettings::default();
                let p = Problem::new(&seg.data, s.method, s.model, s.contact_mode, &s.effects);
                let bounds = p.bounds().expect("bounds");
                for _ in 0..25 {
                    let x: Vec<f64> = (0..bounds.dim())
                        .map(|j| rng.gen_range(bounds.lower()[j]..=bounds.upper()[j]))
                        .collect();
                    let (v, sv) = (p.value(&x), p.search_value(&x));
                    match (v.is_finite(), sv.is_finite()) {
                        (true, true) => {
                            both += 1;
                            let rel = (v - sv).abs() / v.max(1.0);
                            assert!(rel <= 1e-5, "{}: {v} against {sv} at {x:?}", seg.id);
                            differ += usize::from(v != sv);
                        }
                        (false, false) => {}
                        _ => one += 1,
                    }
                }
            }
        }
        assert!(both >= 1900, "{both} finite pairs");
        assert!(differ * 2 > both, "{differ} of {both} differ");
        assert!(one <= 10, "{one} points finite by one only");
    }

    /// The fast path answers a repeat of its last point from memory, without solving or
    /// counting an evaluation; any other point, or a point solved before the last, is solved.
    #[test]
    fn the_last_point_is_answered_again_without_a_solve() {
        let net = bench_network(10, 848911, MaterialMix::Default);
        let s = FitSettings::default();
        let p = Problem::new(&net[0].data, s.method, s.model, s.contact_mode, &s.effects);
        let bounds = p.bounds().expect("bounds");
        let at = |t: f64| -> Vec<f64> {
            (0..bounds.dim())
                .map(|q| bounds.lower()[q] + t * bounds.width(q))
                .collect()
        };
        let (x, y) = (at(0.4), at(0.6));
        let kx = p.predict(&x).expect("roots at x");
        assert_eq!(p.evaluations(), 1);
        assert_eq!(p.predict(&x).expect("again"), kx);
        assert_eq!(p.evaluations(), 1);
        let ky = p.predict(&y).expect("roots at y");
        assert_ne!(ky, kx);
        assert_eq!(p.predict(&x).expect("x after y"), kx);
        assert_eq!(p.evaluations(), 3);
        let mut safe = Problem::new(&net[0].data, s.method, s.model, s.contact_mode, &s.effects);
        safe.path = SolvePath::Safe;
        let _ = safe.predict(&x);
        let _ = safe.predict(&x);
        assert_eq!(safe.evaluations(), 2);
    }

    /// The fast path keeps its ramp for what the ramp is for: on a bench-network pipe, at a
    /// point a polish evaluated, the direct start at the lowest frequency (421 rad/s) finds no
    /// root and the 8-point ramp answers, with decaying waves. (The ramp runs only after such a
    /// failure.)
    #[test]
    fn the_ramp_answers_where_the_lowest_frequency_fails() {
        let net = bench_network(200, 848701, MaterialMix::Default);
        let seg = net
            .iter()
            .find(|s| s.id == "WM10145")
            .expect("in the network");
        let s = FitSettings::default();
        let problem = Problem::new(&seg.data, Method::Default, s.model, s.contact_mode, &[]);
        let x = [8.454412826549524, 0.34785634812278293, 0.19030904466416065];
        let sys = problem.system_at(&x).expect("a system");
        let omegas = &problem.omegas;
        let direct = solve_curve(
            &sys,
            omegas,
            Continuation {
                ramp_points: 0,
                tolerance: Tolerance::FAST,
            },
        );
        let lowest = (0..omegas.len())
            .min_by(|&a, &b| omegas[a].total_cmp(&omegas[b]))
            .expect("measurements");
        assert!(accept_roots(&sys, &direct[lowest..=lowest]).is_none());
        let fast = predict_fast(&sys, omegas).expect("the ramp answers");
        // The point lies at grazing: the ramp's root at the lowest frequency travels at the
        // soil's c_P (488.4 m/s), where the reference path reports no root (P44).
        let (c_p, _) = sys.soil.wave_speeds();
        let c = omegas[lowest] / fast[lowest].re;
        assert!((c / c_p - 1.0).abs() < 0.01, "{c} against c_P {c_p}");
        assert!(fast.iter().all(|k| k.im < 0.0 && k.re > 0.0));
        assert!(problem.reference_roots(&sys).is_none());
    }

    /// The Jacobian of a fit's polish with each step's roots one Newton step from the centre's
    /// ([`LeastSquares::residuals_near`]) agrees with central differences of the full fast
    /// path over a 100 times longer step (accurate to about 1e-6 there) to 1e-5 of each
    /// column, on every segment of a plastic-heavy bench network (measured: 1.3e-6 to 2.2e-6;
    /// differenced against the path's own centre instead of the refined one, 3e-3 to 4e-2 on
    /// 10 of the 12), and it is not the path's Jacobian; with the centre not the last point
    /// predicted, it is the full path's, bit for bit.
    #[test]
    fn a_jacobian_from_the_centre_roots_is_the_full_paths() {
        use crate::optimize::{jacobian_fd, FiniteDifference};
        /// The problem without its near residuals.
        struct Full<'p>(&'p Problem<'p>);
        impl LeastSquares for Full<'_> {
            fn n_params(&self) -> usize {
                self.0.n_params()
            }
            fn n_residuals(&self) -> usize {
                LeastSquares::n_residuals(self.0)
            }
            fn residuals(&self, x: &[f64], out: &mut [f64]) -> bool {
                self.0.residuals(x, out)
            }
        }
        let s = FitSettings::default();
        let (mut compared, mut refined) = (0, 0);
        for seg in bench_network(12, 848812, MaterialMix::PlasticHeavy) {
            let problem = Problem::new(&seg.data, Method::Default, s.model, s.contact_mode, &[]);
            let bounds = problem.bounds().expect("a box");
            let x: Vec<f64> = (0..bounds.dim())
                .map(|q| bounds.lower()[q] + 0.37 * bounds.width(q))
                .collect();
            let (n, m) = (x.len(), LeastSquares::n_residuals(&problem));
            let mut r0 = vec![0.0; m];
            if !problem.residuals(&x, &mut r0) {
                continue;
            }
            let jacobian = |p: &dyn LeastSquares, fd: FiniteDifference, step: f64| {
                let mut j = vec![0.0; m * n];
                jacobian_fd(p, &x, &r0, Some(&bounds), fd, step, &mut j).expect("a Jacobian");
                j
            };
            let before = problem.evaluations();
            let near = jacobian(&problem, FiniteDifference::Forward, 1e-6);
            assert!(problem.evaluations() > before);
            let reference = jacobian(&Full(&problem), FiniteDifference::Central, 1e-4);
            // The steps were solved from the centre's roots, not on the path.
            if near != jacobian(&Full(&problem), FiniteDifference::Forward, 1e-6) {
                refined += 1;
            }
            let mut again = vec![0.0; m];
            assert!(problem.residuals(&x, &mut again));
            for q in 0..n {
                let norm = (0..m)
                    .map(|i| reference[i * n + q].powi(2))
                    .sum::<f64>()
                    .sqrt();
                for i in 0..m {
                    let (a, b) = (near[i * n + q], reference[i * n + q]);
                    assert!(
                        (a - b).abs() <= 1e-5 * norm,
                        "{} column {q} row {i}: {a} against {b} (norm {norm})",
                        seg.id
                    );
                }
            }
            // Another point predicted last: the Jacobian at x is the full path's.
            let mut other = vec![0.0; m];
            let y: Vec<f64> = (0..n)
                .map(|q| bounds.lower()[q] + 0.5 * bounds.width(q))
                .collect();
            problem.residuals(&y, &mut other);
            let fallback = jacobian(&problem, FiniteDifference::Forward, 1e-6);
            assert_eq!(
                fallback,
                jacobian(&Full(&problem), FiniteDifference::Forward, 1e-6)
            );
            compared += 1;
        }
        assert!(compared >= 8, "{compared}");
        assert!(refined >= compared - 1, "{refined} of {compared}");
    }
}
