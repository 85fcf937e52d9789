//! What a fit's user must know: flags (act on these: the prediction is not to be trusted as it
//! stands) and notes (what the data leave undetermined: information about the soil, not a defect
//! of the fit; model §7.10). Each finding has a code and a one-line reason.
//!
//! The rule: a fit is `ok` when the model explains the data, the optimum is unique where it
//! matters for the prediction, and the leak-band speed is determined (one sigma ≤
//! [`SPEED_RSTD_MAX`]); anything else that the user must act on is a flag. That E_m or ν_m
//! alone is not determined is a note.

use std::fmt;

use num_complex::Complex64;

use super::problem::{Param, Problem, Weighting};
use super::uncertainty::{Determined, WithError};
use crate::physics::dispersion::korteweg_speed;
use crate::physics::effects::Effect;
use crate::physics::solver::Root;
use crate::physics::{Soil, System};
use crate::stats::chi2_upper_tail;
use crate::units::sig;

/// A chi-square whose upper-tail probability is below this is too high for the stated noise.
pub const MISFIT_P_VALUE: f64 = 1e-3;
/// Without standard deviations: RMS relative error of Re k above which the fit is poor.
pub const RELATIVE_SPEED_RMS_MAX: f64 = 0.02;
/// Without standard deviations: RMS relative error of the attenuation above which it is poor.
pub const RELATIVE_ATTENUATION_RMS_MAX: f64 = 0.3;
/// A measured phase speed below this fraction of the Korteweg speed of the stiffest plausible
/// wall of the material cannot be the s = 1 wave of that pipe.
pub const MIN_SPEED_FRACTION_OF_KORTEWEG: f64 = 0.5;
/// Relative one-sigma error of the leak-band speed above which the prediction is not
/// determined: the speed a correlator is given should be good to 2 %.
pub const SPEED_RSTD_MAX: f64 = 0.02;
/// Relative one-sigma error of c_P or c_S below which the data determine that speed.
pub const SPEED_DETERMINED_RSTD: f64 = 0.1;
/// E_m is determined when its 95 % interval spans at most this factor (hi/lo).
pub const MODULUS_DETERMINED_RATIO: f64 = 2.0;
/// ν_m is determined when its 95 % interval is at most this wide.
pub const POISSON_DETERMINED_WIDTH: f64 = 0.15;
/// ξ (and an effect's parameter, as a fraction of its range) is determined when its 95 %
/// interval spans at most this fraction of its range.
pub const RANGE_DETERMINED_FRACTION: f64 = 0.5;
/// Two equally good optima predict the same leak-band speed when they differ by less than this
/// many sigma of it, or less than [`SAME_SPEED_RTOL`].
pub const SAME_SPEED_SIGMAS: f64 = 2.0;
/// … or less than this relative amount.
pub const SAME_SPEED_RTOL: f64 = 0.005;

/// Whether a finding asks for action (a flag) or informs (a note).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Severity {
    /// Stored in `fits.flags`; the fit's status is `flagged`.
    Flag,
    /// Stored in `fits.notes`; the status is unaffected.
    Note,
}

/// Finding codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FlagCode {
    /// Misfit too high for the stated noise (flag).
    HighMisfit,
    /// Fewer numbers than parameters (flag).
    TooFewMeasurements,
    /// A measured speed no pipe of that material could have (flag).
    InconsistentMeasurements,
    /// A measured frequency outside the model's validity (flag).
    OutOfValidity,
    /// Equally good, separated optima predicting different leak-band speeds (flag).
    MultipleMinima,
    /// The leak-band speed is uncertain by more than [`SPEED_RSTD_MAX`] (flag).
    SpeedUncertain,
    /// The model's root cannot be followed next to the optimum, so the misfit's curvature is
    /// unknown and the intervals are the search range (flag).
    UnstableRoot,
    /// E_m and ν_m known only through c_P (note).
    SoilViaCp,
    /// E_m and ν_m known only through c_S (note).
    SoilViaCs,
    /// E_m or ν_m not determined, though c_P and c_S are (note).
    SoilViaSpeeds,
    /// Neither soil speed is determined (note).
    SoilUndetermined,
    /// ξ not determined (note).
    ContactUndetermined,
    /// An effect's parameter not determined (note).
    EffectUndetermined,
    /// A parameter's interval reaches its search bound (note).
    AtBound,
    /// A predicted root near grazing (note).
    NearGrazing,
    /// Equally good, separated optima that predict the same speed (note).
    EquivalentMinima,
    /// The fitted speed is far from what the measured neighbours predict, leave-one-out
    /// (flag; raised by the soil field, not by a segment's fit).
    FieldOutlier,
}

