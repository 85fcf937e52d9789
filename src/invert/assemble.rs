//! The result of a fit, built once from the search's optima: what the data determine at the
//! answer (model §7.10: the soil's speeds and every parameter's interval, widened along a flat
//! valley and to rival optima), the predicted curve with its errors (P65), corrected by a
//! discrepancy where the model does not explain the data (P89), and the findings (flags and
//! notes). Pure functions of what the search ([`super::fit`]) found.

use num_complex::Complex64;

use super::discrepancy::{
    extrapolation_octaves, Discrepancy, Residual, ASSUMED_RELATIVE_ATTENUATION_STD,
    ASSUMED_RELATIVE_SPEED_STD,
};
use super::fit::{nested_start, problem_for, BaseOptimum, FitSettings, Optimum};
use super::flags::{assess, Evidence, Flag, FlagCode, Separated, Severity};
use super::problem::{Method, Param, Problem, SegmentData, SolvePath, Weighting};
use super::provenance::{Provenance, SearchError};
use super::result::{CurveSource, Estimate, FitResult, PredictedPoint};
use super::uncertainty::{determine, propagate, Determined, WithError};
use crate::optimize::{FiniteDifference, LevenbergMarquardt};
use crate::physics::curves::{band_mean, curve, LEAK_BAND_HZ, STANDARD_GRID_HZ};
use crate::physics::effects::Effect;
use crate::physics::solver::{solve_from_guess_tol, Root, Tolerance};
use crate::physics::System;
use crate::types::FitStatus;
use crate::units::{db_to_np, hz_to_omega, sig};

/// Two restarts whose chi-square differs by less than this are equally good (Δχ² = 1 is a
/// one-sigma change of one parameter).
pub const EQUIVALENT_DCHI2: f64 = 1.0;
/// … for the relative objective: cost within this fraction of the best.
pub const EQUIVALENT_RELATIVE: f64 = 0.01;
/// Two optima are separated when a coordinate differs by more than this many sigma …
pub const SEPARATION_SIGMAS: f64 = 3.0;
/// … and by more than this fraction of its search range.
pub const SEPARATION_RANGE_FRACTION: f64 = 0.05;

/// Relative step (of each coordinate's search range) of the finite differences that give the
/// predicted curve's sensitivity to the fitted parameters (P65).
pub const CURVE_FD_STEP_FRACTION: f64 = 1e-3;

/// Build the result once from the search's optima.
#[allow(clippy::too_many_arguments)]
pub(super) fn assemble(
    problem: &Problem<'_>,
    settings: &FitSettings,
    bounds: &crate::optimize::Bounds,
    optima: &[Optimum],
    best_i: usize,
    sys: System,
    predicted: Vec<Complex64>,
    roots: &[Root],
) -> Result<FitResult, SearchError> {
    let started = std::time::Instant::now();
    let x = &optima[best_i].x;
    let n = problem.specs.len();
    let m = problem.n_residuals();
    let ss = problem.sum_of_squares(&predicted);
    let dof = m.saturating_sub(n);
    let chi2_per_dof = match (problem.weighting, dof) {
        (Weighting::ChiSquare, d) if d > 0 => Some(ss / d as f64),
        _ => None,
    };
    let scale = match problem.weighting {
        // Errors widened by the Birge ratio (P88) where the misfit exceeds the noise.
        Weighting::ChiSquare => crate::stats::birge_ratio(ss, m, n).powi(2),
        Weighting::Relative if dof > 0 => ss / dof as f64,
        Weighting::Relative => 1.0,
    };
    let mut determined = uncertainty(problem, bounds, x, &predicted, ss, scale);
    let (curve, mut leak_band_speed) = predicted_curve(problem, bounds, x, &sys, &determined.cov);
    widen_to_rival_optima(
        problem,
        optima,
        best_i,
        scale,
        &mut determined,
        &mut leak_band_speed,
    );
    widen_band_to_valley(problem, &determined, &mut leak_band_speed);
    let estimates: Vec<Estimate> = problem
        .specs
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let iv = determined.intervals[i];
            let sx = determined.cov[i * n + i].max(0.0).sqrt();
            // One sigma consistent with the 95 % interval: its width in the coordinate / 3.92,
            // carried to physical units at the estimate.
            let width = (s.coordinate(iv.hi) - s.coordinate(iv.lo)).abs();
            let s_coord = width / (2.0 * super::uncertainty::Z_95);
            Estimate {
                param: s.param,
                value: s.value(x[i]),
                std: Some(s.value_std(x[i], s_coord)),
                coordinate: x[i],
                coordinate_std: sx,
                interval: iv,
            }
        })
        .collect();
    let separated = separated_minima(problem, optima, best_i, &determined);
    let findings = assess(&Evidence {
        problem,
        x,
        predicted: &predicted,
        roots,
        chi2_per_dof,
        determined: &determined,
        leak_band_speed,
        separated,
    });
    // The information the soil field learns from (P79), divided by the misfit's variance
    // factor: R_B² (P88) when the measurement errors are known, so that a fit the model does
    // not explain does not teach the field overconfident soil; σ̂² of the relative residuals
    // otherwise. None when the curvature could not be evaluated.
    let variance = match problem.weighting {
        Weighting::ChiSquare => crate::stats::birge_ratio(ss, m, n).powi(2),
        Weighting::Relative => scale,
    };
    let soil_information =
        (!determined.curvature_unknown).then(|| determined.speed_information.map(|v| v / variance));
    let (mut flags, notes): (Vec<Flag>, Vec<Flag>) = findings
        .into_iter()
        .partition(|f| f.code.severity() == Severity::Flag);
    let mut curve = curve;
    let curve_source = if flags.iter().any(|f| f.code == FlagCode::HighMisfit) {
        // The discrepancy now carries the misfit: the model's part of the errors is that of the
        // measurement noise alone, not widened by the Birge ratio again.
        let unwiden = match problem.weighting {
            Weighting::ChiSquare => 1.0 / scale.max(1.0).sqrt(),
            Weighting::Relative => 1.0,
        };
        correct_by_discrepancy(
            problem,
            &predicted,
            unwiden,
            &mut curve,
            &mut leak_band_speed,
        )
    } else {
        CurveSource::Model
    };
    if curve_source == CurveSource::ModelPlusDiscrepancy {
        // The correction changed the reported leak-band speed and its error: the flag on it
        // reads the reported values, as the exports do.
        let at = flags
            .iter()
            .position(|f| f.code == FlagCode::SpeedUncertain);
        match (at, super::flags::speed_uncertain(leak_band_speed)) {
            (Some(i), Some(reason)) => flags[i].reason = reason,
            (Some(i), None) => {
                flags.remove(i);
            }
            (None, Some(reason)) => flags.push(Flag {
                code: FlagCode::SpeedUncertain,
                reason,
            }),
            (None, None) => {}
        }
    }
    let measured_hz: Vec<f64> = problem
        .data
        .measurements
        .iter()
        .map(|m| m.omega / std::f64::consts::TAU)
        .collect();
    Ok(FitResult {
        status: if flags.is_empty() {
            FitStatus::Ok
        } else {
            FitStatus::Flagged
        },
        method: settings.method,
        model: problem.model,
        contact_mode: settings.contact_mode,
        effects: settings.effects.clone(),
        estimates,
        misfit: match settings.method {
            Method::Paper => problem.paper_objective(&predicted),
            Method::Default => ss,
        },
        chi2_per_dof,
        weighting: problem.weighting,
        n_measurements: problem.data.measurements.len(),
        condition_number: Some(determined.condition_number),
        correlations: determined.correlation.clone(),
        flags,
        notes,
        evaluations: problem.evaluations(),
        system: Some(sys),
        predicted,
        message: None,
        restart_misfits: optima.iter().map(|o| o.cost).collect(),
        path_checked: true,
        p_wave_speed: Some(determined.p_wave_speed),
        s_wave_speed: Some(determined.s_wave_speed),
        curve,
        leak_band_speed,
        soil_information,
        curve_source,
        leak_band_extrapolation_octaves: extrapolation_octaves(LEAK_BAND_HZ, &measured_hz),
        result_seconds: started.elapsed().as_secs_f64(),
        provenance: Provenance::default(),
    })
}

