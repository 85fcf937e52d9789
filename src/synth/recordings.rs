//! Synthetic hydrant-test recordings from the forward model (model §10, eq. P72), with their
//! truth, so that `pipewave wavenumbers` can be tested and tried.
//!
//! The source is broadband flow noise: a complex Gaussian spectrum, flat between
//! [`SOURCE_LO_HZ`] and the top of the band with cosine tapers. Each sensor at signed position
//! x hears p(x, ω) = S(ω) exp(−i k1(ω) |x|) (P72), made by one inverse FFT over the whole record
//! (the record is one period of a periodic random signal, so every stretch of it is a valid
//! stationary sample), plus its own independent white noise whose RMS is a fraction of the
//! source channel's.

pub mod recovery;

use std::io;
use std::path::Path;

use crate::outfile::{Contents, OutFile};

use num_complex::Complex64;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realfft::RealFftPlanner;

use crate::physics::solver::{solve_curve, Continuation};
use crate::physics::System;
use crate::recordings::estimate::MAX_FREQUENCY_FRACTION;
use crate::stats::normal;
use crate::units::hz_to_omega;

/// Lowest source frequency, Hz (the taper rises from here to twice this).
pub const SOURCE_LO_HZ: f64 = 2.0;
/// Highest source frequency, Hz: hydrant flow noise is broadband well above the leak band.
pub const SOURCE_HI_HZ: f64 = 2500.0;
/// The source band stops below this fraction of the pipe's ring frequency (where the s = 1 wave
/// ceases to be the only one, model §1), as the synthetic networks do.
pub const RING_FRACTION: f64 = 0.45;
/// Relative width of the upper taper of the source spectrum.
pub const TOP_TAPER_FRACTION: f64 = 0.1;
/// Spacing of the forward-model solutions, Hz; k1 is interpolated linearly between them (its
/// curvature over 1 Hz changes Re k1 by far less than 1e-6 relative).
pub const TRUTH_STEP_HZ: f64 = 1.0;
/// Spacing of the rows of the written truth file, Hz.
pub const TRUTH_FILE_STEP_HZ: f64 = 10.0;
/// Peak level of the written PCM files, as a fraction of full scale (headroom, no clipping).
pub const WAV_PEAK: f64 = 0.5;

/// The wavenumber the recordings were made with, k1 at f0 + i·step (Im k1 < 0).
#[derive(Debug, Clone, PartialEq)]
pub struct TruthCurve {
    /// First frequency, Hz.
    pub f0_hz: f64,
    /// Spacing, Hz.
    pub step_hz: f64,
    /// k1 at each point, rad/m.
    pub k1: Vec<Complex64>,
}

impl TruthCurve {
    /// k1 at `f_hz` by linear interpolation, `None` outside the curve.
    pub fn at(&self, f_hz: f64) -> Option<Complex64> {
        let x = (f_hz - self.f0_hz) / self.step_hz;
        if x.is_nan() || x < 0.0 || x > (self.k1.len() - 1) as f64 {
            return None;
        }
        let i = (x.floor() as usize).min(self.k1.len().saturating_sub(2));
        let t = x - i as f64;
        Some(self.k1[i] * (1.0 - t) + self.k1[(i + 1).min(self.k1.len() - 1)] * t)
    }

    /// Highest frequency of the curve, Hz.
    pub fn hi_hz(&self) -> f64 {
        self.f0_hz + self.step_hz * (self.k1.len() - 1) as f64
    }
}

/// What to record.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingSpec {
    /// Sample rate, Hz.
    pub sample_rate: u32,
    /// Length, s.
    pub seconds: f64,
    /// Sensor positions, m from the source (signed).
    pub positions_m: Vec<f64>,
    /// RMS of each sensor's own noise as a fraction of the RMS of the (noise-free) signal at the
    /// sensor nearest the source.
    pub noise_fraction: f64,
    /// Seed of the source and noise.
    pub seed: u64,
}

/// A synthetic hydrant test.
#[derive(Debug, Clone)]
pub struct HydrantRecording {
    /// Sample rate, Hz.
    pub sample_rate: u32,
    /// One signal per sensor, in the order of the positions.
    pub channels: Vec<Vec<f64>>,
    /// The wavenumber that made them.
    pub truth: TruthCurve,
}

