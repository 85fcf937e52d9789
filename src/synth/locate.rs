//! Synthetic two-sensor leak recordings of a known leak on a path of several segments, made
//! from the segments' true soil and contact (the synthetic network's truth), not from stored
//! curves, so that locating them does not test the chain against itself.
//!
//! The leak is broadband noise L(ω); sensor j hears it through the pieces of path between them,
//! X_j = L exp(−i Σ_s k_s(ω) ℓ_s,j) (P85) with each segment's true k_s (its attenuation shapes
//! the spectrum), made by one inverse FFT over the whole record (one period of a periodic random
//! signal, as the hydrant-test recordings are), plus each sensor's own white noise.

use crate::outfile::{Contents, OutFile};
use std::path::Path;

use num_complex::Complex64;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realfft::RealFftPlanner;

use crate::db::results::CurvePoint;
use crate::db::wkt::LineString;
use crate::locate::gcc::Recording;
use crate::locate::model::SpeedCurve;
use crate::locate::network::{NetSegment, Network, SensorAt, SensorPath};
use crate::recordings::estimate::MAX_FREQUENCY_FRACTION;
use crate::stats::normal;
use crate::synth::recordings::{
    headroom_gain, source_amplitude, system_of, truth_curve, write_wav, TruthCurve, WavFormat,
    RING_FRACTION, SOURCE_HI_HZ,
};
use crate::synth::{SynthOptions, SynthSegment};
use crate::units::np_to_db;

/// Default length of a synthetic leak recording, s.
pub const DEFAULT_LEAK_SECONDS: f64 = 60.0;
/// Default sample rate, Hz.
pub const DEFAULT_LEAK_SAMPLE_RATE: u32 = 8000;
/// Default sensor noise: RMS as a fraction of the leak signal's RMS at that sensor.
pub const DEFAULT_LEAK_NOISE_FRACTION: f64 = 0.3;
/// Shortest and longest span of a synthetic leak path, m.
pub const LEAK_SPAN_M: (f64, f64) = (40.0, 400.0);
/// Longest stretch of plastic pipe on a path of [`write_leaks`], m: plastics attenuate leak
/// noise within tens of metres, and correlators are used on plastic spans of 150 m at most.
pub const MAX_PLASTIC_M: f64 = 150.0;
/// A synthetic leak lies this fraction of the span or more from either sensor.
const LEAK_MARGIN_FRACTION: f64 = 0.1;

/// What to record.
#[derive(Debug, Clone, PartialEq)]
pub struct LeakSpec {
    /// Sample rate, Hz.
    pub sample_rate: u32,
    /// Length, s.
    pub seconds: f64,
    /// Sensor noise RMS over the leak signal's RMS at each sensor.
    pub noise_fraction: f64,
    /// Seed of the leak noise and the sensor noise.
    pub seed: u64,
}