/// What the data determine, from the Jacobian of the weighted residuals at the optimum.
fn uncertainty(
    problem: &Problem<'_>,
    bounds: &crate::optimize::Bounds,
    x: &[f64],
    predicted: &[Complex64],
    ss: f64,
    scale: f64,
) -> Determined {
    let m = problem.n_residuals();
    let n = problem.specs.len();
    let mut r0 = vec![0.0; m];
    problem.residuals_of(predicted, &mut r0);
    let mut j = vec![0.0; m * n];
    let jacobian = |p: &Problem<'_>, step: f64, j: &mut [f64]| {
        crate::optimize::jacobian_fd(
            p,
            x,
            &r0,
            Some(bounds),
            FiniteDifference::Central,
            step * FiniteDifference::Central.default_rel_step(),
            j,
        )
        .is_ok()
    };
    // Next to a root at grazing, or where the continuation passes close to another branch,
    // the search path may fail on both sides of a step while the reference path (which
    // accepted the optimum) still solves: fall back to it, then to coarser steps (a
    // continuation failure can sit between x and x ± h for the default h alone, as where the
    // root of a thin plastic pipe in stiff soil jumps between branches near the optimum).
    // When nothing works the Jacobian is left zero: the quadratic model then holds only the
    // weak prior, the intervals span the search range, and the fit is flagged, rather than the
    // segment left without an answer.
    let mut curvature_unknown = false;
    if !jacobian(problem, 1.0, &mut j) {
        let reference = problem.on_path(SolvePath::Reference);
        let found = JACOBIAN_FALLBACK_STEPS
            .iter()
            .any(|&step| jacobian(&reference, step, &mut j));
        problem.add_evaluations(reference.evaluations());
        if !found {
            j.fill(0.0);
            curvature_unknown = true;
        }
    }
    let mut determined = determine(
        &problem.specs,
        bounds,
        x,
        problem.data.soil_density,
        &j,
        m,
        scale,
        ss,
        |p| problem.predict(p).map(|k| problem.sum_of_squares(&k)),
        |p| profile_misfit(problem, bounds, p),
    );
    determined.curvature_unknown = curvature_unknown;
    determined
}

/// Finite-difference steps, as multiples of the default, tried on the reference path when the
/// search path cannot evaluate the Jacobian at the optimum: the default, then finer (a jump
/// of the continuation just beyond x + h on one side), then coarser (a failure band narrower
/// than the step).
const JACOBIAN_FALLBACK_STEPS: [f64; 5] = [1.0, 0.1, 0.01, 10.0, 100.0];