/// A synthetic recording that cannot be made.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SynthRecordingError {
    /// The forward model has no root low in the band.
    #[error("the forward model has no wavenumber below {0} Hz for this pipe")]
    NoRoot(f64),
    /// Bad specification.
    #[error("{0}")]
    Spec(String),
}

/// The forward model's k1 from [`SOURCE_LO_HZ`] up to `hi_hz` every [`TRUTH_STEP_HZ`], cut at
/// the first frequency where it fails.
pub fn truth_curve(sys: &System, hi_hz: f64) -> Result<TruthCurve, SynthRecordingError> {
    let n = ((hi_hz - SOURCE_LO_HZ) / TRUTH_STEP_HZ).floor() as usize + 1;
    let freqs: Vec<f64> = (0..n)
        .map(|i| SOURCE_LO_HZ + TRUTH_STEP_HZ * i as f64)
        .collect();
    let omegas: Vec<f64> = freqs.iter().map(|&f| hz_to_omega(f)).collect();
    let k1: Vec<Complex64> = solve_curve(sys, &omegas, Continuation::default())
        .into_iter()
        .map_while(|r| {
            r.ok()
                .filter(|r| !r.flags.growing_wave && r.k1.re > 0.0)
                .map(|r| r.k1)
        })
        .collect();
    if k1.len() < 2 {
        return Err(SynthRecordingError::NoRoot(hi_hz));
    }
    Ok(TruthCurve {
        f0_hz: SOURCE_LO_HZ,
        step_hz: TRUTH_STEP_HZ,
        k1,
    })
}

/// Amplitude of the source spectrum at `f`: cosine tapers at both ends of [lo, hi].
pub(crate) fn source_amplitude(f: f64, hi: f64) -> f64 {
    let lo = SOURCE_LO_HZ;
    if f <= lo || f >= hi {
        return 0.0;
    }
    let top = hi * (1.0 - TOP_TAPER_FRACTION);
    if f < 2.0 * lo {
        (0.5 - 0.5 * (std::f64::consts::PI * (f - lo) / lo).cos()).sqrt()
    } else if f > top {
        (0.5 + 0.5 * (std::f64::consts::PI * (f - top) / (hi - top)).cos()).sqrt()
    } else {
        1.0
    }
}