/// The two sensors' signals for a leak `x_m` from sensor 1 on a path whose pieces (in order
/// from sensor 1) have true wavenumbers `pieces[i].0` and lengths `pieces[i].1`.
pub fn leak_recording(
    pieces: &[(&TruthCurve, f64)],
    x_m: f64,
    spec: &LeakSpec,
) -> Result<Recording, String> {
    let fs = spec.sample_rate as f64;
    if pieces.is_empty() || spec.seconds.is_nan() || spec.seconds <= 0.0 || spec.sample_rate < 100 {
        return Err("a leak recording needs a path, a positive length and 100 Hz or more".into());
    }
    let hi = pieces
        .iter()
        .map(|p| p.0.hi_hz())
        .fold(MAX_FREQUENCY_FRACTION * fs, f64::min);
    let n = 2 * ((spec.seconds * fs / 2.0).round() as usize).max(1);
    let bins = n / 2 + 1;
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let mut x1 = vec![Complex64::new(0.0, 0.0); bins];
    let mut x2 = vec![Complex64::new(0.0, 0.0); bins];
    for j in 1..bins - 1 {
        let f = j as f64 * fs / n as f64;
        let a = source_amplitude(f, hi);
        let z = Complex64::new(normal(&mut rng), normal(&mut rng));
        if a == 0.0 {
            continue;
        }
        let (mut psi1, mut psi2) = (Complex64::new(0.0, 0.0), Complex64::new(0.0, 0.0));
        let mut start = 0.0;
        for (k, len) in pieces {
            let kf = k.at(f).unwrap_or(Complex64::new(0.0, 0.0));
            let on1 = (x_m - start).clamp(0.0, *len);
            psi1 += kf * on1;
            psi2 += kf * (len - on1);
            start += len;
        }
        let l = z * (a / std::f64::consts::SQRT_2);
        // eq. P85: X_j = L exp(−i ψ_j).
        x1[j] = l * (Complex64::new(0.0, -1.0) * psi1).exp();
        x2[j] = l * (Complex64::new(0.0, -1.0) * psi2).exp();
    }
    let mut planner = RealFftPlanner::<f64>::new();
    let inv = planner.plan_fft_inverse(n);
    let mut out = Vec::with_capacity(2);
    for mut z in [x1, x2] {
        let mut t = inv.make_output_vec();
        inv.process(&mut z, &mut t)
            .map_err(|e| format!("inverse FFT: {e}"))?;
        let rms = (t.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
        let sigma = spec.noise_fraction * rms;
        for v in &mut t {
            *v += sigma * normal(&mut rng);
        }
        out.push(t);
    }
    let x2 = out.pop().unwrap_or_default();
    let x1 = out.pop().unwrap_or_default();
    Ok(Recording {
        sample_rate: spec.sample_rate,
        x1,
        x2,
    })
}

/// A truth curve as a speed curve (every point of it inside `band_hz`, widened by 2 Hz), so the
/// P85 model can give the true delay.
pub fn true_curve(truth: &TruthCurve, band_hz: (f64, f64)) -> Option<SpeedCurve> {
    let pts: Vec<CurvePoint> = truth
        .k1
        .iter()
        .enumerate()
        .filter_map(|(i, k)| {
            let f = truth.f0_hz + truth.step_hz * i as f64;
            (f >= band_hz.0 - 2.0 && f <= band_hz.1 + 2.0).then(|| CurvePoint {
                frequency_hz: f,
                phase_speed_m_per_s: Some(crate::units::hz_to_omega(f) / k.re),
                attenuation_db_per_m: Some(np_to_db(-k.im)),
                phase_speed_std_m_per_s: Some(0.0),
                attenuation_std_db_per_m: None,
                model_phase_speed_m_per_s: None,
                model_attenuation_db_per_m: None,
            })
        })
        .collect();
    SpeedCurve::from_points(&pts)
}

/// The true wavenumber of a synthetic segment over the source band of `sample_rate`.
pub fn segment_truth(
    seg: &SynthSegment,
    opts: &SynthOptions,
    sample_rate: u32,
) -> Result<TruthCurve, String> {
    let sys = system_of(seg, opts)?;
    let hi = SOURCE_HI_HZ
        .min(RING_FRACTION * sys.pipe.ring_frequency_hz())
        .min(MAX_FREQUENCY_FRACTION * sample_rate as f64);
    truth_curve(&sys, hi).map_err(|e| format!("segment {}: {e}", seg.id))
}

/// The network of a synthetic inventory (its lines are in metres already).
pub fn network_of(segments: &[SynthSegment], opts: &SynthOptions) -> Network {
    Network::from_segments(
        segments
            .iter()
            .map(|s| {
                NetSegment::new(
                    s.id.clone(),
                    Some(LineString {
                        points: s.geometry.clone(),
                    }),
                    None,
                )
            })
            .collect(),
        Some(opts.srid as i64),
        crate::locate::network::DEFAULT_JOIN_TOLERANCE_M,
    )
}

/// A synthetic leak case: the path, the sensors and where the leak is.
#[derive(Debug, Clone, PartialEq)]
pub struct LeakCase {
    /// Segment indices of the path, from sensor 1.
    pub segments: Vec<usize>,
    /// Sensor 1.
    pub sensor1: SensorAt,
    /// Sensor 2.
    pub sensor2: SensorAt,
    /// The path.
    pub path: SensorPath,
    /// The leak, m from sensor 1.
    pub leak_m: f64,
}

impl LeakCase {
    /// The path's pieces from sensor 1 as (the segment's true wavenumbers, metres of it), the
    /// input of `leak_recording`. Panics if `truths` lacks a segment of the path (a caller's
    /// bug: every generator fills the truths of a case before it records it).
    pub fn truth_pieces<'a>(
        &self,
        truths: &'a std::collections::HashMap<usize, TruthCurve>,
    ) -> Vec<(&'a TruthCurve, f64)> {
        self.path
            .pieces
            .iter()
            .map(|p| (&truths[&p.segment], p.length_m()))
            .collect()
    }
}