impl FlagCode {
    /// The code stored in `fits.flags` or `fits.notes`.
    pub fn as_str(self) -> &'static str {
        match self {
            FlagCode::HighMisfit => "high_misfit",
            FlagCode::TooFewMeasurements => "too_few_measurements",
            FlagCode::InconsistentMeasurements => "inconsistent_measurements",
            FlagCode::OutOfValidity => "out_of_validity",
            FlagCode::MultipleMinima => "multiple_minima",
            FlagCode::SpeedUncertain => "speed_uncertain",
            FlagCode::SoilViaCp => "soil_via_cp",
            FlagCode::SoilViaCs => "soil_via_cs",
            FlagCode::SoilViaSpeeds => "soil_via_speeds",
            FlagCode::SoilUndetermined => "soil_undetermined",
            FlagCode::ContactUndetermined => "contact_undetermined",
            FlagCode::EffectUndetermined => "effect_undetermined",
            FlagCode::AtBound => "at_bound",
            FlagCode::NearGrazing => "near_grazing",
            FlagCode::EquivalentMinima => "equivalent_minima",
            FlagCode::UnstableRoot => "unstable_root",
            FlagCode::FieldOutlier => "field_outlier",
        }
    }

    /// Flag or note.
    pub fn severity(self) -> Severity {
        match self {
            FlagCode::HighMisfit
            | FlagCode::TooFewMeasurements
            | FlagCode::InconsistentMeasurements
            | FlagCode::OutOfValidity
            | FlagCode::MultipleMinima
            | FlagCode::SpeedUncertain
            | FlagCode::UnstableRoot
            | FlagCode::FieldOutlier => Severity::Flag,
            _ => Severity::Note,
        }
    }

    /// What it means and what to do about it (README, audit report).
    pub fn advice(self) -> &'static str {
        match self {
            FlagCode::HighMisfit => "the model does not explain the data within their stated noise: check the measurements and the inventory record, then run `diagnose`",
            FlagCode::TooFewMeasurements => "fewer measured numbers than fitted parameters: measure at more frequencies",
            FlagCode::InconsistentMeasurements => "a measured speed no pipe of this material could have: check the material and the measurement",
            FlagCode::OutOfValidity => "a measured frequency above half the ring or fluid cut-on frequency, where the model does not hold: drop it or re-measure lower",
            FlagCode::MultipleMinima => "two soils explain the data equally well and predict different speeds: measure at more frequencies to separate them",
            FlagCode::SpeedUncertain => "the leak-band speed is uncertain by more than 2 %: measure at more frequencies in 100-800 Hz or with less noise",
            FlagCode::SoilViaCp => "the data fix the soil's compressional speed c_P, not E_m and nu_m separately (usual for metal pipes); nothing to do",
            FlagCode::SoilViaCs => "the data fix the soil's shear speed c_S, not E_m and nu_m separately; nothing to do",
            FlagCode::SoilViaSpeeds => "the data fix c_P and c_S but E_m or nu_m only loosely; nothing to do",
            FlagCode::SoilUndetermined => "the data say little about the soil; the speed prediction may still be good",
            FlagCode::ContactUndetermined => "the contact coefficient is not determined; nothing to do",
            FlagCode::EffectUndetermined => "an effect's parameter is not determined by the data",
            FlagCode::AtBound => "a parameter's interval reaches its search bound: the data bound it on one side only",
            FlagCode::NearGrazing => "the predicted wave is within 2 % of a soil wave speed: the model is near a singular point there",
            FlagCode::EquivalentMinima => "separated optima fit equally well but predict the same speed; nothing to do",
            FlagCode::UnstableRoot => "the model's wave jumps between branches next to the fitted soil, so no uncertainty can be computed: do not use the values; check the inventory record and run `diagnose`",
            FlagCode::FieldOutlier => "the fitted leak-band speed is far from what the measured neighbours predict (leave-one-out, |z| > 3.29): a wrong record, a changed soil or a leak; check the record and re-measure",
        }
    }

    /// Every code.
    pub const ALL: [FlagCode; 17] = [
        FlagCode::HighMisfit,
        FlagCode::TooFewMeasurements,
        FlagCode::InconsistentMeasurements,
        FlagCode::OutOfValidity,
        FlagCode::MultipleMinima,
        FlagCode::SpeedUncertain,
        FlagCode::UnstableRoot,
        FlagCode::FieldOutlier,
        FlagCode::SoilViaCp,
        FlagCode::SoilViaCs,
        FlagCode::SoilViaSpeeds,
        FlagCode::SoilUndetermined,
        FlagCode::ContactUndetermined,
        FlagCode::EffectUndetermined,
        FlagCode::AtBound,
        FlagCode::NearGrazing,
        FlagCode::EquivalentMinima,
    ];
}