/// Make the recordings of a hydrant test on the pipe `sys`.
pub fn hydrant_test(
    sys: &System,
    spec: &RecordingSpec,
) -> Result<HydrantRecording, SynthRecordingError> {
    let fs = spec.sample_rate as f64;
    if spec.positions_m.is_empty()
        || !spec.seconds.is_finite()
        || spec.seconds <= 0.0
        || spec.seconds > MAX_RECORDING_S
        || spec.sample_rate < 100
    {
        return Err(SynthRecordingError::Spec(format!(
            "a recording needs sensor positions, a length of 0 - {MAX_RECORDING_S} s and a \
                 sample rate of 100 Hz or more"
        )));
    }
    let hi = SOURCE_HI_HZ
        .min(RING_FRACTION * sys.pipe.ring_frequency_hz())
        .min(MAX_FREQUENCY_FRACTION * fs);
    let truth = truth_curve(sys, hi)?;
    let hi = truth.hi_hz();
    let n = 2 * ((spec.seconds * fs / 2.0).round() as usize).max(1);
    let bins = n / 2 + 1;
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let source: Vec<Complex64> = (0..bins)
        .map(|j| {
            let f = j as f64 * fs / n as f64;
            let a = source_amplitude(f, hi);
            let z = Complex64::new(normal(&mut rng), normal(&mut rng));
            if a > 0.0 {
                z * (a / std::f64::consts::SQRT_2)
            } else {
                Complex64::new(0.0, 0.0)
            }
        })
        .collect();
    let mut planner = RealFftPlanner::<f64>::new();
    let inv = planner.plan_fft_inverse(n);
    let mut clean: Vec<Vec<f64>> = Vec::with_capacity(spec.positions_m.len());
    for &x in &spec.positions_m {
        let mut z: Vec<Complex64> = source
            .iter()
            .enumerate()
            .map(|(j, s)| {
                if s.norm_sqr() == 0.0 {
                    return Complex64::new(0.0, 0.0);
                }
                let f = j as f64 * fs / n as f64;
                let k = truth.at(f).unwrap_or(Complex64::new(0.0, 0.0));
                // eq. P72
                s * (Complex64::new(0.0, -1.0) * k * x.abs()).exp()
            })
            .collect();
        z[0] = Complex64::new(0.0, 0.0);
        z[bins - 1] = Complex64::new(z[bins - 1].re, 0.0);
        let mut out = inv.make_output_vec();
        inv.process(&mut z, &mut out)
            .map_err(|e| SynthRecordingError::Spec(format!("inverse FFT: {e}")))?;
        clean.push(out);
    }
    let nearest = (0..spec.positions_m.len())
        .min_by(|&i, &j| {
            spec.positions_m[i]
                .abs()
                .total_cmp(&spec.positions_m[j].abs())
        })
        .unwrap_or(0);
    let rms = (clean[nearest].iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    let sigma = spec.noise_fraction * rms;
    let channels = clean
        .into_iter()
        .map(|c| {
            c.into_iter()
                .map(|v| v + sigma * normal(&mut rng))
                .collect()
        })
        .collect();
    Ok(HydrantRecording {
        sample_rate: spec.sample_rate,
        channels,
        truth,
    })
}

/// Sample format of a written WAV file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WavFormat {
    /// 16-bit PCM.
    Pcm16,
    /// 24-bit PCM.
    Pcm24,
    /// 32-bit float.
    Float32,
}

/// Write channels as one multichannel WAV file, scaled by `gain` (full scale = 1; PCM values
/// beyond full scale are clipped, as a recorder would).
pub fn write_wav(
    path: &Path,
    sample_rate: u32,
    channels: &[&[f64]],
    format: WavFormat,
    gain: f64,
) -> Result<(), hound::Error> {
    let (bits, sample_format) = match format {
        WavFormat::Pcm16 => (16, hound::SampleFormat::Int),
        WavFormat::Pcm24 => (24, hound::SampleFormat::Int),
        WavFormat::Float32 => (32, hound::SampleFormat::Float),
    };
    let spec = hound::WavSpec {
        channels: channels.len() as u16,
        sample_rate,
        bits_per_sample: bits,
        sample_format,
    };
    let mut file = OutFile::create(path, Contents::Plain).map_err(io::Error::other)?;
    let mut w = hound::WavWriter::new(&mut file, spec)?;
    let n = channels.iter().map(|c| c.len()).min().unwrap_or(0);
    let full = 2f64.powi(bits as i32 - 1);
    for i in 0..n {
        for c in channels {
            let v = c[i] * gain;
            match format {
                WavFormat::Float32 => w.write_sample(v as f32)?,
                _ => {
                    let q = (v * full).round().clamp(-full, full - 1.0) as i32;
                    w.write_sample(q)?
                }
            }
        }
    }
    w.finalize()?;
    file.commit().map_err(io::Error::other)?;
    Ok(())
}

/// The gain that puts the loudest sample of `channels` at [`WAV_PEAK`] of full scale.
pub fn headroom_gain(channels: &[Vec<f64>]) -> f64 {
    let peak = channels
        .iter()
        .flat_map(|c| c.iter())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    if peak > 0.0 {
        WAV_PEAK / peak
    } else {
        1.0
    }
}

/// Rows of a truth file for one segment: (frequency Hz, Re k1 rad/m, attenuation Np/m), every
/// [`TRUTH_FILE_STEP_HZ`] inside the source band.
pub fn truth_rows(truth: &TruthCurve) -> Vec<(f64, f64, f64)> {
    let mut out = Vec::new();
    let mut f = (truth.f0_hz / TRUTH_FILE_STEP_HZ).ceil() * TRUTH_FILE_STEP_HZ;
    while f <= truth.hi_hz() {
        if let Some(k) = truth.at(f) {
            out.push((f, k.re, -k.im));
        }
        f += TRUTH_FILE_STEP_HZ;
    }
    out
}

