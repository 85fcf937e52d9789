//! Honest errors where the model does not explain the data (model §7.13): coverage of the
//! truth by the corrected curve over many synthetic segments hiding effects the fit lacks,
//! fits the model explains left alone, the two published real cases, and what a user sees:
//! `fits.curve_source`, the model-only curve kept beside the corrected one, the export
//! column, and `run --diagnose`.

mod cli_run;
use cli_run::run_ok;

use pipewave::invert::{fit_segment, CurveSource, FitSettings};
use pipewave::physics::effects::Effect;
use pipewave::synth::honesty::{check_measured, summarize, trials, TrialCheck};
use pipewave::synth::network::published::{lu2022, muggleton2004};
use pipewave::synth::network::NetworkTables;
use pipewave::types::FitStatus;

/// Trials per hidden effect (the acceptance figures of docs/honest-errors.md use 60).
const TRIALS: usize = 10;

#[test]
fn the_corrected_curve_covers_the_truth_and_is_sharper_than_the_data() {
    let settings = FitSettings::default();
    let mut all: Vec<TrialCheck> = Vec::new();
    for (k, e) in [
        Effect::SoilDamping,
        Effect::AirInWater,
        Effect::WallThinning,
        Effect::PipeLoss,
        Effect::ViscoelasticWall,
    ]
    .into_iter()
    .enumerate()
    {
        let checks = trials(Some(e), TRIALS, 7_000_000 + 1000 * k as u64, &settings);
        let s = summarize(&checks);
        // Per effect, loose for ten trials: most true speeds within 2σ, and the corrected
        // curve no further from the truth than the data.
        assert!(s.point_coverage >= 0.75, "{e:?}: {s:?}");
        assert!(s.band_coverage >= 0.7, "{e:?}: {s:?}");
        assert!(
            s.median_curve_error <= s.median_measured_error,
            "{e:?}: {s:?}"
        );
        all.extend(checks);
    }
    let s = summarize(&all);
    assert!(s.corrected > all.len() / 3, "{s:?}");
    assert!(
        (0.85..=0.98).contains(&s.point_coverage),
        "pooled coverage at the measured frequencies {s:?}"
    );
    assert!(s.band_coverage >= 0.85, "pooled leak-band coverage {s:?}");
    assert!(s.median_curve_error <= s.median_measured_error, "{s:?}");
    // Every corrected fit is a high_misfit one, every other keeps the model's curve.
    for c in &all {
        assert_eq!(
            c.corrected(),
            c.fit.has_flag(pipewave::invert::FlagCode::HighMisfit),
            "{:?}",
            c.hidden
        );
        for p in &c.fit.curve {
            if c.corrected() {
                assert!(p.model_phase_speed.is_some() || p.phase_speed.is_none());
            } else {
                assert_eq!(p.phase_speed, p.model_phase_speed);
                assert_eq!(p.attenuation_db, p.model_attenuation_db);
            }
        }
    }
}

#[test]
fn fits_the_model_explains_keep_their_errors() {
    let checks = trials(None, TRIALS, 7_100_000, &FitSettings::default());
    let ok: Vec<&TrialCheck> = checks
        .iter()
        .filter(|c| c.fit.status == FitStatus::Ok)
        .collect();
    assert!(ok.len() >= TRIALS / 2, "{} ok fits", ok.len());
    for c in ok {
        assert_eq!(c.fit.curve_source, CurveSource::Model);
        assert!(c
            .fit
            .curve
            .iter()
            .all(|p| p.phase_speed == p.model_phase_speed));
    }
}

#[test]
fn the_published_cases_lie_within_their_curves() {
    let settings = FitSettings::default();
    let lu = lu2022().unwrap();
    let data = lu.segment_data().unwrap();
    let fit = fit_segment(&data, &settings, 1);
    assert_eq!(fit.curve_source, CurveSource::ModelPlusDiscrepancy);
    let m = check_measured(&fit, &data);
    assert_eq!(m.points.len(), 4);
    assert!(m.within() >= 3, "{m:?}");
    assert_eq!(m.band_consistent, Some(true), "{m:?}");
    // The leak band lies below the measured 497-1642 Hz: 2.3 octaves of extrapolation.
    let x = fit.leak_band_extrapolation_octaves.unwrap();
    assert!((x - (497.0f64 / 100.0).log2()).abs() < 0.01, "{x}");
    // The band speed's error says at least what the measured speeds scatter (2-3 %).
    let b = fit.leak_band_speed.unwrap();
    assert!(b.std / b.value > 0.01, "{b:?}");

    let mdpe = muggleton2004().unwrap();
    let data = mdpe.segment_data().unwrap();
    let fit = fit_segment(&data, &settings, 1);
    assert_eq!(fit.curve_source, CurveSource::ModelPlusDiscrepancy);
    let m = check_measured(&fit, &data);
    assert!(4 * m.within() >= 3 * m.points.len(), "{m:?}");
    assert_eq!(m.band_consistent, Some(true), "{m:?}");
}

#[test]
fn a_user_sees_the_corrected_speed_its_source_and_the_model_curve() {
    let dir = tempfile::tempdir().unwrap();
    let net = dir.path().join("net");
    let mut t = NetworkTables::default();
    t.push_published(lu2022().unwrap());
    t.write_dir(&net).unwrap();
    let out = run_ok(&["run", net.to_str().unwrap(), "--jobs", "1", "--diagnose"]);
    assert!(
        out.contains("run --diagnose: 1 segments diagnosed"),
        "{out}"
    );
    assert!(net.join("out/diagnosis/diagnosis.csv").is_file());

    let conn = rusqlite::Connection::open(net.join("pipewave.sqlite")).unwrap();
    let (source, run_id, std, extra): (String, i64, f64, f64) = conn
        .query_row(
            "SELECT curve_source, run_id, leak_band_speed_std_m_per_s, \
             leak_band_extrapolation_octaves FROM latest_fits",
            [],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)),
        )
        .unwrap();
    assert_eq!(source, "model+discrepancy");
    assert!(std > 10.0, "{std}");
    assert!(extra > 2.0, "{extra}");
    // The model-only curve stays beside the corrected one (the model lies 3-9 % above the
    // measured speeds of this main; the corrected curve follows them).
    let (c, model): (f64, f64) = conn
        .query_row(
            "SELECT phase_speed_m_per_s, model_phase_speed_m_per_s FROM curves \
             WHERE run_id = ?1 AND frequency_hz = 500",
            [run_id],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .unwrap();
    assert!(model > c * 1.02, "{c} {model}");
    let mut csv = csv::Reader::from_path(net.join("out/segments.csv")).unwrap();
    let col = csv
        .headers()
        .unwrap()
        .iter()
        .position(|h| h == "curve_source")
        .unwrap();
    let row = csv.records().next().unwrap().unwrap();
    assert_eq!(&row[col], "model+discrepancy");
}