/// Iterations of the profile minimisation at a point of the valley scan.
pub const PROFILE_LM_ITERATIONS: usize = 3;

/// The misfit at `x` minimised over every coordinate but E_m and ν_m (a few Levenberg–Marquardt
/// iterations from `x`): the profile of P66 along the valley.
fn profile_misfit(
    problem: &Problem<'_>,
    bounds: &crate::optimize::Bounds,
    x: &[f64],
) -> Option<(f64, Vec<f64>)> {
    let free: Vec<usize> = problem
        .specs
        .iter()
        .enumerate()
        .filter(|(_, s)| !matches!(s.param, Param::SoilModulus | Param::SoilPoisson))
        .map(|(i, _)| i)
        .collect();
    let at_x = || {
        problem
            .predict(x)
            .map(|k| (problem.sum_of_squares(&k), x.to_vec()))
    };
    if free.is_empty() {
        return at_x();
    }
    minimize_restricted(problem, bounds, x, free, PROFILE_LM_ITERATIONS).or_else(at_x)
}

/// The misfit minimised over the coordinates `free` by Levenberg–Marquardt (at most
/// `iterations`, forward differences) from `x`, the others held at `x`'s values: the cost and
/// the full coordinates reached. Levenberg–Marquardt accepts only steps that lower the misfit,
/// so its cost is never above the start's. `None` when the minimisation fails.
fn minimize_restricted(
    problem: &Problem<'_>,
    bounds: &crate::optimize::Bounds,
    x: &[f64],
    free: Vec<usize>,
    iterations: usize,
) -> Option<(f64, Vec<f64>)> {
    let sub_bounds = crate::optimize::Bounds::new(
        free.iter().map(|&i| bounds.lower()[i]).collect(),
        free.iter().map(|&i| bounds.upper()[i]).collect(),
    )
    .ok()?;
    let x0: Vec<f64> = free.iter().map(|&i| x[i]).collect();
    let restricted = Restricted {
        problem,
        base: x.to_vec(),
        free,
    };
    let lm = LevenbergMarquardt::new()
        .max_iterations(iterations)
        .ok()?
        .finite_difference(FiniteDifference::Forward)
        .fd_rel_step(1e-6)
        .ok()?;
    lm.minimize(&restricted, &x0, Some(&sub_bounds))
        .ok()
        .filter(|r| r.cost.is_finite())
        .map(|r| (r.cost, restricted.full(&r.x)))
}

/// Levenberg–Marquardt iterations of [`predicted_with_effect_at`].
pub const EFFECT_AT_LM_ITERATIONS: usize = 40;

/// The prediction of `data` by the model with `settings.effects`, `effect`'s parameter held at
/// `value` (physical units) and every other coordinate minimising the misfit: a profile point
/// of the nested fit. The minimisation (Levenberg–Marquardt, at most
/// [`EFFECT_AT_LM_ITERATIONS`]) starts from `start`, a fit of the same data (with or without
/// the effect), with the effect set to `value`. `None` when `start` failed, `effect` is not among
/// `settings.effects`, `value` lies outside the effect's range, or no prediction exists.
pub fn predicted_with_effect_at(
    data: &SegmentData,
    settings: &FitSettings,
    start: &FitResult,
    effect: Effect,
    value: f64,
) -> Option<Vec<Complex64>> {
    let problem = problem_for(data, settings);
    let at = problem
        .specs
        .iter()
        .position(|s| s.param == Param::Effect(effect))?;
    let mut x = nested_start(&problem, &BaseOptimum::of(start)?)?;
    let c = problem.specs[at].coordinate(value);
    if !(c >= problem.specs[at].lower && c <= problem.specs[at].upper) {
        return None;
    }
    x[at] = c;
    let bounds = problem.bounds().ok()?;
    let free: Vec<usize> = (0..x.len()).filter(|&i| i != at).collect();
    let at_x = || problem.predict(&x);
    if free.is_empty() {
        return at_x();
    }
    minimize_restricted(&problem, &bounds, &x, free, EFFECT_AT_LM_ITERATIONS)
        .and_then(|(_, full)| problem.predict(&full))
        .or_else(at_x)
}

/// The problem with some coordinates held fixed.
struct Restricted<'p> {
    problem: &'p Problem<'p>,
    base: Vec<f64>,
    free: Vec<usize>,
}

impl crate::optimize::LeastSquares for Restricted<'_> {
    fn n_params(&self) -> usize {
        self.free.len()
    }
    fn n_residuals(&self) -> usize {
        self.problem.n_residuals()
    }
    fn residuals(&self, x: &[f64], out: &mut [f64]) -> bool {
        crate::optimize::LeastSquares::residuals(self.problem, &self.full(x), out)
    }
    fn near_at(&self, base: &[f64]) -> bool {
        crate::optimize::LeastSquares::near_at(self.problem, &self.full(base))
    }
    fn residuals_near(&self, base: &[f64], x: &[f64], out: &mut [f64]) -> bool {
        crate::optimize::LeastSquares::residuals_near(
            self.problem,
            &self.full(base),
            &self.full(x),
            out,
        )
    }
}

