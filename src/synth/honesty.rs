//! How honest a fit's errors are, against the truth of synthetic trials (model §7.13): at the
//! measured frequencies, whether the true phase speed lies within 2σ of the fitted curve and
//! how far the curve is from it beside the raw measured speed; the same for the leak-band
//! speed and the soil speeds c_P, c_S.
//!
//! A trial is a pipe of the synthetic network's catalogue in a random soil of its classes,
//! with an effect the fit does not model hidden in the data ([`crate::synth::trial`]), fitted
//! with the default settings, as a first nightly run fits it.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::invert::assemble::leak_band_speed_of;
use crate::invert::uncertainty::WithError;
use crate::invert::{fit_segment, CurveSource, FitResult, FitSettings};
use crate::physics::curves::curve;
use crate::physics::effects::Effect;
use crate::physics::{Material, System};
use crate::synth::{default_hidden_range, MATERIAL_MIX};
use crate::types::FitStatus;

/// Coverage factor of the checks: "within 2σ".
pub const COVERAGE_SIGMAS: f64 = 2.0;

/// One measured frequency of a trial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointCheck {
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// The true phase speed, m/s.
    pub truth: f64,
    /// The measured phase speed ω/Re k, m/s.
    pub measured: f64,
    /// The fitted curve there (interpolated in ln f on the stored grid), with its error.
    pub curve: WithError,
}

impl PointCheck {
    /// Whether the truth lies within [`COVERAGE_SIGMAS`] σ of the curve.
    pub fn covered(&self) -> bool {
        (self.curve.value - self.truth).abs() <= COVERAGE_SIGMAS * self.curve.std
    }
    /// Whether the measured speed lies within [`COVERAGE_SIGMAS`] σ of the curve.
    pub fn measured_within(&self) -> bool {
        (self.curve.value - self.measured).abs() <= COVERAGE_SIGMAS * self.curve.std
    }
}

/// A fit judged against its truth.
#[derive(Debug, Clone)]
pub struct TrialCheck {
    /// The hidden effect, if any.
    pub hidden: Option<(Effect, f64)>,
    /// The pipe's material.
    pub material: Material,
    /// The fit.
    pub fit: FitResult,
    /// One check per measured frequency where the curve has a value.
    pub points: Vec<PointCheck>,
    /// The true leak-band speed and the fitted one, m/s.
    pub band: Option<(f64, WithError)>,
    /// The true soil speeds (c_P, c_S), m/s.
    pub soil: (f64, f64),
}

impl TrialCheck {
    /// Whether the fit's curve was corrected by a discrepancy.
    pub fn corrected(&self) -> bool {
        self.fit.curve_source == CurveSource::ModelPlusDiscrepancy
    }
    /// Whether the true leak-band speed lies within 2σ of the fitted one.
    pub fn band_covered(&self) -> Option<bool> {
        self.band
            .map(|(t, b)| (b.value - t).abs() <= COVERAGE_SIGMAS * b.std)
    }
}

/// A stored curve's value and error at `f_hz`, linear in ln f between its grid points.
pub fn curve_at(fit: &FitResult, f_hz: f64) -> Option<WithError> {
    let pts: Vec<(f64, f64, f64)> = fit
        .curve
        .iter()
        .filter_map(|p| Some((p.frequency_hz.ln(), p.phase_speed?, p.phase_speed_std?)))
        .collect();
    let x = f_hz.ln();
    let i = pts.windows(2).position(|w| w[0].0 <= x && x <= w[1].0)?;
    let (a, b) = (pts[i], pts[i + 1]);
    let t = (x - a.0) / (b.0 - a.0);
    Some(WithError {
        value: a.1 + t * (b.1 - a.1),
        std: a.2 + t * (b.2 - a.2),
    })
}

/// Judge `fit` of the data measured on `truth`.
pub fn check(
    fit: FitResult,
    data: &crate::invert::SegmentData,
    truth: &System,
    hidden: Option<(Effect, f64)>,
    material: Material,
) -> TrialCheck {
    let freqs: Vec<f64> = data
        .measurements
        .iter()
        .map(|m| m.omega / std::f64::consts::TAU)
        .collect();
    let true_curve = curve(truth, &freqs);
    let points = data
        .measurements
        .iter()
        .zip(&true_curve)
        .filter_map(|(m, t)| {
            let f = m.omega / std::f64::consts::TAU;
            Some(PointCheck {
                frequency_hz: f,
                truth: t.status.is_ok().then_some(t.phase_speed)?,
                measured: m.omega / m.k_re,
                curve: curve_at(&fit, f)?,
            })
        })
        .collect();
    let band = leak_band_speed_of(truth).zip(fit.leak_band_speed);
    TrialCheck {
        hidden,
        material,
        points,
        band,
        soil: truth.soil.wave_speeds(),
        fit,
    }
}

/// A material drawn from the synthetic network's mix, plastics only if asked.
fn pick_material<R: Rng>(rng: &mut R, plastic_only: bool) -> Material {
    let mix: Vec<(Material, f64)> = MATERIAL_MIX
        .iter()
        .copied()
        .filter(|(m, _)| !plastic_only || m.is_plastic())
        .collect();
    let total: f64 = mix.iter().map(|m| m.1).sum();
    let mut u = rng.gen::<f64>() * total;
    for (m, w) in &mix {
        if u < *w {
            return *m;
        }
        u -= w;
    }
    mix[mix.len() - 1].0
}