impl fmt::Display for FlagCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A raised flag or note.
#[derive(Debug, Clone, PartialEq)]
pub struct Flag {
    /// Its code.
    pub code: FlagCode,
    /// One line for the engineer.
    pub reason: String,
}

impl fmt::Display for Flag {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.code, self.reason)
    }
}

/// A second optimum as good as the best one, far from it.
#[derive(Debug, Clone, PartialEq)]
pub struct Separated {
    /// What differs (parameter values, misfits).
    pub description: String,
    /// The leak-band speed the other optimum predicts, m/s (None: not computable).
    pub other_leak_band_speed: Option<f64>,
}

/// Everything the assessment looks at, built once by the fit.
pub struct Evidence<'a> {
    /// The problem.
    pub problem: &'a Problem<'a>,
    /// The optimum in search coordinates.
    pub x: &'a [f64],
    /// Model wavenumbers at the measured frequencies.
    pub predicted: &'a [Complex64],
    /// The reference-path roots at the measured frequencies.
    pub roots: &'a [Root],
    /// χ²/dof when standard deviations are known.
    pub chi2_per_dof: Option<f64>,
    /// What the data determine.
    pub determined: &'a Determined,
    /// The predicted leak-band speed, m/s, with its error.
    pub leak_band_speed: Option<WithError>,
    /// A separated, equally good optimum, if the restarts found one.
    pub separated: Option<Separated>,
}

/// The `speed_uncertain` reason for the reported leak-band speed, from the very value and error
/// the fit stores and the exports show; `None` when it is known within [`SPEED_RSTD_MAX`].
pub fn speed_uncertain(leak_band_speed: Option<WithError>) -> Option<String> {
    match leak_band_speed {
        Some(s) if s.relative() <= SPEED_RSTD_MAX => None,
        Some(s) => Some(format!(
            "leak-band speed {} ± {} m/s ({:.1} %, one sigma)",
            sig(s.value, 4),
            sig(s.std, 2),
            100.0 * s.relative()
        )),
        None => {
            Some("the leak-band speed could not be predicted over the whole 100-800 Hz band".into())
        }
    }
}

/// Assess a fit: its flags and notes, flags first.
pub fn assess(ev: &Evidence<'_>) -> Vec<Flag> {
    let mut out = Vec::new();
    let mut push = |code, reason: String| out.push(Flag { code, reason });
    let problem = ev.problem;
    let data = problem.data;
    let m = data.measurements.len();
    let n = problem.specs.len();

    if 2 * m <= n {
        push(
            FlagCode::TooFewMeasurements,
            format!(
                "{m} measurement(s) give {} numbers for {n} parameters",
                2 * m
            ),
        );
    }
    if let Some(reason) = inconsistent_measurements(problem) {
        push(FlagCode::InconsistentMeasurements, reason);
    }
    if let Some(reason) = misfit_too_high(problem, ev) {
        push(FlagCode::HighMisfit, reason);
    }
    if ev.determined.curvature_unknown {
        push(
            FlagCode::UnstableRoot,
            "the finite-difference Jacobian could not be evaluated at the optimum on any \
             solve path or step: the intervals are the search range"
                .to_string(),
        );
    }
    let hz = |r: &Root| format!("{:.0} Hz", r.omega / std::f64::consts::TAU);
    let out_hz: Vec<String> = ev
        .roots
        .iter()
        .filter(|r| r.flags.out_of_validity)
        .map(hz)
        .collect();
    if !out_hz.is_empty() {
        push(
            FlagCode::OutOfValidity,
            format!(
                "{} above half the ring or fluid cut-on frequency (eq. P7)",
                out_hz.join(", ")
            ),
        );
    }
    let speed_std = ev.leak_band_speed.map(|s| s.std);
    if let Some(sep) = &ev.separated {
        let here = ev.leak_band_speed.map(|s| s.value);
        let same = match (here, sep.other_leak_band_speed) {
            (Some(a), Some(b)) => {
                let d = (a - b).abs();
                d <= SAME_SPEED_RTOL * a || d <= SAME_SPEED_SIGMAS * speed_std.unwrap_or(0.0)
            }
            _ => false,
        };
        let speeds = match (here, sep.other_leak_band_speed) {
            (Some(a), Some(b)) => format!("; leak-band speeds {} and {} m/s", sig(a, 4), sig(b, 4)),
            _ => String::new(),
        };
        if same {
            push(
                FlagCode::EquivalentMinima,
                format!("{}{speeds}", sep.description),
            );
        } else {
            push(
                FlagCode::MultipleMinima,
                format!("{}{speeds}", sep.description),
            );
        }
    }
    if let Some(reason) = speed_uncertain(ev.leak_band_speed) {
        push(FlagCode::SpeedUncertain, reason);
    }
    soil_notes(ev, &mut push);
    let grazing: Vec<String> = ev
        .roots
        .iter()
        .filter(|r| r.flags.near_grazing)
        .map(hz)
        .collect();
    if !grazing.is_empty() {
        push(
            FlagCode::NearGrazing,
            format!(
                "predicted wave within 2 % of a soil wave speed at {}",
                grazing.join(", ")
            ),
        );
    }
    out.sort_by_key(|f| (f.code.severity() == Severity::Note, f.code));
    out
}

