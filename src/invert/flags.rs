//! Flags that say when a fit should not be trusted, each with a code and a one-line reason.

use std::fmt;

use super::fit::FitResult;
use super::problem::{Param, Problem, Scale, Weighting};
use crate::physics::dispersion::korteweg_speed;
use crate::physics::effects::Effect;
use crate::physics::solver::{solve_curve, Continuation, Tolerance};
use crate::physics::{Soil, System};
use crate::units::sig;

/// A chi-square whose upper-tail probability is below this is too high for the stated noise.
pub const MISFIT_P_VALUE: f64 = 1e-3;
/// Without standard deviations: RMS relative error of Re k above which the fit is poor.
pub const RELATIVE_SPEED_RMS_MAX: f64 = 0.02;
/// Without standard deviations: RMS relative error of the attenuation above which it is poor.
pub const RELATIVE_ATTENUATION_RMS_MAX: f64 = 0.3;
/// A coordinate within this fraction of its range from a bound is "at the bound".
pub const AT_BOUND_FRACTION: f64 = 1e-3;
/// Condition number of the column-scaled Jacobian above which the fit is ill-conditioned.
pub const CONDITION_MAX: f64 = 1e4;
/// Relative one-sigma error of E_m above which the soil modulus is flagged as uncertain.
pub const MODULUS_RSTD_MAX: f64 = 0.1;
/// A measured phase speed below this fraction of the Korteweg speed of the stiffest plausible
/// wall of the material cannot be the s = 1 wave of that pipe.
pub const MIN_SPEED_FRACTION_OF_KORTEWEG: f64 = 0.5;

/// Flag codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FlagCode {
    /// Misfit too high for the stated noise.
    HighMisfit,
    /// A parameter at its bound.
    AtBound,
    /// The Jacobian is ill-conditioned.
    IllConditioned,
    /// A parameter's uncertainty spans most of its range (its std is not reported).
    Unidentifiable,
    /// The soil modulus is uncertain by more than 10 %.
    ModulusUncertain,
    /// Restarts found equally good, separated minima.
    MultipleMinima,
    /// Fewer numbers than parameters.
    TooFewMeasurements,
    /// A measured speed no pipe of that material could have.
    InconsistentMeasurements,
    /// A predicted root near grazing (numerically fragile).
    NearGrazing,
    /// A measured frequency outside the model's validity.
    OutOfValidity,
}

impl FlagCode {
    /// The code stored in `fits.flags`.
    pub fn as_str(self) -> &'static str {
        match self {
            FlagCode::HighMisfit => "high_misfit",
            FlagCode::AtBound => "at_bound",
            FlagCode::IllConditioned => "ill_conditioned",
            FlagCode::Unidentifiable => "unidentifiable",
            FlagCode::ModulusUncertain => "modulus_uncertain",
            FlagCode::MultipleMinima => "multiple_minima",
            FlagCode::TooFewMeasurements => "too_few_measurements",
            FlagCode::InconsistentMeasurements => "inconsistent_measurements",
            FlagCode::NearGrazing => "near_grazing",
            FlagCode::OutOfValidity => "out_of_validity",
        }
    }

    /// Every code.
    pub const ALL: [FlagCode; 10] = [
        FlagCode::HighMisfit,
        FlagCode::AtBound,
        FlagCode::IllConditioned,
        FlagCode::Unidentifiable,
        FlagCode::ModulusUncertain,
        FlagCode::MultipleMinima,
        FlagCode::TooFewMeasurements,
        FlagCode::InconsistentMeasurements,
        FlagCode::NearGrazing,
        FlagCode::OutOfValidity,
    ];
}

impl fmt::Display for FlagCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A raised flag.
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

