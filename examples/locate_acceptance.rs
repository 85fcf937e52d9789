//! Acceptance of `pipewave locate` (model §11) on a fresh synthetic network:
//!
//! 1. Position from a given delay: paths of 1–4 segments, spans 40–400 m, mixed materials;
//!    speeds from the segments' own fits; the delay from the TRUE soils through the P85 model
//!    plus noise σ_τ = 0.1 ms. Coverage of the 95 % interval, its median width, and on spans
//!    with a plastic segment the median error against the table-speed (Korteweg, P45) error.
//! 2. Position from recordings: 60 s at 8 kHz, sensor noise 30 %, made from the true soils;
//!    metal spans up to 300 m and plastic spans up to 150 m; median error and coverage.
//! 3. Time of one correlation from a delay and from two recordings (DB open and graph build
//!    excluded).
//!
//! Run: `cargo run --release --example locate_acceptance -- [--cases 200] [--recordings 40]
//! [--seed 11] [--segments 160] [--plastic-band LO,HI] [--verbose]`

use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

use pipewave::locate::gcc::RecordingPair;
use pipewave::locate::model::Weighting;
use pipewave::locate::{DelayInput, LocateOptions, Located, Locator, DEFAULT_BAND_HZ};
use pipewave::stats::normal;
use pipewave::synth::locate::{
    calibrated_database, case_job, draw_case, leak_recording, network_of, segment_truth,
    true_curve, true_delay, LeakSpec, DEFAULT_LEAK_NOISE_FRACTION, DEFAULT_LEAK_SAMPLE_RATE,
};
use pipewave::synth::recordings::{headroom_gain, write_wav, TruthCurve, WavFormat};
use pipewave::synth::{generate, SynthOptions};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Noise on the given delays, s.
const SIGMA_TAU_S: f64 = 1e-4;