/// One recorded segment to write with [`write_recordings`].
#[derive(Debug, Clone)]
pub struct RecordedSegment {
    /// Asset id.
    pub segment_id: String,
    /// Its recordings.
    pub recording: HydrantRecording,
    /// Sensor positions, m.
    pub positions_m: Vec<f64>,
}

/// File names inside a recordings directory.
pub const LAYOUT_CSV: &str = "layout.csv";
/// The truth of synthetic recordings.
pub const TRUTH_WAVENUMBERS_CSV: &str = "truth_wavenumbers.csv";

/// Write `dir/layout.csv`, one 16-bit WAV per segment (`<segment_id>.wav`, one channel per
/// sensor) and `dir/truth_wavenumbers.csv`.
pub fn write_recordings(dir: &Path, segments: &[RecordedSegment]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let io = |e: &dyn std::fmt::Display| std::io::Error::other(e.to_string());
    let out = |name: &str| -> std::io::Result<csv::Writer<OutFile>> {
        let f = OutFile::create(&dir.join(name), Contents::Plain).map_err(io::Error::other)?;
        Ok(csv::Writer::from_writer(f))
    };
    let mut layout = out(LAYOUT_CSV)?;
    layout.write_record(crate::recordings::layout::LAYOUT_COLUMNS)?;
    let mut truth = out(TRUTH_WAVENUMBERS_CSV)?;
    truth.write_record([
        "segment_id",
        "frequency_hz",
        "k_re_rad_per_m",
        "attenuation_np_per_m",
    ])?;
    for s in segments {
        let file = format!("{}.wav", s.segment_id);
        let chans: Vec<&[f64]> = s.recording.channels.iter().map(Vec::as_slice).collect();
        write_wav(
            &dir.join(&file),
            s.recording.sample_rate,
            &chans,
            WavFormat::Pcm16,
            headroom_gain(&s.recording.channels),
        )
        .map_err(|e| io(&e))?;
        for (c, x) in s.positions_m.iter().enumerate() {
            layout.write_record([s.segment_id.as_str(), &file, &c.to_string(), &x.to_string()])?;
        }
        for (f, k, a) in truth_rows(&s.recording.truth) {
            truth.write_record([
                s.segment_id.as_str(),
                &f.to_string(),
                &k.to_string(),
                &a.to_string(),
            ])?;
        }
    }
    for w in [layout, truth] {
        let f = w.into_inner().map_err(|e| io(&e))?;
        f.commit().map_err(io::Error::other)?;
    }
    Ok(())
}

/// The usual layout of the seed paper's test (its §4): one sensor at the hydrant, one on each
/// side, at distances drawn in `range_m`.
pub fn seed_layout<R: Rng + ?Sized>(rng: &mut R, range_m: (f64, f64)) -> Vec<f64> {
    let mut d = || (rng.gen_range(range_m.0..range_m.1) * 10.0).round() / 10.0;
    vec![0.0, -d(), d()]
}

/// Sensor distances from the source, m, of the synthetic tests: plastics attenuate within tens
/// of metres in the leak band, so field teams put sensors closer on them.
pub fn sensor_range_m(material: crate::physics::Material) -> (f64, f64) {
    if material.is_plastic() {
        (6.0, 30.0)
    } else {
        (20.0, 80.0)
    }
}

/// Default length of the synthetic recordings, s.
pub const DEFAULT_SECONDS: f64 = 15.0;
/// The longest synthetic recording, s: ten minutes, longer than any hydrant test, and about
/// 5 M samples a channel at [`DEFAULT_SAMPLE_RATE`] (the spectra of the whole record are held
/// in memory while it is made).
pub const MAX_RECORDING_S: f64 = 600.0;