/// Measured speeds a pipe of this material and wall cannot have.
fn inconsistent_measurements(problem: &Problem<'_>) -> Option<String> {
    let data = problem.data;
    let c_fluid = data.fluid.sound_speed();
    let mut pipe = data.pipe;
    if let Some(mat) = data.material {
        pipe.youngs_modulus = mat.youngs_modulus_range().1;
    }
    let sys_k = System {
        fluid: data.fluid,
        pipe,
        soil: Soil::none(),
        contact: 0.0,
        model: problem.model,
        contact_mode: problem.contact_mode,
    };
    let c_low = MIN_SPEED_FRACTION_OF_KORTEWEG * korteweg_speed(&sys_k);
    let bad: Vec<String> = data
        .measurements
        .iter()
        .filter(|meas| {
            let c = meas.phase_speed();
            c > c_fluid || c < c_low
        })
        .map(|meas| {
            format!(
                "{:.0} m/s at {:.0} Hz",
                meas.phase_speed(),
                meas.omega / std::f64::consts::TAU
            )
        })
        .collect();
    (!bad.is_empty()).then(|| {
        format!(
            "measured speed {} outside {:.0}-{:.0} m/s possible for this pipe",
            bad.join(", "),
            c_low,
            c_fluid
        )
    })
}

/// The misfit against the noise (chi-square tail), or against fixed relative tolerances when
/// no standard deviations are given.
fn misfit_too_high(problem: &Problem<'_>, ev: &Evidence<'_>) -> Option<String> {
    let data = problem.data;
    let m = data.measurements.len();
    let n = problem.specs.len();
    match problem.weighting {
        Weighting::ChiSquare => {
            let dof = (2 * m).saturating_sub(n);
            if dof == 0 {
                return None;
            }
            let chi2 = ev.chi2_per_dof.unwrap_or(f64::NAN) * dof as f64;
            let p = chi2_upper_tail(chi2, dof as f64);
            (p.is_nan() || p < MISFIT_P_VALUE).then(|| {
                format!(
                    "chi-square {chi2:.1} for {dof} degrees of freedom (p = {p:.1e}): the model does not explain the data within the stated noise"
                )
            })
        }
        Weighting::Relative => {
            let (mut s_re, mut s_att) = (0.0, 0.0);
            for (meas, k) in data.measurements.iter().zip(ev.predicted) {
                s_re += ((k.re - meas.k_re) / meas.k_re).powi(2);
                s_att += ((-k.im - meas.attenuation) / meas.attenuation.max(1e-12)).powi(2);
            }
            let (rms_re, rms_att) = ((s_re / m as f64).sqrt(), (s_att / m as f64).sqrt());
            (rms_re > RELATIVE_SPEED_RMS_MAX || rms_att > RELATIVE_ATTENUATION_RMS_MAX).then(|| {
                format!(
                    "RMS relative error {:.1} % in Re k and {:.0} % in attenuation (no standard deviations given)",
                    100.0 * rms_re,
                    100.0 * rms_att
                )
            })
        }
    }
}