impl Restricted<'_> {
    /// The full coordinates of the free ones `x`.
    fn full(&self, x: &[f64]) -> Vec<f64> {
        let mut full = self.base.clone();
        for (&i, &v) in self.free.iter().zip(x) {
            full[i] = v;
        }
        full
    }
}

/// The predicted curve on the standard grid with one-sigma errors (P65), and the leak-band
/// mean speed with its error. Values come from the reference path; the sensitivities from one
/// perturbed system per fitted coordinate, each root solved from the unperturbed one.
fn predicted_curve(
    problem: &Problem<'_>,
    bounds: &crate::optimize::Bounds,
    x: &[f64],
    sys: &System,
    cov: &[f64],
) -> (Vec<PredictedPoint>, Option<WithError>) {
    let base = curve(sys, &STANDARD_GRID_HZ);
    let n = x.len();
    let k_of = |c: f64, att_db: f64, f: f64| {
        let w = hz_to_omega(f);
        Complex64::new(w / c, -db_to_np(att_db))
    };
    // Sensitivities: per coordinate, the perturbed speeds and attenuations.
    let mut d_speed = vec![vec![None; n]; base.len()];
    let mut d_att = vec![vec![None; n]; base.len()];
    let mut d_band = vec![None; n];
    let band_of = |pts: &[(f64, Option<f64>)]| band_mean(pts, LEAK_BAND_HZ);
    let base_pts: Vec<(f64, Option<f64>)> = base
        .iter()
        .map(|p| (p.frequency_hz, p.status.is_ok().then_some(p.phase_speed)))
        .collect();
    let band0 = band_of(&base_pts);
    for q in 0..n {
        let w = bounds.width(q);
        let mut h = CURVE_FD_STEP_FRACTION * w;
        if x[q] + h > bounds.upper()[q] {
            h = -h;
        }
        let mut xp = x.to_vec();
        xp[q] += h;
        let Some(sp) = problem.system_at(&xp) else {
            continue;
        };
        let mut pts = Vec::with_capacity(base.len());
        for (i, p) in base.iter().enumerate() {
            let mut c1 = None;
            if p.status.is_ok() {
                let guess = k_of(p.phase_speed, p.attenuation_db, p.frequency_hz);
                if let Ok(r) =
                    solve_from_guess_tol(&sp, hz_to_omega(p.frequency_hz), guess, Tolerance::FAST)
                {
                    d_speed[i][q] = Some((r.phase_speed() - p.phase_speed) / h);
                    d_att[i][q] = Some((r.attenuation_db() - p.attenuation_db) / h);
                    c1 = Some(r.phase_speed());
                }
            }
            pts.push((p.frequency_hz, c1));
        }
        if let (Some(b0), Some(b1)) = (band0, band_of(&pts)) {
            d_band[q] = Some((b1 - b0) / h);
        }
    }
    let sigma = |g: &[Option<f64>]| -> Option<f64> {
        let g: Option<Vec<f64>> = g.iter().copied().collect();
        g.map(|g| propagate(&g, cov))
    };
    let points = base
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let ok = p.status.is_ok();
            let finite = |v: f64| (ok && v.is_finite()).then_some(v);
            let phase_speed = finite(p.phase_speed);
            let attenuation_db = finite(p.attenuation_db);
            PredictedPoint {
                frequency_hz: p.frequency_hz,
                phase_speed,
                phase_speed_std: phase_speed.and(sigma(&d_speed[i])),
                attenuation_db,
                attenuation_db_std: attenuation_db.and(sigma(&d_att[i])),
                model_phase_speed: phase_speed,
                model_attenuation_db: attenuation_db,
            }
        })
        .collect();
    let band = band0.and_then(|v| sigma(&d_band).map(|s| WithError { value: v, std: s }));
    (points, band)
}

/// The residuals of the phase speed and of the attenuation in ln q at the measured
/// frequencies (P89), with the stated relative errors or the assumed ones.
fn log_residuals(problem: &Problem<'_>, predicted: &[Complex64]) -> (Vec<Residual>, Vec<Residual>) {
    let mut speed = Vec::new();
    let mut att = Vec::new();
    for (m, k) in problem.data.measurements.iter().zip(predicted) {
        let f = m.omega / std::f64::consts::TAU;
        // c = ω/Re k, so ln(c_meas/c_model) = ln(Re k_model / Re k_meas).
        speed.push(Residual {
            frequency_hz: f,
            ln_ratio: (k.re / m.k_re).ln(),
            sigma: m
                .k_re_std
                .map_or(ASSUMED_RELATIVE_SPEED_STD, |s| s / m.k_re),
        });
        if m.attenuation > 0.0 && -k.im > 0.0 {
            att.push(Residual {
                frequency_hz: f,
                ln_ratio: (m.attenuation / -k.im).ln(),
                sigma: m
                    .attenuation_std
                    .map_or(ASSUMED_RELATIVE_ATTENUATION_STD, |s| s / m.attenuation),
            });
        }
    }
    (speed, att)
}