/// A recording length for `synth --recording-seconds`: a finite number of seconds from what
/// `wavenumbers` needs ([`crate::recordings::estimate::MIN_RECORDING_S`]) to [`MAX_RECORDING_S`].
pub fn check_recording_seconds(seconds: f64) -> Result<f64, String> {
    let lo = crate::recordings::estimate::MIN_RECORDING_S;
    if seconds.is_finite() && (lo..=MAX_RECORDING_S).contains(&seconds) {
        Ok(seconds)
    } else {
        Err(format!(
            "{} s is outside {} - {} s (wavenumbers needs at least {} s of recording)",
            crate::units::short(seconds),
            crate::units::short(lo),
            crate::units::short(MAX_RECORDING_S),
            crate::units::short(lo)
        ))
    }
}
/// Default sample rate of the synthetic recordings, Hz.
pub const DEFAULT_SAMPLE_RATE: u32 = 8000;
/// Default sensor noise, fraction of the source channel's RMS.
pub const DEFAULT_NOISE_FRACTION: f64 = 0.3;

/// FNV-1a hash of a segment id, to give each recorded segment its own seed.
fn id_hash(id: &str) -> u64 {
    id.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The system that made a synthetic segment's data (its inventory pipe, the true soil and
/// contact, the hidden effect if any).
pub fn system_of(
    seg: &crate::synth::SynthSegment,
    opts: &crate::synth::SynthOptions,
) -> Result<System, String> {
    let pipe = crate::synth::pipe_of(seg.material, &seg.size);
    let soil = crate::physics::Soil::new(seg.soil_modulus, seg.soil_poisson, seg.soil_density, 0.0)
        .map_err(|e| e.to_string())?;
    let sys = System::new(
        crate::physics::Fluid::water(),
        pipe,
        soil,
        seg.contact,
        opts.model,
        opts.contact_mode,
    )
    .map_err(|e| e.to_string())?;
    match seg.hidden {
        Some((eff, v)) => eff.apply(&sys, v).map_err(|e| e.to_string()),
        None => Ok(sys),
    }
}

/// Hydrant tests of the named segments of a synthetic network: the seed layout (a sensor at the
/// hydrant, one on each side at [`sensor_range_m`]), [`DEFAULT_SAMPLE_RATE`],
/// [`DEFAULT_NOISE_FRACTION`]; each segment's seed from the network seed and its id.
pub fn record_network_segments(
    network: &[crate::synth::SynthSegment],
    opts: &crate::synth::SynthOptions,
    ids: &[String],
    seconds: f64,
) -> Result<Vec<RecordedSegment>, String> {
    ids.iter()
        .map(|id| {
            let seg = network.iter().find(|s| &s.id == id).ok_or_else(|| {
                format!("segment {id} is not in the synthetic network (ids WM10001 ...)")
            })?;
            let sys = system_of(seg, opts)?;
            let seed = opts.seed ^ id_hash(id);
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let positions_m = seed_layout(&mut rng, sensor_range_m(seg.material));
            let spec = RecordingSpec {
                sample_rate: DEFAULT_SAMPLE_RATE,
                seconds,
                positions_m: positions_m.clone(),
                noise_fraction: DEFAULT_NOISE_FRACTION,
                seed: rng.gen(),
            };
            let recording = hydrant_test(&sys, &spec).map_err(|e| format!("segment {id}: {e}"))?;
            Ok(RecordedSegment {
                segment_id: id.clone(),
                recording,
                positions_m,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn source_taper_is_continuous_and_flat_inside() {
        assert_eq!(source_amplitude(SOURCE_LO_HZ, 1000.0), 0.0);
        assert!((source_amplitude(2.0 * SOURCE_LO_HZ - 1e-9, 1000.0) - 1.0).abs() < 1e-6);
        assert_eq!(source_amplitude(500.0, 1000.0), 1.0);
        assert!(source_amplitude(999.999, 1000.0) < 1e-2);
    }

    #[test]
    fn truth_interpolates_linearly() {
        let t = TruthCurve {
            f0_hz: 2.0,
            step_hz: 1.0,
            k1: vec![Complex64::new(1.0, -0.1), Complex64::new(2.0, -0.3)],
        };
        assert_eq!(t.at(2.5), Some(Complex64::new(1.5, -0.2)));
        assert_eq!(t.at(1.9), None);
        assert_eq!(t.at(3.0), Some(Complex64::new(2.0, -0.3)));
    }
}
