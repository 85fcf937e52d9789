//! Honest errors where the model does not explain the data (model §7.13): every figure of
//! docs/honest-errors.md.
//!
//! * For each effect `synth --hidden-effect` supports (viscoelastic_wall on plastics) and for
//!   controls without one: N synthetic trials fitted without the effect. Printed over all trials
//!   and over the corrected ones (`high_misfit`, curve `model+discrepancy`): the share of measured
//!   points whose true phase speed lies within the curve's 2σ, the share of trials whose true
//!   leak-band speed lies within its 2σ, the median |error| of the curve and of the raw measured
//!   speeds at the measured frequencies, the share of true c_P within 2σ, and the median
//!   relative σ of the curve.
//! * The two published real cases: the measured speeds within 2σ of the curve, and whether the
//!   leak-band speed agrees with the measured speeds in the leak band.
//!
//! Run: `cargo run --release --example honest_errors -- [N] [BASE]` (default N = 60, BASE = 0).

use pipewave::invert::{fit_segment, FitSettings};
use pipewave::physics::effects::Effect;
use pipewave::synth::honesty::{check_measured, summarize, trials, Summary, TrialCheck};
use pipewave::synth::network::published::{lu2022, muggleton2004};
use pipewave::types::FitStatus;

fn row(name: &str, s: &Summary) {
    println!(
        "{name:<18} {:>4} {:>5} {:>8.1} {:>8.1} {:>9.2} {:>9.2} {:>7.1} {:>8.2}",
        s.trials,
        s.corrected,
        100.0 * s.point_coverage,
        100.0 * s.band_coverage,
        100.0 * s.median_curve_error,
        100.0 * s.median_measured_error,
        100.0 * s.cp_coverage,
        100.0 * s.median_relative_std,
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(60);
    let base: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(0);
    let settings = FitSettings::default();
    println!(
        "{:<18} {:>4} {:>5} {:>8} {:>8} {:>9} {:>9} {:>7} {:>8}",
        "hidden effect", "n", "corr", "pts2σ%", "band2σ%", "|curve|%", "|meas|%", "cP2σ%", "σ/c %"
    );
    let effects = [
        None,
        Some(Effect::SoilDamping),
        Some(Effect::AirInWater),
        Some(Effect::WallThinning),
        Some(Effect::PipeLoss),
        Some(Effect::ViscoelasticWall),
    ];
    for (k, e) in effects.into_iter().enumerate() {
        let checks = trials(e, n, base + 100_000 * k as u64, &settings);
        let name = e.map_or("none (controls)", |e| e.name());
        row(name, &summarize(&checks));
        let corrected: Vec<TrialCheck> = checks.iter().filter(|c| c.corrected()).cloned().collect();
        row("  corrected only", &summarize(&corrected));
        let ok: Vec<TrialCheck> = checks
            .iter()
            .filter(|c| c.fit.status == FitStatus::Ok)
            .cloned()
            .collect();
        row("  ok only", &summarize(&ok));
    }
    for case in [
        lu2022().expect("embedded"),
        muggleton2004().expect("embedded"),
    ] {
        let data = case.segment_data().expect("valid case");
        let fit = fit_segment(&data, &settings, 1);
        let m = check_measured(&fit, &data);
        println!(
            "{}: curve {}, {} of {} measured speeds within 2σ, leak-band speed {} ± {} m/s \
             (extrapolates {:.2} octaves), consistent with the measured speeds in the band: {:?}",
            case.segment.segment_id,
            fit.curve_source.as_str(),
            m.within(),
            m.points.len(),
            fit.leak_band_speed.map_or(f64::NAN, |b| b.value.round()),
            fit.leak_band_speed.map_or(f64::NAN, |b| b.std.round()),
            fit.leak_band_extrapolation_octaves.unwrap_or(f64::NAN),
            m.band_consistent
        );
        for (f, c, at) in &m.points {
            println!(
                "    {f:>7.1} Hz: measured {c:>7.1}, curve {:>7.1} ± {:>5.1} m/s",
                at.value, at.std
            );
        }
    }
}