/// `n` trials hiding `effect` (none: controls) at values of its default range, on the
/// materials it applies to (viscoelastic_wall: plastics), fitted with `settings`; trial `i`
/// uses seed `base + i`, whatever the thread count.
pub fn trials(
    effect: Option<Effect>,
    n: usize,
    base: u64,
    settings: &FitSettings,
) -> Vec<TrialCheck> {
    (0..n as u64)
        .into_par_iter()
        .map(|i| {
            let mut rng = ChaCha8Rng::seed_from_u64(base + i);
            loop {
                let m = pick_material(&mut rng, effect == Some(Effect::ViscoelasticWall));
                let hidden = effect.and_then(|e| {
                    let (lo, hi) = default_hidden_range(e)?;
                    let v = if e == Effect::AirInWater {
                        (lo.ln() + rng.gen::<f64>() * (hi.ln() - lo.ln())).exp()
                    } else {
                        rng.gen_range(lo..hi)
                    };
                    Some((e, v))
                });
                let Some(t) = crate::synth::trial::effect_trial(&mut rng, m, hidden) else {
                    continue;
                };
                let fit = fit_segment(&t.data, settings, base + i);
                if fit.status == FitStatus::Failed {
                    continue;
                }
                return check(fit, &t.data, &t.true_system, hidden, m);
            }
        })
        .collect()
}

/// The acceptance figures of a set of trials.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Summary {
    /// Trials.
    pub trials: usize,
    /// Of which corrected by a discrepancy (`high_misfit`).
    pub corrected: usize,
    /// Share of measured points whose true speed lies within the curve's 2σ.
    pub point_coverage: f64,
    /// Share of trials whose true leak-band speed lies within its 2σ.
    pub band_coverage: f64,
    /// Median |curve − truth| / truth at the measured points.
    pub median_curve_error: f64,
    /// Median |measured − truth| / truth at the measured points.
    pub median_measured_error: f64,
    /// Share of trials whose true c_P lies within 2σ of the fitted one.
    pub cp_coverage: f64,
    /// Median relative σ of the curve at the measured points.
    pub median_relative_std: f64,
}

fn median(v: Vec<f64>) -> f64 {
    crate::synth::network::recovery::Spread::of(&v).median
}

/// Summarise `checks`.
pub fn summarize(checks: &[TrialCheck]) -> Summary {
    let pts: Vec<&PointCheck> = checks.iter().flat_map(|c| &c.points).collect();
    let share = |k: usize, n: usize| {
        if n == 0 {
            f64::NAN
        } else {
            k as f64 / n as f64
        }
    };
    let bands: Vec<bool> = checks.iter().filter_map(TrialCheck::band_covered).collect();
    let cps: Vec<bool> = checks
        .iter()
        .filter_map(|c| {
            let cp = c.fit.p_wave_speed?;
            Some((cp.value - c.soil.0).abs() <= COVERAGE_SIGMAS * cp.std)
        })
        .collect();
    Summary {
        trials: checks.len(),
        corrected: checks.iter().filter(|c| c.corrected()).count(),
        point_coverage: share(pts.iter().filter(|p| p.covered()).count(), pts.len()),
        band_coverage: share(bands.iter().filter(|&&b| b).count(), bands.len()),
        median_curve_error: median(
            pts.iter()
                .map(|p| (p.curve.value - p.truth).abs() / p.truth)
                .collect(),
        ),
        median_measured_error: median(
            pts.iter()
                .map(|p| (p.measured - p.truth).abs() / p.truth)
                .collect(),
        ),
        cp_coverage: share(cps.iter().filter(|&&b| b).count(), cps.len()),
        median_relative_std: median(pts.iter().map(|p| p.curve.std / p.curve.value).collect()),
    }
}

/// A fit of measured data judged against the data alone (real cases, no truth): at each
/// measured frequency the measured phase speed and the curve there; and whether the leak-band
/// speed agrees with the measured speeds inside the leak band (their mean within 2σ of the
/// combined error).
#[derive(Debug, Clone)]
pub struct MeasuredCheck {
    /// (frequency Hz, measured phase speed m/s, the curve there) per measured frequency.
    pub points: Vec<(f64, f64, WithError)>,
    /// The leak-band speed agrees with the measured speeds inside the leak band (`None`: no
    /// measured frequency in the band, or no leak-band speed).
    pub band_consistent: Option<bool>,
}

impl MeasuredCheck {
    /// Measured frequencies whose speed lies within 2σ of the curve.
    pub fn within(&self) -> usize {
        self.points
            .iter()
            .filter(|(_, m, c)| (c.value - m).abs() <= COVERAGE_SIGMAS * c.std)
            .count()
    }
}

/// Judge `fit` against the data it was fitted to.
pub fn check_measured(fit: &FitResult, data: &crate::invert::SegmentData) -> MeasuredCheck {
    let band = crate::physics::curves::LEAK_BAND_HZ;
    let mut points = Vec::new();
    let (mut in_band, mut var_in_band) = (Vec::new(), 0.0);
    for m in &data.measurements {
        let f = m.omega / std::f64::consts::TAU;
        let c = m.omega / m.k_re;
        let Some(at) = curve_at(fit, f) else {
            continue;
        };
        points.push((f, c, at));
        if (band.0..=band.1).contains(&f) {
            in_band.push(c);
            let rel = m.k_re_std.map_or(
                crate::invert::discrepancy::ASSUMED_RELATIVE_SPEED_STD,
                |s| s / m.k_re,
            );
            var_in_band += (c * rel).powi(2);
        }
    }
    let band_consistent = fit.leak_band_speed.and_then(|b| {
        if in_band.is_empty() {
            return None;
        }
        let n = in_band.len() as f64;
        let mean = in_band.iter().sum::<f64>() / n;
        let sigma = (b.std * b.std + var_in_band / (n * n)).sqrt();
        Some((b.value - mean).abs() <= COVERAGE_SIGMAS * sigma)
    });
    MeasuredCheck {
        points,
        band_consistent,
    }
}