/// Draw a path of 1 to `max_segments` segments whose span lies in [`LEAK_SPAN_M`] (at most
/// `max_span_m`), the sensors and a leak. `filter` says which segments may be used.
pub fn draw_case<R: Rng + ?Sized>(
    net: &Network,
    rng: &mut R,
    max_segments: usize,
    max_span_m: f64,
    filter: &dyn Fn(usize) -> bool,
) -> Option<LeakCase> {
    let n = net.segments.len();
    for _ in 0..1000 {
        let start = rng.gen_range(0..n);
        if !filter(start) {
            continue;
        }
        let want = rng.gen_range(1..=max_segments.max(1));
        let segs: Vec<usize> = net
            .walk(start, want - 1, rng)
            .into_iter()
            .take_while(|&s| filter(s))
            .collect();
        let (first, last) = (segs[0], *segs.last()?);
        let (l1, l2) = (net.segments[first].length_m?, net.segments[last].length_m?);
        let sensor1 = SensorAt {
            segment: first,
            chainage_m: rng.gen_range(0.0..l1),
        };
        let sensor2 = SensorAt {
            segment: last,
            chainage_m: rng.gen_range(0.0..l2),
        };
        let ids: Vec<String> = segs.iter().map(|&s| net.segments[s].id.clone()).collect();
        let Ok(path) = net.explicit_path(&ids, sensor1, sensor2) else {
            continue;
        };
        let d = path.span_m();
        if d < LEAK_SPAN_M.0 || d > LEAK_SPAN_M.1.min(max_span_m) {
            continue;
        }
        let leak_m = d * rng.gen_range(LEAK_MARGIN_FRACTION..1.0 - LEAK_MARGIN_FRACTION);
        return Some(LeakCase {
            segments: segs,
            sensor1,
            sensor2,
            path,
            leak_m,
        });
    }
    None
}

/// Files written by [`write_leaks`] into its directory.
pub const LEAK_JOBS_CSV: &str = "jobs.csv";
/// The truth of the synthetic leaks.
pub const LEAK_TRUTH_CSV: &str = "leaks_truth.csv";