/// Notes on what the data leave undetermined (model §7.10), and on intervals at their bounds.
fn soil_notes(ev: &Evidence<'_>, push: &mut impl FnMut(FlagCode, String)) {
    let problem = ev.problem;
    let d = ev.determined;
    let interval_of = |p: Param| {
        problem
            .specs
            .iter()
            .position(|s| s.param == p)
            .map(|i| (i, d.intervals[i]))
    };
    let (Some((_, e)), Some((_, nu))) = (
        interval_of(Param::SoilModulus),
        interval_of(Param::SoilPoisson),
    ) else {
        return;
    };
    let e_known = e.hi / e.lo <= MODULUS_DETERMINED_RATIO
        && !(e.reaches_lower_bound || e.reaches_upper_bound);
    let nu_known = nu.hi - nu.lo <= POISSON_DETERMINED_WIDTH;
    let (cp, cs) = (d.p_wave_speed, d.s_wave_speed);
    let fmt_speed =
        |name: &str, s: WithError| format!("{name} = {} ± {} m/s", sig(s.value, 3), sig(s.std, 2));
    let range = format!(
        "95 % intervals: E_m {}-{} Pa, nu_m {:.2}-{:.2}",
        sig(e.lo, 2),
        sig(e.hi, 2),
        nu.lo,
        nu.hi
    );
    if !(e_known && nu_known) {
        let cp_known = cp.relative() <= SPEED_DETERMINED_RSTD;
        let cs_known = cs.relative() <= SPEED_DETERMINED_RSTD;
        let (code, what) = match (cp_known, cs_known) {
            (true, false) => (
                FlagCode::SoilViaCp,
                format!("E_m and nu_m known only through {}", fmt_speed("c_P", cp)),
            ),
            (false, true) => (
                FlagCode::SoilViaCs,
                format!("E_m and nu_m known only through {}", fmt_speed("c_S", cs)),
            ),
            (true, true) => (
                FlagCode::SoilViaSpeeds,
                format!(
                    "E_m and nu_m known through {} and {}",
                    fmt_speed("c_P", cp),
                    fmt_speed("c_S", cs)
                ),
            ),
            (false, false) => (
                FlagCode::SoilUndetermined,
                format!(
                    "the soil is not determined ({}, {})",
                    fmt_speed("c_P", cp),
                    fmt_speed("c_S", cs)
                ),
            ),
        };
        push(code, format!("{what} ({range})"));
    }
    let mut at = Vec::new();
    for (i, s) in problem.specs.iter().enumerate() {
        let iv = d.intervals[i];
        let width_fraction =
            (s.coordinate(iv.hi) - s.coordinate(iv.lo)).abs() / (s.upper - s.lower);
        match s.param {
            Param::Contact if width_fraction > RANGE_DETERMINED_FRACTION => push(
                FlagCode::ContactUndetermined,
                format!("contact 95 % interval {:.2}-{:.2}", iv.lo, iv.hi),
            ),
            Param::Effect(_) if width_fraction > RANGE_DETERMINED_FRACTION => push(
                FlagCode::EffectUndetermined,
                format!(
                    "{} 95 % interval {}-{}",
                    s.param.name(),
                    sig(iv.lo, 2),
                    sig(iv.hi, 2)
                ),
            ),
            _ => {}
        }
        // The contact coefficient's ends 0 and 1 are physical (lubricated, bonded), and an
        // effect's neutral end means "absent": neither is worth a note.
        let neutral_end_low = matches!(
            s.param,
            Param::Contact
                | Param::Effect(Effect::AirInWater | Effect::SoilDamping | Effect::PipeLoss)
        );
        let neutral_end_high = matches!(
            s.param,
            Param::Contact | Param::Effect(Effect::WallThinning)
        );
        let lo = iv.reaches_lower_bound && !neutral_end_low;
        let hi = iv.reaches_upper_bound && !neutral_end_high;
        if lo || hi {
            at.push(format!(
                "{} interval {}-{} reaches its {} bound",
                s.param.name(),
                sig(iv.lo, 3),
                sig(iv.hi, 3),
                match (lo, hi) {
                    (true, true) => "lower and upper",
                    (true, false) => "lower",
                    _ => "upper",
                }
            ));
        }
    }
    if !at.is_empty() {
        push(FlagCode::AtBound, at.join("; "));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_unique_and_flags_sort_first() {
        let names: std::collections::BTreeSet<&str> =
            FlagCode::ALL.iter().map(|c| c.as_str()).collect();
        assert_eq!(names.len(), FlagCode::ALL.len());
        let flags = FlagCode::ALL
            .iter()
            .filter(|c| c.severity() == Severity::Flag)
            .count();
        assert_eq!(flags, 8);
    }

    #[test]
    fn every_code_has_its_own_advice() {
        let advice: std::collections::BTreeSet<&str> =
            FlagCode::ALL.iter().map(|c| c.advice()).collect();
        assert_eq!(advice.len(), FlagCode::ALL.len());
        assert!(FlagCode::ALL.contains(&FlagCode::FieldOutlier));
        assert!(FlagCode::FieldOutlier
            .advice()
            .contains(&format!("{:.2}", crate::field::FIELD_OUTLIER_Z)));
    }
}