/// Where the misfit is significant: the curve becomes the model times exp(δ̂) of the
/// discrepancy fitted to each quantity's residuals (P89), its errors include the
/// discrepancy's, and the leak-band speed is the corrected curve's band mean, its error the
/// model's and the band mean of the discrepancy's one-sigma (taken fully correlated across the
/// band, since a discrepancy is smooth in frequency). The model's errors are multiplied by
/// `model_std_factor` (1/R_B: the discrepancy explains the misfit). The model's values stay in
/// `model_phase_speed` and `model_attenuation_db`. The corrected curve is kept physical
/// ([`correct_curve`]).
fn correct_by_discrepancy(
    problem: &Problem<'_>,
    predicted: &[Complex64],
    model_std_factor: f64,
    curve: &mut [PredictedPoint],
    leak_band_speed: &mut Option<WithError>,
) -> CurveSource {
    let (speed_res, att_res) = log_residuals(problem, predicted);
    let Some(speed) = Discrepancy::fit(&speed_res) else {
        return CurveSource::Model;
    };
    let att = Discrepancy::fit(&att_res);
    let measured_db: Vec<f64> = problem
        .data
        .measurements
        .iter()
        .map(|m| crate::units::np_to_db(m.attenuation))
        .filter(|a| a.is_finite() && *a > 0.0)
        .collect();
    let att_range = (!measured_db.is_empty()).then(|| {
        (
            measured_db.iter().copied().fold(f64::INFINITY, f64::min),
            measured_db
                .iter()
                .copied()
                .fold(f64::NEG_INFINITY, f64::max),
        )
    });
    let (band_pts, band_disc) = correct_curve(
        curve,
        &speed,
        att.as_ref().zip(att_range),
        model_std_factor,
        problem.data.fluid.sound_speed(),
    );
    let model_band_std = leak_band_speed.map_or(0.0, |b| b.std * model_std_factor);
    *leak_band_speed = match (
        band_mean(&band_pts, LEAK_BAND_HZ),
        band_mean(&band_disc, LEAK_BAND_HZ),
    ) {
        (Some(v), Some(s)) => Some(WithError {
            value: v,
            std: (model_band_std * model_band_std + s * s).sqrt(),
        }),
        _ => None,
    };
    CurveSource::ModelPlusDiscrepancy
}

/// How far a corrected attenuation may lie from the measured ones and still be given: within a
/// factor of 10 below the smallest and above the largest measured attenuation of the segment.
pub const ATTENUATION_SUPPORT_FACTOR: f64 = 10.0;

/// Per grid frequency (Hz), a value where there is one: the inputs of a band mean.
type BandPoints = Vec<(f64, Option<f64>)>;

/// One corrected value: the value, its one-sigma error, and the discrepancy's part of it.
type Corrected = (f64, f64, f64);

/// `model` × exp(δ̂) at `f` with its error, or `None` where the model gives no positive value.
fn corrected(
    model: Option<f64>,
    model_std: Option<f64>,
    model_std_factor: f64,
    d: &Discrepancy,
    f: f64,
) -> Option<Corrected> {
    let v = model.filter(|v| v.is_finite() && *v > 0.0)?;
    let (mean, var) = d.at(f);
    let c = v * mean.exp();
    let model_std = model_std.unwrap_or(0.0) * model_std_factor * mean.exp();
    let out = (
        c,
        (model_std * model_std + c * c * var).sqrt(),
        c * var.sqrt(),
    );
    (out.0.is_finite() && out.1.is_finite() && out.2.is_finite()).then_some(out)
}

/// Correct a model curve by the discrepancies of its speed and attenuation (P89), physically:
///
/// - a corrected phase speed lies in (0, `max_speed`), `max_speed` the water's free speed c_f
///   (the pipe's wave is slower than sound in the unconfined water); where exp(δ̂) would take
///   it out, the point keeps the model's speed, with the discrepancy's error (tapered to the
///   model). Outside the measured band δ̂ is held at its edge value (`Discrepancy::at`);
/// - a corrected attenuation is given only where it is supported: within the measured band
///   widened by [`super::discrepancy::SUPPORT_MARGIN_OCTAVES`], where the model's attenuation
///   is positive, where its one-sigma error is below the value itself, and where it lies within
///   [`ATTENUATION_SUPPORT_FACTOR`] of the measured attenuations (`att`'s range, dB/m: a
///   correction that multiplies a model attenuation near zero by the ratio found next to it
///   gives values no measurement is near); elsewhere it and its error are `None` (the exports
///   leave them blank, the plots leave them out). Never below 0.
///
/// Returns the leak-band mean's inputs: each point's speed and the discrepancy's part of its
/// error.
pub(crate) fn correct_curve(
    curve: &mut [PredictedPoint],
    speed: &Discrepancy,
    att: Option<(&Discrepancy, (f64, f64))>,
    model_std_factor: f64,
    max_speed: f64,
) -> (BandPoints, BandPoints) {
    let mut band_pts = Vec::with_capacity(curve.len());
    let mut band_disc = Vec::with_capacity(curve.len());
    for p in curve.iter_mut() {
        let f = p.frequency_hz;
        let model_speed = p.model_phase_speed.filter(|v| v.is_finite() && *v > 0.0);
        let c = corrected(model_speed, p.phase_speed_std, model_std_factor, speed, f)
            .filter(|c| c.0 > 0.0 && c.0 < max_speed)
            .or_else(|| {
                // Tapered to the model: its speed, with the discrepancy's error.
                model_speed.filter(|v| *v < max_speed).and_then(|v| {
                    let m = p.phase_speed_std.unwrap_or(0.0) * model_std_factor;
                    let d = v * speed.at(f).1.sqrt();
                    let s = (m * m + d * d).sqrt();
                    (d.is_finite() && s.is_finite()).then_some((v, s, d))
                })
            });
        p.phase_speed = c.map(|c| c.0);
        p.phase_speed_std = c.map(|c| c.1);
        band_pts.push((f, p.phase_speed));
        band_disc.push((f, c.map(|c| c.2)));
        if let Some((a, (a_lo, a_hi))) = att {
            let (lo, hi) = a.support_hz();
            let (v_lo, v_hi) = (
                a_lo / ATTENUATION_SUPPORT_FACTOR,
                a_hi * ATTENUATION_SUPPORT_FACTOR,
            );
            let c = corrected(
                p.model_attenuation_db,
                p.attenuation_db_std,
                model_std_factor,
                a,
                f,
            )
            .filter(|c| (lo..=hi).contains(&f) && (v_lo..=v_hi).contains(&c.0) && c.1 < c.0);
            p.attenuation_db = c.map(|c| c.0);
            p.attenuation_db_std = c.map(|c| c.1);
        } else if p.attenuation_db.is_some_and(|a| a.is_nan() || a < 0.0) {
            // No attenuation residual to correct by: the model's, where it is physical.
            p.attenuation_db = None;
            p.attenuation_db_std = None;
        }
    }
    (band_pts, band_disc)
}