/// Write `count` synthetic leak correlations on the network into `dir`: one two-channel 16-bit
/// WAV per job (channel 0 sensor 1, channel 1 sensor 2), `jobs.csv` for `pipewave locate`, and
/// `leaks_truth.csv` (where each leak is). Deterministic for the network's seed.
pub fn write_leaks(
    dir: &Path,
    network: &[SynthSegment],
    opts: &SynthOptions,
    count: usize,
    seconds: f64,
) -> Result<usize, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let net = network_of(network, opts);
    let mut rng = ChaCha8Rng::seed_from_u64(crate::seed::derive(opts.seed, LEAK_SEED_STREAM));
    let mut truths: std::collections::HashMap<usize, TruthCurve> = Default::default();
    let csv_err = |e: csv::Error| e.to_string();
    let out = |name: &str| -> Result<csv::Writer<OutFile>, String> {
        let f = OutFile::create(&dir.join(name), Contents::Plain).map_err(|e| e.to_string())?;
        Ok(csv::Writer::from_writer(f))
    };
    let mut jobs = out(LEAK_JOBS_CSV)?;
    jobs.write_record([
        "job_id",
        "sensor1_segment",
        "sensor1_chainage_m",
        "sensor2_segment",
        "sensor2_chainage_m",
        "recording1",
        "channel1",
        "recording2",
        "channel2",
        "path",
    ])
    .map_err(csv_err)?;
    let mut truth = out(LEAK_TRUTH_CSV)?;
    truth
        .write_record([
            "job_id",
            "leak_segment",
            "leak_chainage_m",
            "distance_from_sensor1_m",
            "span_m",
        ])
        .map_err(csv_err)?;
    let mut written = 0;
    for j in 0..count {
        // A correlator hears a leak through at most [`MAX_PLASTIC_M`] of plastic pipe.
        let plastic_m = |c: &LeakCase| -> f64 {
            c.path
                .pieces
                .iter()
                .filter(|p| network[p.segment].material.is_plastic())
                .map(|p| p.length_m())
                .sum()
        };
        let Some(case) = (0..100)
            .filter_map(|_| draw_case(&net, &mut rng, 4, LEAK_SPAN_M.1, &|_| true))
            .find(|c| plastic_m(c) <= MAX_PLASTIC_M)
        else {
            break;
        };
        for &s in &case.segments {
            if let std::collections::hash_map::Entry::Vacant(e) = truths.entry(s) {
                e.insert(segment_truth(&network[s], opts, DEFAULT_LEAK_SAMPLE_RATE)?);
            }
        }
        let pieces = case.truth_pieces(&truths);
        let spec = LeakSpec {
            sample_rate: DEFAULT_LEAK_SAMPLE_RATE,
            seconds,
            noise_fraction: DEFAULT_LEAK_NOISE_FRACTION,
            seed: rng.gen(),
        };
        let rec = leak_recording(&pieces, case.leak_m, &spec)?;
        let id = format!("L{:03}", j + 1);
        let file = format!("{id}.wav");
        let chans = [rec.x1.clone(), rec.x2.clone()];
        write_wav(
            &dir.join(&file),
            rec.sample_rate,
            &[&rec.x1, &rec.x2],
            WavFormat::Pcm16,
            headroom_gain(&chans),
        )
        .map_err(|e| format!("cannot write {file}: {e}"))?;
        let name = |s: usize| net.segments[s].id.clone();
        let ids: Vec<String> = case.segments.iter().map(|&s| name(s)).collect();
        jobs.write_record([
            id.clone(),
            name(case.sensor1.segment),
            format!("{:.2}", case.sensor1.chainage_m),
            name(case.sensor2.segment),
            format!("{:.2}", case.sensor2.chainage_m),
            file.clone(),
            "0".into(),
            file,
            "1".into(),
            ids.join(";"),
        ])
        .map_err(csv_err)?;
        let (pi, ch) = case.path.locate(case.leak_m);
        truth
            .write_record([
                id,
                name(case.path.pieces[pi].segment),
                format!("{ch:.3}"),
                format!("{:.3}", case.leak_m),
                format!("{:.3}", case.path.span_m()),
            ])
            .map_err(csv_err)?;
        written += 1;
    }
    for w in [jobs, truth] {
        let f = w.into_inner().map_err(|e| e.to_string())?;
        f.commit().map_err(|e| e.to_string())?;
    }
    Ok(written)
}

/// Stream of the network seed that draws the synthetic leaks.
const LEAK_SEED_STREAM: u64 = 0x6c65_616b;