/// Assess a fit. `separated` is the multiple-minima finding of the restarts, if any.
pub fn assess(problem: &Problem<'_>, r: &FitResult, separated: Option<String>) -> Vec<Flag> {
    let mut flags = Vec::new();
    let mut push = |code, reason: String| flags.push(Flag { code, reason });
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

    // Measured speeds a pipe of this material and wall cannot have.
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
    if !bad.is_empty() {
        push(
            FlagCode::InconsistentMeasurements,
            format!(
                "measured speed {} outside {:.0}-{:.0} m/s possible for this pipe",
                bad.join(", "),
                c_low,
                c_fluid
            ),
        );
    }

    // Misfit against the noise.
    match problem.weighting {
        Weighting::ChiSquare => {
            let dof = (2 * m).saturating_sub(n);
            if dof > 0 {
                let chi2 = r.chi2_per_dof.unwrap_or(f64::NAN) * dof as f64;
                let p = chi2_upper_tail(chi2, dof as f64);
                if p.is_nan() || p < MISFIT_P_VALUE {
                    push(
                        FlagCode::HighMisfit,
                        format!(
                            "chi-square {chi2:.1} for {dof} degrees of freedom (p = {p:.1e}): the model does not explain the data within the stated noise"
                        ),
                    );
                }
            }
        }
        Weighting::Relative => {
            let (mut s_re, mut s_att) = (0.0, 0.0);
            for (meas, k) in data.measurements.iter().zip(&r.predicted) {
                s_re += ((k.re - meas.k_re) / meas.k_re).powi(2);
                s_att += ((-k.im - meas.attenuation) / meas.attenuation.max(1e-12)).powi(2);
            }
            let (rms_re, rms_att) = ((s_re / m as f64).sqrt(), (s_att / m as f64).sqrt());
            if rms_re > RELATIVE_SPEED_RMS_MAX || rms_att > RELATIVE_ATTENUATION_RMS_MAX {
                push(
                    FlagCode::HighMisfit,
                    format!(
                        "RMS relative error {:.1} % in Re k and {:.0} % in attenuation (no standard deviations given)",
                        100.0 * rms_re,
                        100.0 * rms_att
                    ),
                );
            }
        }
    }

    // Parameters at a bound (not the neutral end of an effect, and not the contact
    // coefficient, whose ends 0 and 1 are physical: lubricated and bonded).
    let mut at = Vec::new();
    for (s, e) in problem.specs.iter().zip(&r.estimates) {
        let w = s.upper - s.lower;
        let lo = e.coordinate - s.lower <= AT_BOUND_FRACTION * w;
        let hi = s.upper - e.coordinate <= AT_BOUND_FRACTION * w;
        let flagged = match s.param {
            Param::SoilModulus | Param::SoilPoisson => lo || hi,
            Param::Contact => false,
            Param::Effect(Effect::WallThinning) => lo,
            Param::Effect(Effect::AirInWater) => hi,
            Param::Effect(_) => hi,
        };
        if flagged {
            at.push(format!(
                "{} = {} at its {} bound",
                s.param.name(),
                sig(e.value, 4),
                if lo { "lower" } else { "upper" }
            ));
        }
    }
    if !at.is_empty() {
        push(FlagCode::AtBound, at.join("; "));
    }

    if let Some(c) = r.condition_number {
        if c.is_nan() || c > CONDITION_MAX {
            push(
                FlagCode::IllConditioned,
                format!("scaled Jacobian condition number {c:.2e}: parameters trade off against each other"),
            );
        }
    }
    let unident: Vec<&str> = r
        .estimates
        .iter()
        .filter(|e| e.std.is_none())
        .map(|e| e.param.name())
        .collect();
    if !unident.is_empty() {
        push(
            FlagCode::Unidentifiable,
            format!(
                "{} not constrained by the data (uncertainty spans most of the range)",
                unident.join(", ")
            ),
        );
    }
    if let Some(e) = r.get(Param::SoilModulus) {
        let rstd = match e.std {
            Some(s) => s / e.value,
            None => f64::INFINITY,
        };
        let spec_is_log = problem
            .specs
            .iter()
            .any(|s| s.param == Param::SoilModulus && s.scale == Scale::Log10);
        if rstd > MODULUS_RSTD_MAX && e.std.is_some() {
            push(
                FlagCode::ModulusUncertain,
                format!(
                    "soil modulus {} Pa uncertain by {:.0} % (one sigma{})",
                    sig(e.value, 3),
                    100.0 * rstd,
                    if spec_is_log { ", from log10 E" } else { "" }
                ),
            );
        }
    }
    if let Some(msg) = separated {
        push(FlagCode::MultipleMinima, msg);
    }

    // Root warnings at the optimum.
    if let Some(sys) = &r.system {
        let omegas: Vec<f64> = data.measurements.iter().map(|m| m.omega).collect();
        let roots = solve_curve(
            sys,
            &omegas,
            Continuation {
                ramp_points: 8,
                tolerance: Tolerance::FAST,
            },
        );
        let grazing: Vec<String> = roots
            .iter()
            .filter_map(|x| x.as_ref().ok())
            .filter(|x| x.flags.near_grazing)
            .map(|x| format!("{:.0} Hz", x.omega / std::f64::consts::TAU))
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
        let out: Vec<String> = roots
            .iter()
            .filter_map(|x| x.as_ref().ok())
            .filter(|x| x.flags.out_of_validity)
            .map(|x| format!("{:.0} Hz", x.omega / std::f64::consts::TAU))
            .collect();
        if !out.is_empty() {
            push(
                FlagCode::OutOfValidity,
                format!(
                    "{} above half the ring or fluid cut-on frequency (eq. P7)",
                    out.join(", ")
                ),
            );
        }
    }
    flags
}

/// Upper-tail probability P(χ²_k > x) by the Wilson–Hilferty cube-root normal approximation
/// (accurate to a few 1e-3 in the tail for k ≥ 3, ample for a 1e-3 threshold).
pub fn chi2_upper_tail(x: f64, k: f64) -> f64 {
    if !(x.is_finite() && k > 0.0) {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    let v = 2.0 / (9.0 * k);
    let z = ((x / k).cbrt() - (1.0 - v)) / v.sqrt();
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// Complementary error function, Numerical Recipes' `erfcc` (Chebyshev fit, relative error
/// below 1.2e-7 everywhere).
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let ans = t
        * (-z * z - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87
                                        + t * (-0.822_152_23 + t * 0.170_872_77)))))))))
            .exp();
    if x >= 0.0 {
        ans
    } else {
        2.0 - ans
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erfc_and_chi2_tail_match_tables() {
        // erfc(0.5) = 0.4795001221869535, erfc(2) = 0.004677734981047266.
        assert!((erfc(0.5) - 0.479_500_122_186_953_5).abs() < 1e-7);
        assert!((erfc(2.0) / 0.004_677_734_981_047_266 - 1.0).abs() < 1e-6);
        assert!((erfc(-1.0) - 1.842_700_792_949_715).abs() < 1e-7);
        // chi-square 0.999 quantiles: k = 5: 20.515; k = 13: 34.528; k = 1e3 approx 1143.9.
        for (x, k) in [(20.515, 5.0), (34.528, 13.0), (1143.917, 1000.0)] {
            let p = chi2_upper_tail(x, k);
            assert!((p - 1e-3).abs() < 0.15e-3, "k = {k}: p = {p}");
        }
        // Median of chi-square(10) is 9.342.
        assert!((chi2_upper_tail(9.342, 10.0) - 0.5).abs() < 0.005);
    }
}
