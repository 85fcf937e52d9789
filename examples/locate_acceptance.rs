//! Acceptance of `pipewave locate` (model §11) on a fresh synthetic network:
//!
//! 1. Position from a given delay: paths of 1–4 segments, spans 40–400 m, mixed materials;
//!    speeds from the segments' own fits (15 % of segments measured, by default) or the soil
//!    field's predictions (three geological units, by default); the delay from the TRUE soils through the P85 model
//!    plus noise σ_τ = 0.1 ms. Coverage of the 95 % interval, its median width, and on spans
//!    with a plastic segment the median error against the table-speed (Korteweg, P45) error.
//! 2. Position from recordings: 60 s at 8 kHz, sensor noise 30 %, made from the true soils;
//!    metal spans up to 300 m and plastic spans up to 150 m; median error and coverage.
//! 3. Time of one correlation from a delay and from two recordings (DB open and graph build
//!    excluded).
//!
//! Run: `cargo run --release --example locate_acceptance -- [--cases 200] [--recordings 40]
//! [--seed 11] [--segments 160] [--measured 0.15] [--units 3] [--plastic-band LO,HI]
//! [--independent-speeds] [--verbose] [--cases-csv FILE]` (`--cases-csv` appends one line per
//! given-delay case, for figures pooled over several seeds)
//!
//! On spans with a plastic segment it also splits the error: the position from the same noisy
//! delay with the TRUE curves (the delay's share), the position from the noise-free delay with
//! the stored curves (the speeds' share), and the stored and table speeds' errors on the plastic
//! segments of those paths.

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
    let measured: f64 = arg("--measured", 0.15);
    let units: usize = arg("--units", 3);
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
        measured_fraction: measured,
        units,
        ..SynthOptions::default()
    };
    let network = generate(&opts);
    let t0 = Instant::now();
    let database = calibrated_database(dir.path(), &network, &opts, 2).expect("network");
    eprintln!(
        "network: {} segments, seed {seed}, {:.0} % measured, {units} units, imported and \
         calibrated in {:.1} s",
        network.len(),
        100.0 * measured,
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
        joint_speeds: !std::env::args().any(|a| a == "--independent-speeds"),
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
    let mut split: Vec<Split> = Vec::new();
    let mut joint_ratio: Vec<f64> = Vec::new();
    // A path with a segment whose true soil has no wave over the band (no root of F, P32)
    // has no true delay to test against: it is drawn again, and counted.
    let mut no_true_delay = 0usize;
    let mut drawn = 0;
    while drawn < cases {
        let Some(case) = draw_case(&net, &mut rng, 4, 400.0, &|_| true) else {
            break;
        };
        fill(&mut truths, &case.segments);
        let Some(tau_true) = true_delay(&case, &truths, DEFAULT_BAND_HZ, plain) else {
            no_true_delay += 1;
            if no_true_delay > cases {
                break;
            }
            continue;
        };
        let c = drawn;
        drawn += 1;
        let tau = tau_true + SIGMA_TAU_S * normal(&mut rng);
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
                if l.notes
                    .iter()
                    .any(|n| n.contains("correlated through the soil field"))
                {
                    let indep = l
                        .budget
                        .iter()
                        .filter(|t| t.segment_id.is_some())
                        .map(|t| t.shift_m * t.shift_m)
                        .sum::<f64>()
                        .sqrt();
                    if indep > 0.0 {
                        joint_ratio.push(l.speeds_std_m / indep);
                    }
                }
                if o.plastic {
                    let exact = DelayInput::Given {
                        delay_s: tau_true,
                        std_s: SIGMA_TAU_S,
                    };
                    let speeds_only = locator
                        .locate(&case_job(&net, &case, format!("S{c}"), exact))
                        .map_or(f64::NAN, |m| (m.distance_m - case.leak_m).abs());
                    let delay_only = true_position(&case, &truths, plain, tau)
                        .map_or(f64::NAN, |x| (x - case.leak_m).abs());
                    let mut speed_errs = Vec::new();
                    for (k, &s) in case.segments.iter().enumerate() {
                        if !plastic(s) {
                            continue;
                        }
                        let i = locator.network.segment(&network[s].id).expect("in db");
                        let (_, cur) = locator.curve(i).expect("curve");
                        let tc = true_curve(&truths[&s], DEFAULT_BAND_HZ).expect("truth");
                        let f = l.band_used_hz.0.max(100.0) + 15.0;
                        let ct = tc.at(f).0;
                        let kt = locator.korteweg(i).expect("korteweg");
                        let (cs, rel, _) = cur.at(f);
                        speed_errs.push((
                            l.sources[k].as_str(),
                            (cs - ct) / ct,
                            (kt - ct) / ct,
                            (cs - ct) / (rel * cs),
                        ));
                    }
                    split.push(Split {
                        total: o.err,
                        table: o.table_err,
                        delay_only,
                        speeds_only,
                        speed_errs,
                    });
                }
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
    if no_true_delay > 0 {
        println!("  {no_true_delay} drawn paths had no true delay (a segment without a wave in the band) and were drawn again");
    }
    // One line per case, for figures pooled over several networks (seeds).
    let cases_csv: String = arg("--cases-csv", String::new());
    if !cases_csv.is_empty() {
        use std::io::Write as _;
        let new = !Path::new(&cases_csv).exists();
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&cases_csv)
            .expect("cases CSV");
        if new {
            writeln!(f, "seed,case,plastic,error_m,table_error_m,covered,width_m").expect("write");
        }
        for (c, o) in given.iter().enumerate() {
            writeln!(
                f,
                "{seed},{c},{},{},{},{},{}",
                u8::from(o.plastic),
                o.err,
                o.table_err,
                u8::from(o.covered),
                o.width
            )
            .expect("write");
        }
    }
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
    report_split(&split);
    {
        let n = joint_ratio.len();
        let below = joint_ratio.iter().filter(|r| **r < 0.99).count();
        let above = joint_ratio.iter().filter(|r| **r > 1.01).count();
        println!(
            "  joint speed errors: {n} cases with correlated predicted neighbours; speeds' σ_x \
             joint/independent median {:.3} (below 0.99 on {below}, above 1.01 on {above})",
            median(&mut joint_ratio)
        );
    }
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
            let pieces = case.truth_pieces(&truths);
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

/// Where a plastic span's error comes from.
struct Split {
    total: f64,
    table: f64,
    /// With the true curves and the noisy delay.
    delay_only: f64,
    /// With the stored curves and the noise-free delay.
    speeds_only: f64,
    /// Per plastic segment: its curve's source, its stored speed's relative error and the
    /// table (Korteweg) speed's, near the low edge of the band used, and the stored speed's
    /// error in units of its own σ (z).
    speed_errs: Vec<(&'static str, f64, f64, f64)>,
}

fn report_split(split: &[Split]) {
    let med = |f: &dyn Fn(&Split) -> f64| {
        let mut v: Vec<f64> = split.iter().map(f).filter(|v| v.is_finite()).collect();
        median(&mut v)
    };
    println!(
        "  plastic spans, error split: median total {:.2} m; true curves with the noisy delay \
         {:.2} m; stored curves with the exact delay {:.2} m; table {:.2} m",
        med(&|s| s.total),
        med(&|s| s.delay_only),
        med(&|s| s.speeds_only),
        med(&|s| s.table),
    );
    for src in ["fit", "prediction"] {
        let mut stored: Vec<f64> = split
            .iter()
            .flat_map(|s| s.speed_errs.iter())
            .filter(|e| e.0 == src)
            .map(|e| 100.0 * e.1.abs())
            .collect();
        let mut table: Vec<f64> = split
            .iter()
            .flat_map(|s| s.speed_errs.iter())
            .filter(|e| e.0 == src)
            .map(|e| 100.0 * e.2.abs())
            .collect();
        let z: Vec<f64> = split
            .iter()
            .flat_map(|s| s.speed_errs.iter())
            .filter(|e| e.0 == src && e.3.is_finite())
            .map(|e| e.3)
            .collect();
        let inside = z.iter().filter(|z| z.abs() <= 1.96).count();
        let rms = (z.iter().map(|z| z * z).sum::<f64>() / z.len().max(1) as f64).sqrt();
        let n = stored.len();
        let p90 = |v: &mut Vec<f64>| {
            v.sort_by(|a, b| a.total_cmp(b));
            v.get((0.9 * v.len() as f64) as usize)
                .copied()
                .unwrap_or(f64::NAN)
        };
        println!(
            "  plastic segments on those paths with a {src}: {n}; speed error median {:.1} % \
             (p90 {:.1} %), table speed's {:.1} % (p90 {:.1} %); within 1.96σ {inside}/{} (z rms {rms:.2})",
            median(&mut stored.clone()),
            p90(&mut stored),
            median(&mut table.clone()),
            p90(&mut table),
            z.len()
        );
    }
    let worse: Vec<&Split> = split.iter().filter(|s| s.total > s.table / 3.0).collect();
    println!(
        "  {} of {} plastic spans miss a third of their table error; of those, the delay alone \
         (true curves) would miss on {}, the speeds alone (exact delay) on {}",
        worse.len(),
        split.len(),
        worse
            .iter()
            .filter(|s| s.delay_only > s.table / 3.0)
            .count(),
        worse
            .iter()
            .filter(|s| s.speeds_only > s.table / 3.0)
            .count()
    );
}

/// The position from delay `tau` with the segments' TRUE curves (P85, P86).
fn true_position(
    case: &pipewave::synth::locate::LeakCase,
    truths: &HashMap<usize, TruthCurve>,
    plain: bool,
    tau: f64,
) -> Option<f64> {
    use pipewave::locate::model::{band_grid, solve, DelayModel, MODEL_GRID_POINTS};
    let (curves, pieces) =
        pipewave::synth::locate::true_delay_model(case, truths, DEFAULT_BAND_HZ)?;
    let refs: Vec<_> = curves.iter().collect();
    let grid = band_grid(DEFAULT_BAND_HZ, MODEL_GRID_POINTS);
    let model = DelayModel::new(&grid, &vec![1.0; grid.len()], plain, &refs, pieces);
    solve(&model, tau, SIGMA_TAU_S, 0.0, &[])
        .ok()
        .map(|p| p.x_m)
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