/// The job of a synthetic case: the sensors by segment and chainage, its path given explicitly.
pub fn case_job(
    net: &Network,
    case: &LeakCase,
    id: String,
    delay: crate::locate::DelayInput,
) -> crate::locate::Job {
    let on = |s: SensorAt| crate::locate::network::SensorSpec::OnSegment {
        segment_id: net.segments[s.segment].id.clone(),
        chainage_m: s.chainage_m,
    };
    crate::locate::Job {
        id,
        source: std::path::PathBuf::from(LEAK_JOBS_CSV),
        line: 2,
        sensor1: on(case.sensor1),
        sensor2: on(case.sensor2),
        delay,
        band_hz: None,
        path: Some(
            case.segments
                .iter()
                .map(|&s| net.segments[s].id.clone())
                .collect(),
        ),
    }
}

/// The delay model (P85) of a case with the segments' TRUE wavenumbers over `band_hz`: a plain
/// correlation of a flat leak spectrum (`path_attenuation`) or a whitened one. Returns the
/// model's curves and pieces; `truths` by segment index.
pub fn true_delay_model(
    case: &LeakCase,
    truths: &std::collections::HashMap<usize, TruthCurve>,
    band_hz: (f64, f64),
) -> Option<(Vec<SpeedCurve>, Vec<crate::locate::model::ModelPiece>)> {
    use crate::locate::model::ModelPiece;
    let curves: Vec<SpeedCurve> = case
        .segments
        .iter()
        .map(|s| truths.get(s).and_then(|t| true_curve(t, band_hz)))
        .collect::<Option<_>>()?;
    let pieces: Vec<ModelPiece> = case
        .path
        .pieces
        .iter()
        .map(|p| {
            Some(ModelPiece {
                curve: case.segments.iter().position(|&s| s == p.segment)?,
                length_m: p.length_m(),
            })
        })
        .collect::<Option<_>>()?;
    Some((curves, pieces))
}

/// The delay a correlator would measure for a case with the segments' TRUE wavenumbers (P85)
/// over `band_hz`: a plain correlation of a flat leak spectrum (`path_attenuation`) or a
/// whitened one. `truths` by segment index.
pub fn true_delay(
    case: &LeakCase,
    truths: &std::collections::HashMap<usize, TruthCurve>,
    band_hz: (f64, f64),
    path_attenuation: bool,
) -> Option<f64> {
    use crate::locate::model::{band_grid, DelayModel, MODEL_GRID_POINTS};
    let (curves, pieces) = true_delay_model(case, truths, band_hz)?;
    let refs: Vec<&SpeedCurve> = curves.iter().collect();
    let grid = band_grid(band_hz, MODEL_GRID_POINTS);
    let model = DelayModel::new(
        &grid,
        &vec![1.0; grid.len()],
        path_attenuation,
        &refs,
        pieces,
    );
    Some(model.delay(case.leak_m))
}

/// Write a synthetic network into `dir`, import it into `dir/db.sqlite` and calibrate every
/// segment (the fits see only the inventory and the noisy measurements, never the truth).
pub fn calibrated_database(
    dir: &Path,
    network: &[SynthSegment],
    opts: &SynthOptions,
    jobs: usize,
) -> Result<crate::db::Database, String> {
    use crate::synth::network::{NetworkTables, MEASUREMENTS_CSV, SEGMENTS_CSV};
    NetworkTables::from_synth(network, opts.srid)
        .write_dir(dir)
        .map_err(|e| e.to_string())?;
    let mut database =
        crate::db::Database::open(dir.join("db.sqlite")).map_err(|e| e.to_string())?;
    let src = |n: &str| crate::db::ImportSource::from_path(&dir.join(n)).map_err(|e| e.to_string());
    crate::db::import(
        database.conn_mut(),
        Some(&src(SEGMENTS_CSV)?),
        Some(&src(MEASUREMENTS_CSV)?),
        crate::db::ImportOptions::default(),
    )
    .map_err(|e| e.to_string())?;
    crate::batch::calibrate(
        database.conn_mut(),
        &crate::batch::CalibrateOptions {
            jobs: Some(jobs.max(1)),
            seed: opts.seed,
            ..crate::batch::CalibrateOptions::default()
        },
        &mut (),
        &std::sync::atomic::AtomicBool::new(false),
    )
    .map_err(|e| e.to_string())?;
    Ok(database)
}