/// Mean phase speed over [`LEAK_BAND_HZ`] of `sys`, m/s: the leak-band speed every fit and
/// prediction reports, and the truth of a synthetic network.
pub fn leak_band_speed_of(sys: &System) -> Option<f64> {
    let band: Vec<f64> = STANDARD_GRID_HZ
        .iter()
        .copied()
        .filter(|&f| f >= LEAK_BAND_HZ.0 && f <= LEAK_BAND_HZ.1)
        .collect();
    let pts: Vec<(f64, Option<f64>)> = curve(sys, &band)
        .into_iter()
        .map(|p| (p.frequency_hz, p.status.is_ok().then_some(p.phase_speed)))
        .collect();
    band_mean(&pts, LEAK_BAND_HZ)
}

/// The valley points inside the 95 % profile region ([`Determined::valley`]) must lie within
/// 1.96 σ of the leak-band speed too, as they do of c_P and c_S. The quadratic model at the
/// optimum does not see how far a flat valley reaches: at a valley's end (ξ at its bound, say)
/// it can give the band speed a fifth of the error it has in the valley's middle. The band
/// speed moves along the valley with c_P and c_S, so it is computed at the points where they
/// are extreme (at most four).
fn widen_band_to_valley(
    problem: &Problem<'_>,
    determined: &Determined,
    leak_band_speed: &mut Option<WithError>,
) {
    let Some(band) = leak_band_speed.as_mut() else {
        return;
    };
    // (c_P, c_S, system) of each valley point.
    let points: Vec<(f64, f64, System)> = determined
        .valley
        .iter()
        .filter_map(|x| {
            let sys = problem.system_at(x)?;
            let (cp, cs) = sys.soil.wave_speeds();
            Some((cp, cs, sys))
        })
        .collect();
    let by_cp = |a: &&(f64, f64, System), b: &&(f64, f64, System)| a.0.total_cmp(&b.0);
    let by_cs = |a: &&(f64, f64, System), b: &&(f64, f64, System)| a.1.total_cmp(&b.1);
    let mut extremes: Vec<&(f64, f64, System)> = Vec::with_capacity(4);
    for pick in [
        points.iter().min_by(by_cp),
        points.iter().max_by(by_cp),
        points.iter().min_by(by_cs),
        points.iter().max_by(by_cs),
    ]
    .into_iter()
    .flatten()
    {
        if !extremes.iter().any(|e| std::ptr::eq(*e, pick)) {
            extremes.push(pick);
        }
    }
    for (_, _, sys) in extremes {
        if let Some(other) = leak_band_speed_of(sys) {
            band.reach(other);
        }
    }
}

/// The other optima inside the 95 % confidence region of the best (P66): the misfit's profile
/// over any parameter is at most Δχ² = 3.84 (times `scale`, the variance factor of the
/// covariance) above the best at their values, so the 95 % intervals must reach them, and the
/// errors of c_P, c_S (P63–P64) and the leak-band speed must put them within 1.96 σ. The
/// quadratic model at the best optimum cannot see another basin.
fn widen_to_rival_optima(
    problem: &Problem<'_>,
    optima: &[Optimum],
    best_i: usize,
    scale: f64,
    determined: &mut Determined,
    leak_band_speed: &mut Option<WithError>,
) {
    use super::uncertainty::DCHI2_95;
    let best = optima[best_i].cost;
    for (i, o) in optima.iter().enumerate() {
        let inside = o.cost - best <= DCHI2_95 * scale;
        if i == best_i || !inside {
            continue;
        }
        for (j, s) in problem.specs.iter().enumerate() {
            determined.intervals[j].include(s, s.value(o.x[j]));
        }
        let Some(sys) = problem.system_at(&o.x) else {
            continue;
        };
        let (cp, cs) = sys.soil.wave_speeds();
        determined.p_wave_speed.reach(cp);
        determined.s_wave_speed.reach(cs);
        if let (Some(b), Some(other)) = (leak_band_speed.as_mut(), leak_band_speed_of(&sys)) {
            b.reach(other);
        }
    }
}