fn arg<T: std::str::FromStr>(name: &str, default: T) -> T {
    let a: Vec<String> = std::env::args().collect();
    a.iter()
        .position(|x| x == name)
        .and_then(|i| a.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

struct Outcome {
    err: f64,
    covered: bool,
    width: f64,
    table_err: f64,
    plastic: bool,
    ms: f64,
}

impl Outcome {
    /// How a located leak compares with the truth `leak_m`.
    fn of(l: &Located, leak_m: f64, plastic: bool, ms: f64) -> Outcome {
        Outcome {
            err: (l.distance_m - leak_m).abs(),
            covered: l.lo_m <= leak_m && leak_m <= l.hi_m,
            width: l.hi_m - l.lo_m,
            table_err: (l.table_distance_m - leak_m).abs(),
            plastic,
            ms,
        }
    }
}

fn main() {
    let cases: usize = arg("--cases", 200);
    let n_rec: usize = arg("--recordings", 40);
    let seed: u64 = arg("--seed", 11);
    let segments: usize = arg("--segments", 160);
    let verbose = std::env::args().any(|a| a == "--verbose");
    let plastic_band: Option<(f64, f64)> = {
        let t: String = arg("--plastic-band", String::new());
        let v: Vec<f64> = t.split(',').filter_map(|x| x.parse().ok()).collect();
        (v.len() == 2).then(|| (v[0], v[1]))
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let opts = SynthOptions {
        segments,
        seed,
        defect_fraction: 0.0,
        ..SynthOptions::default()
    };
    let network = generate(&opts);
    let t0 = Instant::now();
    let database = calibrated_database(dir.path(), &network, &opts, 2).expect("network");
    eprintln!(
        "network: {} segments, seed {seed}, imported and calibrated in {:.1} s",
        network.len(),
        t0.elapsed().as_secs_f64()
    );
    let net = network_of(&network, &opts);
    let conn = database.conn();
    let mut truths: HashMap<usize, TruthCurve> = HashMap::new();
    let fill = |truths: &mut HashMap<usize, TruthCurve>, segs: &[usize]| {
        for &s in segs {
            truths.entry(s).or_insert_with(|| {
                segment_truth(&network[s], &opts, DEFAULT_LEAK_SAMPLE_RATE).expect("truth")
            });
        }
    };
    let plastic = |s: usize| network[s].material.is_plastic();
    // 1. Given delays.
    let plain = !std::env::args().any(|a| a == "--phat-given");
    let options = LocateOptions {
        span_std_fraction: 0.0,
        given_weighting: if plain {
            Weighting::Plain
        } else {
            Weighting::Phat
        },
        ..LocateOptions::default()
    };
    let mut locator = Locator::new(conn, options.clone(), 1.0).expect("locator");
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let mut given = Vec::new();
    let mut failed = Vec::new();
    for c in 0..cases {
        let Some(case) = draw_case(&net, &mut rng, 4, 400.0, &|_| true) else {
            break;
        };
        fill(&mut truths, &case.segments);
        let tau = true_delay(&case, &truths, DEFAULT_BAND_HZ, plain).expect("true delay")
            + SIGMA_TAU_S * normal(&mut rng);
        let delay = DelayInput::Given {
            delay_s: tau,
            std_s: SIGMA_TAU_S,
        };
        let job = case_job(&net, &case, format!("G{c}"), delay);
        let t = Instant::now();
        let r = locator.locate(&job);
        let ms = t.elapsed().as_secs_f64() * 1e3;
        match r {
            Ok(l) => {
                let o = Outcome::of(
                    &l,
                    case.leak_m,
                    case.segments.iter().any(|&s| plastic(s)),
                    ms,
                );
                if verbose && (!o.covered || o.err > 2.0) {
                    eprintln!(
                        "  {}: span {:.1} {:?} leak {:.2} got {:.2} [{:.2}, {:.2}] table {:.2}; {:?}",
                        job.id,
                        l.span_m,
                        l.path_ids,
                        case.leak_m,
                        l.distance_m,
                        l.lo_m,
                        l.hi_m,
                        l.table_distance_m,
                        l.budget.iter().map(|t| format!("{} {:+.2}", t.name, t.shift_m)).collect::<Vec<_>>()
                    );
                }
                if verbose && !o.covered {
                    for &s in &case.segments {
                        let i = locator.network.segment(&network[s].id).expect("in db");
                        let (_, c) = locator.curve(i).expect("curve");
                        let tc = true_curve(&truths[&s], DEFAULT_BAND_HZ).expect("truth");
                        let (cf, rel, _) = c.at(400.0);
                        let (ct, _, _) = tc.at(400.0);
                        eprintln!(
                            "    {} {}: c(400 Hz) fit {:.1} true {:.1}, z = {:.1} (σ {:.2} %)",
                            network[s].id,
                            network[s].material.code(),
                            cf,
                            ct,
                            (cf - ct) / (rel * cf),
                            100.0 * rel
                        );
                    }
                }
                given.push(o);
            }
            Err(e) => failed.push(format!("{}: {e}", job.id)),
        }
    }
    report("from a given delay (σ_τ = 0.1 ms)", &given, &failed);
    let mut pl: Vec<f64> = given.iter().filter(|o| o.plastic).map(|o| o.err).collect();
    let mut pt: Vec<f64> = given
        .iter()
        .filter(|o| o.plastic)
        .map(|o| o.table_err)
        .collect();
    let (mp, mt) = (median(&mut pl), median(&mut pt));
    println!(
        "  spans with a plastic segment ({}): median error {:.2} m, table-speed median error {:.2} m, ratio {:.3} (target ≤ 1/3)",
        pl.len(),
        mp,
        mt,
        mp / mt
    );
    let mut ms: Vec<f64> = given.iter().map(|o| o.ms).collect();
    let max = ms.iter().copied().fold(0.0, f64::max);
    println!(
        "  time per correlation: median {:.2} ms, max {:.2} ms (first use of a segment reads its curve)",
        median(&mut ms),
        max
    );

    // 2. Recordings.
    for (label, is_plastic, max_span) in [("metal", false, 300.0), ("plastic", true, 150.0)] {
        let mut out = Vec::new();
        let mut failed = Vec::new();
        let band = if is_plastic { plastic_band } else { None };
        for c in 0..n_rec {
            let filter = |s: usize| plastic(s) == is_plastic;
            let Some(case) = draw_case(&net, &mut rng, 4, max_span, &filter) else {
                break;
            };
            fill(&mut truths, &case.segments);
            let pieces: Vec<(&TruthCurve, f64)> = case
                .path
                .pieces
                .iter()
                .map(|p| (&truths[&p.segment], p.length_m()))
                .collect();
            let spec = LeakSpec {
                sample_rate: DEFAULT_LEAK_SAMPLE_RATE,
                seconds: 60.0,
                noise_fraction: DEFAULT_LEAK_NOISE_FRACTION,
                seed: seed.wrapping_mul(1000) + c as u64 + if is_plastic { 500 } else { 0 },
            };
            let rec = leak_recording(&pieces, case.leak_m, &spec).expect("recording");
            let file = dir.path().join(format!("{label}{c}.wav"));
            write_wav(
                &file,
                rec.sample_rate,
                &[&rec.x1, &rec.x2],
                WavFormat::Pcm16,
                headroom_gain(&[rec.x1.clone(), rec.x2.clone()]),
            )
            .expect("wav");
            let delay = DelayInput::Recordings(RecordingPair {
                file1: file.clone(),
                channel1: 0,
                file2: file.clone(),
                channel2: 1,
            });
            let mut job = case_job(&net, &case, format!("{label}{c}"), delay);
            job.band_hz = band;
            let t = Instant::now();
            let r = locator.locate(&job);
            let ms = t.elapsed().as_secs_f64() * 1e3;
            let _ = std::fs::remove_file(Path::new(&file));
            match r {
                Ok(l) => {
                    let o = Outcome::of(&l, case.leak_m, is_plastic, ms);
                    if verbose && (!o.covered || o.err > 1.0) {
                        eprintln!(
                            "  {}: span {:.1} {:?} leak {:.2} got {:.2} [{:.2}, {:.2}] τ {:.6}±{:.1e} {}; {:?}",
                            job.id,
                            l.span_m,
                            l.path_ids,
                            case.leak_m,
                            l.distance_m,
                            l.lo_m,
                            l.hi_m,
                            l.delay_s,
                            l.delay_std_s,
                            l.band_note,
                            l.budget.iter().map(|t| format!("{} {:+.2}", t.name, t.shift_m)).collect::<Vec<_>>()
                        );
                    }
                    out.push(o);
                }
                Err(e) => failed.push(format!("{}: {e}", job.id)),
            }
        }
        report(
            &format!(
                "from 60-s recordings, {label} spans up to {max_span} m{}",
                band.map(|b| format!(", band {}–{} Hz", b.0, b.1))
                    .unwrap_or_default()
            ),
            &out,
            &failed,
        );
        let mut ms: Vec<f64> = out.iter().map(|o| o.ms).collect();
        let max = ms.iter().copied().fold(0.0, f64::max);
        println!(
            "  time per correlation (reading the WAV included): median {:.0} ms, max {:.0} ms",
            median(&mut ms),
            max
        );
    }
}

fn report(label: &str, v: &[Outcome], failed: &[String]) {
    let n = v.len();
    let cov = v.iter().filter(|o| o.covered).count();
    let mut err: Vec<f64> = v.iter().map(|o| o.err).collect();
    let mut width: Vec<f64> = v.iter().map(|o| o.width).collect();
    let mut terr: Vec<f64> = v.iter().map(|o| o.table_err).collect();
    println!("{label}: {n} located, {} failed", failed.len());
    for f in failed.iter().take(5) {
        println!("  failed {f}");
    }
    println!(
        "  95 % interval covers {cov}/{n} = {:.1} %; median width {:.2} m; median error {:.2} m (p90 {:.2} m); table-speed median error {:.2} m",
        100.0 * cov as f64 / n.max(1) as f64,
        median(&mut width),
        median(&mut err.clone()),
        {
            err.sort_by(|a, b| a.total_cmp(b));
            err.get((0.9 * n as f64) as usize).copied().unwrap_or(f64::NAN)
        },
        median(&mut terr)
    );
}