/// Whether another restart found an equally good optimum far from the best one (in units of
/// the determined covariance), and the leak-band speed it predicts.
fn separated_minima(
    problem: &Problem<'_>,
    optima: &[Optimum],
    best_i: usize,
    determined: &Determined,
) -> Option<Separated> {
    let best = &optima[best_i];
    let n = problem.specs.len();
    for (i, o) in optima.iter().enumerate() {
        if i == best_i {
            continue;
        }
        let equivalent = match problem.weighting {
            Weighting::ChiSquare => o.cost - best.cost <= EQUIVALENT_DCHI2,
            Weighting::Relative => o.cost - best.cost <= EQUIVALENT_RELATIVE * best.cost + 1e-12,
        };
        if !equivalent {
            continue;
        }
        for (j, s) in problem.specs.iter().enumerate() {
            let d = (o.x[j] - best.x[j]).abs();
            let sigma = determined.cov[j * n + j].max(0.0).sqrt();
            let width = s.upper - s.lower;
            let far = d > SEPARATION_RANGE_FRACTION * width
                && (!sigma.is_finite() || d > SEPARATION_SIGMAS * sigma);
            if far {
                let other_leak_band_speed = problem
                    .system_at(&o.x)
                    .and_then(|sys| leak_band_speed_of(&sys));
                return Some(Separated {
                    description: format!(
                        "restarts found equally good fits (misfit {} and {}) with {} = {} and {}",
                        sig(best.cost, 4),
                        sig(o.cost, 4),
                        s.param.name(),
                        sig(s.value(best.x[j]), 4),
                        sig(s.value(o.x[j]), 4)
                    ),
                    other_leak_band_speed,
                });
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::invert::uncertainty::{Interval, Z_95};
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]
        /// Every curve a fit can store is physical: whatever the residuals (a model several
        /// decades off, few or many frequencies, any noise) and whatever the model curve (an
        /// attenuation near, at or below zero, a speed past the water's), the corrected phase
        /// speed lies in (0, c_f) and the corrected attenuation is absent or non-negative,
        /// inside the support band and near the measured attenuations.
        #[test]
        fn every_corrected_curve_is_physical(
            pts in proptest::collection::vec(
                (20.0..3000.0f64, -12.0..12.0f64, 1e-4..2.0f64, -12.0..12.0f64, 1e-3..2.0f64),
                1..12,
            ),
            model in proptest::collection::vec((10.0..2500.0f64, -0.05..2.0f64), STANDARD_GRID_HZ.len()),
            range in (1e-4..1.0f64, 1.0..100.0f64),
        ) {
            const C_F: f64 = 1481.0;
            let speed_res: Vec<Residual> = pts
                .iter()
                .map(|&(f, r, s, _, _)| Residual { frequency_hz: f, ln_ratio: r, sigma: s })
                .collect();
            let att_res: Vec<Residual> = pts
                .iter()
                .map(|&(f, _, _, r, s)| Residual { frequency_hz: f, ln_ratio: r, sigma: s })
                .collect();
            let (speed, att) = (Discrepancy::fit(&speed_res), Discrepancy::fit(&att_res));
            prop_assume!(speed.is_some() && att.is_some());
            let (speed, att) = (speed.unwrap(), att.unwrap());
            let mut curve: Vec<PredictedPoint> = STANDARD_GRID_HZ
                .iter()
                .zip(&model)
                .map(|(&f, &(c, a))| PredictedPoint {
                    frequency_hz: f,
                    phase_speed: Some(c),
                    phase_speed_std: Some(0.01 * c),
                    attenuation_db: Some(a),
                    attenuation_db_std: Some(0.05 * a.abs()),
                    model_phase_speed: Some(c),
                    model_attenuation_db: Some(a),
                })
                .collect();
            let (lo_a, hi_a) = (range.0, range.0 * range.1);
            correct_curve(&mut curve, &speed, Some((&att, (lo_a, hi_a))), 1.0, C_F);
            let (lo, hi) = att.support_hz();
            for p in &curve {
                if let Some(c) = p.phase_speed {
                    prop_assert!(c > 0.0 && c < C_F, "{} Hz: speed {c}", p.frequency_hz);
                    prop_assert!(p.phase_speed_std.is_some_and(f64::is_finite));
                }
                if let Some(a) = p.attenuation_db {
                    prop_assert!(a.is_finite() && a >= 0.0, "{} Hz: attenuation {a}", p.frequency_hz);
                    prop_assert!((lo..=hi).contains(&p.frequency_hz), "{} Hz outside {lo}-{hi}", p.frequency_hz);
                    prop_assert!(a <= hi_a * ATTENUATION_SUPPORT_FACTOR && a >= lo_a / ATTENUATION_SUPPORT_FACTOR);
                    prop_assert!(p.attenuation_db_std.is_some_and(|s| s < a));
                }
            }
            // Without an attenuation correction the model's attenuation is kept where physical.
            let mut bare = curve.clone();
            for (p, &(c, a)) in bare.iter_mut().zip(&model) {
                p.phase_speed = Some(c);
                p.attenuation_db = Some(a);
            }
            correct_curve(&mut bare, &speed, None, 1.0, C_F);
            for (p, &(_, a)) in bare.iter().zip(&model) {
                prop_assert_eq!(p.attenuation_db, (a >= 0.0).then_some(a));
            }
        }
    }
    use crate::physics::soil::soil_speeds;
    use crate::physics::{ContactMode, Model};

    /// Where no finite-difference Jacobian exists on any path or step, the curvature is
    /// unknown and the intervals span the search range. The point: an HDPE pipe of the stress
    /// network (tests/stress.rs) at a soil where the model's root jumps between branches for
    /// the slightest change of E_m or ξ (the fit now answers next to it, where a Jacobian
    /// exists).
    #[test]
    fn where_no_jacobian_exists_the_intervals_span_the_search_range() {
        use crate::physics::effects::Effect;
        use crate::synth::{generate, SynthOptions};
        let options = SynthOptions::hiding(Effect::WallThinning, 2500, 13).expect("a range");
        let net = generate(&options);
        let data = net
            .iter()
            .find(|s| s.id == "WM10951")
            .expect("the segment")
            .segment_data();
        let s = FitSettings::default();
        let mut p = Problem::new(&data, s.method, s.model, s.contact_mode, &s.effects);
        // The answer came from the safe path (the fast path's ranking was not confirmed).
        p.path = SolvePath::Safe;
        let bounds = p.bounds().expect("bounds");
        let x: Vec<f64> = [
            4_620_961_825_393_077_189,
            4_600_801_963_784_091_329,
            1.0f64.to_bits(),
        ]
        .into_iter()
        .map(f64::from_bits)
        .collect(); // (8.477143144458646, 0.39581359668668986, 1): log10 E_m, ν_m, ξ
        let sys = p.system_at(&x).expect("a system");
        let predicted: Vec<Complex64> = p
            .reference_roots(&sys)
            .expect("the reference path solves there")
            .iter()
            .map(|r| r.k1)
            .collect();
        let ss = p.sum_of_squares(&predicted);
        let d = uncertainty(&p, &bounds, &x, &predicted, ss, 1.0);
        assert!(d.curvature_unknown);
        for (i, s) in d.intervals.iter().zip(&p.specs) {
            assert!(
                i.lo <= s.value(s.lower) * (1.0 + 1e-9) && i.hi >= s.value(s.upper) * (1.0 - 1e-9),
                "{:?}: {i:?}",
                s.param
            );
        }
    }

    /// The 95 % intervals and the errors of the soil speeds and the leak-band speed reach an
    /// optimum inside the 95 % region of the best (Δχ² ≤ 3.84 × scale), and only such one.
    #[test]
    fn intervals_reach_rival_optima_inside_the_95_percent_region() {
        let data = crate::bench::paper_case_data();
        let p = Problem::new(
            &data,
            Method::Default,
            Model::Full,
            ContactMode::Reciprocal,
            &[],
        );
        let best = vec![7.5, 0.30, 0.40];
        let inside = vec![8.5, 0.45, 0.70];
        let outside = vec![5.0, 0.10, 0.95];
        let scale = 2.0;
        let optima = vec![
            Optimum {
                x: best.clone(),
                cost: 10.0,
            },
            Optimum {
                x: inside.clone(),
                cost: 10.0 + 3.8 * scale,
            },
            Optimum {
                x: outside.clone(),
                cost: 10.0 + 3.9 * scale,
            },
        ];
        let speeds = |x: &[f64]| soil_speeds(10f64.powf(x[0]), x[1], data.soil_density);
        let (cp, cs) = speeds(&best);
        let narrow = |v: f64| Interval {
            lo: v * 0.99,
            hi: v * 1.01,
            reaches_lower_bound: false,
            reaches_upper_bound: false,
        };
        let mut determined = Determined {
            p_wave_speed: WithError {
                value: cp,
                std: 1.0,
            },
            s_wave_speed: WithError {
                value: cs,
                std: 1.0,
            },
            intervals: vec![
                narrow(10f64.powf(best[0])),
                narrow(best[1]),
                narrow(best[2]),
            ],
            cov: vec![0.0; 9],
            correlation: vec![0.0; 9],
            condition_number: 1.0,
            curvature_unknown: false,
            valley: Vec::new(),
            speed_information: [0.0; 3],
        };
        let band_at = |x: &[f64]| leak_band_speed_of(&p.system_at(x).unwrap()).unwrap();
        let (band_best, band_inside) = (band_at(&best), band_at(&inside));
        let mut band = Some(WithError {
            value: band_best,
            std: 0.01,
        });
        widen_to_rival_optima(&p, &optima, 0, scale, &mut determined, &mut band);
        let iv = &determined.intervals;
        assert_eq!(iv[0].hi, 10f64.powf(inside[0]));
        assert_eq!((iv[1].hi, iv[2].hi), (inside[1], inside[2]));
        // The optimum outside the region leaves the lower ends alone.
        assert_eq!(iv[0].lo, 10f64.powf(best[0]) * 0.99);
        assert_eq!((iv[1].lo, iv[2].lo), (best[1] * 0.99, best[2] * 0.99));
        assert!(iv
            .iter()
            .all(|i| !i.reaches_lower_bound && !i.reaches_upper_bound));
        let (cp_in, cs_in) = speeds(&inside);
        assert!((determined.p_wave_speed.std - (cp_in - cp).abs() / Z_95).abs() < 1e-9 * cp);
        assert!((determined.s_wave_speed.std - (cs_in - cs).abs() / Z_95).abs() < 1e-9 * cs);
        let b = band.unwrap();
        assert!(band_inside != band_best);
        assert!((b.std - (band_inside - band_best).abs() / Z_95).abs() < 1e-9 * band_best);
    }
}
