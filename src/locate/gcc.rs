//! The delay between two leak-noise recordings by generalised cross-correlation (Knapp &
//! Carter 1976) with its random error from the coherence (P87, Carter 1987).
//!
//! Two stages: a Welch cross-spectrum with segments long enough to hold the largest delay the
//! span allows finds the peak coarsely; channel 2 is then advanced by that many samples, so
//! that short segments (many averages, a well-estimated coherence) see a small residual delay,
//! which is found as the peak of the continuous band-weighted correlation.

use std::path::{Path, PathBuf};

use hound::WavReader;
use num_complex::Complex64;
use realfft::RealFftPlanner;

use super::model::{correlation_peak, Weighting};
use super::LocateError;
use crate::recordings::layout::{SegmentLayout, Sensor};
use crate::recordings::spectra::{welch, Spectra};
use crate::recordings::wav::read_segment;
use crate::units::hz_to_omega;

/// FFT length of the aligned (second) stage, samples at 8 kHz: 0.5 s segments, 2 Hz bins, about
/// 240 averages in 60 s.
pub const ALIGNED_SEGMENT_S: f64 = 0.5;
/// Segments of the coarse stage hold this many times the largest delay, so the peak loses
/// little of its height to the segments' misalignment.
const COARSE_SEGMENT_PER_DELAY: f64 = 4.0;
/// Shortest coarse segment, s.
const MIN_COARSE_SEGMENT_S: f64 = 0.25;
/// Coherence (debiased) below which a frequency carries no usable information: such bins are
/// left out of the band at its edges.
pub const COHERENCE_FLOOR: f64 = 0.1;
/// Coherence used at most in P87: an estimate of 1 would claim an infinitely precise delay.
pub const COHERENCE_CAP: f64 = 0.99;
/// The correlation's peak is told from its neighbours (a carrier period away) when the
/// envelope's error is below this fraction of a period (a slip is then a 4σ event).
const PEAK_SEPARATION: f64 = 8.0;
/// Bins averaged when the coherence is smoothed to find the band's edges.
const SMOOTH_BINS: usize = 5;

/// Two recorded channels, the same length and rate.
#[derive(Debug, Clone)]
pub struct Recording {
    /// Sample rate, Hz.
    pub sample_rate: u32,
    /// Sensor 1.
    pub x1: Vec<f64>,
    /// Sensor 2.
    pub x2: Vec<f64>,
}

/// Where the two recordings of a job are.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingPair {
    /// Sensor 1's WAV file.
    pub file1: PathBuf,
    /// Its channel, from 0.
    pub channel1: u16,
    /// Sensor 2's WAV file.
    pub file2: PathBuf,
    /// Its channel.
    pub channel2: u16,
}

/// Read the two channels (as `wavenumbers` reads a hydrant test), after checking that the two
/// files have one rate, one length and one channel count. `source` and `line` name the job for
/// messages.
pub fn read_pair(
    pair: &RecordingPair,
    source: &Path,
    line: u64,
    job_id: &str,
) -> Result<Recording, LocateError> {
    let err = |m: String| LocateError::Recording(format!("job {job_id}: {m}"));
    if pair.file1 != pair.file2 {
        let head = |p: &Path| {
            WavReader::open(p)
                .map(|r| (r.spec(), r.duration()))
                .map_err(|e| err(format!("{}: not a readable WAV file ({e})", p.display())))
        };
        let (s1, n1) = head(&pair.file1)?;
        let (s2, n2) = head(&pair.file2)?;
        let (a, b) = (pair.file1.display(), pair.file2.display());
        if s1.sample_rate != s2.sample_rate {
            return Err(err(format!(
                "{a} is at {} Hz but {b} at {} Hz; the two sensors must record at one rate",
                s1.sample_rate, s2.sample_rate
            )));
        }
        if n1 != n2 {
            return Err(err(format!(
                "{a} holds {n1} samples per channel but {b} holds {n2}; the two recordings must \
                 start and stop together (one length)"
            )));
        }
        if s1.channels != s2.channels {
            return Err(err(format!(
                "{a} has {} channels but {b} has {}; the two recorders must be set up alike",
                s1.channels, s2.channels
            )));
        }
    }
    let sensor = |file: &Path, channel: u16| Sensor {
        line,
        file: file.display().to_string(),
        path: file.to_path_buf(),
        channel,
        position_m: 0.0,
    };
    let layout = SegmentLayout {
        segment_id: format!("job {job_id}"),
        sensors: vec![
            sensor(&pair.file1, pair.channel1),
            sensor(&pair.file2, pair.channel2),
        ],
    };
    let audio = read_segment(source, &layout, &|_| {})
        .map_err(|e| LocateError::Recording(e.to_string()))?;
    let mut ch = audio.channels.into_iter();
    let (x1, x2) = (ch.next().unwrap_or_default(), ch.next().unwrap_or_default());
    Ok(Recording {
        sample_rate: audio.sample_rate,
        x1,
        x2,
    })
}

/// The measured delay and what it rests on.
#[derive(Debug, Clone, PartialEq)]
pub struct GccDelay {
    /// t₂ − t₁, s.
    pub delay_s: f64,
    /// Its random error from the coherence, P87, s.
    pub delay_std_s: f64,
    /// The band the delay was measured in, Hz.
    pub band_used_hz: (f64, f64),
    /// Why that band.
    pub band_note: String,
    /// Frequencies of the aligned stage inside the band used, Hz.
    pub freqs_hz: Vec<f64>,
    /// |W S₁₂| there (the weighting's magnitude times the cross-spectrum's), for the model.
    pub weights: Vec<f64>,
    /// Length of the record both channels cover after alignment, s.
    pub record_s: f64,
}

/// The weighted cross-spectrum W(ω) G₁₂(ω) at bin k.
fn weighted(s: &Spectra, k: usize, weighting: Weighting) -> Complex64 {
    let g = s.g(0, 1, k);
    match weighting {
        Weighting::Plain => g,
        Weighting::Phat => {
            let m = g.norm();
            if m > 0.0 {
                g / m
            } else {
                Complex64::new(0.0, 0.0)
            }
        }
        Weighting::Scot => {
            let d = (s.g(0, 0, k).re * s.g(1, 1, k).re).sqrt();
            if d > 0.0 {
                g / d
            } else {
                Complex64::new(0.0, 0.0)
            }
        }
    }
}

/// Coherence with the bias of a Welch estimate from n_d averages removed,
/// γ² ≈ (n_d γ̂² − 1)/(n_d − 1) (Bendat & Piersol, Random Data, §9.2.3).
fn debiased_coherence(s: &Spectra, k: usize) -> f64 {
    let g = s.coherence(0, 1, k);
    let n = s.n_eff.max(2.0);
    ((n * g - 1.0) / (n - 1.0)).clamp(0.0, 1.0)
}

/// The delay of channel 2 behind channel 1 within `search_s` (the delays the span allows), in
/// `band_hz`.
pub fn gcc_delay(
    rec: &Recording,
    band_hz: (f64, f64),
    weighting: Weighting,
    search_s: (f64, f64),
) -> Result<GccDelay, String> {
    let fs = rec.sample_rate as f64;
    let n = rec.x1.len().min(rec.x2.len());
    let max_lag = search_s.0.abs().max(search_s.1.abs());
    let want = (COARSE_SEGMENT_PER_DELAY * max_lag).max(MIN_COARSE_SEGMENT_S) * fs;
    let nfft1 = (want.ceil() as usize).next_power_of_two();
    if 2 * nfft1 > n {
        return Err(format!(
            "the recordings are {:.1} s long, too short for a span whose delay can reach \
             {:.3} s: record at least {:.0} s",
            n as f64 / fs,
            max_lag,
            4.0 * nfft1 as f64 / fs
        ));
    }
    if band_hz.1 > 0.5 * fs {
        return Err(format!(
            "the band reaches {} Hz, above half the sample rate ({} Hz)",
            band_hz.1,
            0.5 * fs
        ));
    }
    // Stage 1: the coarse peak over the allowed lags, by one inverse FFT.
    let s1 = welch(&[&rec.x1[..n], &rec.x2[..n]], fs, nfft1, &|_| {})
        .ok_or("the recordings are too short for a cross-spectrum")?;
    let mut planner = RealFftPlanner::<f64>::new();
    let inv = planner.plan_fft_inverse(nfft1);
    let mut spec = inv.make_input_vec();
    for (k, z) in spec.iter_mut().enumerate() {
        let f = k as f64 * s1.bin_hz();
        if f >= band_hz.0 && f <= band_hz.1 && k > 0 && k < nfft1 / 2 {
            *z = weighted(&s1, k, weighting);
        }
    }
    let mut r = inv.make_output_vec();
    inv.process(&mut spec, &mut r)
        .map_err(|e| format!("inverse FFT: {e}"))?;
    let lag_of = |i: usize| {
        if i < nfft1 / 2 {
            i as f64
        } else {
            i as f64 - nfft1 as f64
        }
    };
    let lo = (search_s.0 * fs).floor() - 1.0;
    let hi = (search_s.1 * fs).ceil() + 1.0;
    let coarse = (0..nfft1)
        .filter(|&i| (lo..=hi).contains(&lag_of(i)))
        .max_by(|&a, &b| r[a].total_cmp(&r[b]))
        .map(lag_of)
        .ok_or("no lag inside the span's range")?;
    // Stage 2: advance channel 2 by the coarse lag and measure the residual.
    let shift = coarse as isize;
    let (a, b): (&[f64], &[f64]) = if shift >= 0 {
        let s = shift as usize;
        (&rec.x1[..n - s], &rec.x2[s..n])
    } else {
        let s = (-shift) as usize;
        (&rec.x1[s..n], &rec.x2[..n - s])
    };
    let nfft2 = ((ALIGNED_SEGMENT_S * fs).round() as usize)
        .next_power_of_two()
        .min(nfft1);
    let s2 = welch(&[a, b], fs, nfft2, &|_| {}).ok_or("the recordings are too short")?;
    let df = s2.bin_hz();
    let k0 = ((band_hz.0 / df).ceil() as usize).max(1);
    let k1 = ((band_hz.1 / df).floor() as usize).min(s2.bins() - 2);
    if k1 <= k0 + 2 {
        return Err(format!(
            "the band {}–{} Hz holds too few frequencies",
            band_hz.0, band_hz.1
        ));
    }
    let coh: Vec<f64> = (k0..=k1).map(|k| debiased_coherence(&s2, k)).collect();
    let smooth: Vec<f64> = (0..coh.len())
        .map(|i| {
            let a = i.saturating_sub(SMOOTH_BINS / 2);
            let b = (i + SMOOTH_BINS / 2 + 1).min(coh.len());
            coh[a..b].iter().sum::<f64>() / (b - a) as f64
        })
        .collect();
    let first = smooth.iter().position(|&g| g >= COHERENCE_FLOOR);
    let last = smooth.iter().rposition(|&g| g >= COHERENCE_FLOOR);
    let (Some(i0), Some(i1)) = (first, last) else {
        return Err(format!(
            "the two recordings are not coherent anywhere in {}–{} Hz (coherence below \
             {COHERENCE_FLOOR}): the sensors do not hear the same noise (no leak between them, \
             or a channel is dead)",
            band_hz.0, band_hz.1
        ));
    };
    if i1 < i0 + 2 {
        return Err(format!(
            "only {:.0} Hz of the band {}–{} Hz is coherent; too little for a delay",
            (i1 - i0) as f64 * df,
            band_hz.0,
            band_hz.1
        ));
    }
    let (ka, kb) = (k0 + i0, k0 + i1);
    let used = (ka as f64 * df, kb as f64 * df);
    let band_note = match (ka > k0 + 1, kb + 1 < k1) {
        (false, false) => "all of it coherent".to_string(),
        (true, false) => format!(
            "coherent from {:.0} Hz (below, the coherence is under {COHERENCE_FLOOR})",
            used.0
        ),
        (false, true) => format!(
            "coherent up to {:.0} Hz (above, the coherence is under {COHERENCE_FLOOR}: the \
             path's attenuation leaves only sensor noise)",
            used.1
        ),
        (true, true) => format!(
            "coherent in {:.0}–{:.0} Hz only (outside, the coherence is under {COHERENCE_FLOOR})",
            used.0, used.1
        ),
    };
    let mut omega = Vec::with_capacity(kb - ka + 1);
    let mut w = Vec::with_capacity(kb - ka + 1);
    let mut phi = Vec::with_capacity(kb - ka + 1);
    let mut info = 0.0;
    let mut prev: Option<f64> = None;
    // Phase variance of each bin (P75), for the error of the phase slope (the envelope).
    let mut inv_var = Vec::with_capacity(kb - ka + 1);
    for k in ka..=kb {
        let z = weighted(&s2, k, weighting);
        let om = hz_to_omega(k as f64 * df);
        // φ = −arg(W G₁₂), unwrapped from the band's low edge: the residual delay is a few
        // samples at most, so the phase moves by far less than π between bins.
        let mut p = -z.arg();
        if let Some(q) = prev {
            p += std::f64::consts::TAU * ((q - p) / std::f64::consts::TAU).round();
        }
        prev = Some(p);
        omega.push(om);
        w.push(z.norm());
        phi.push(p);
        let g = coh[k - k0].min(COHERENCE_CAP);
        info += om * om * g / (1.0 - g);
        inv_var.push(g.max(1e-6) * 2.0 * s2.n_eff / (1.0 - g));
    }
    // Error of the weighted slope of φ(ω): the group delay the envelope gives. When it is not
    // well inside a carrier period the correlation's neighbouring peaks cannot be told apart,
    // and the delay is only as good as the envelope.
    let sw: f64 = inv_var.iter().sum();
    let mean_om = omega.iter().zip(&inv_var).map(|(o, w)| o * w).sum::<f64>() / sw;
    let sxx: f64 = omega
        .iter()
        .zip(&inv_var)
        .map(|(o, w)| w * (o - mean_om) * (o - mean_om))
        .sum();
    let envelope_std = sxx.recip().sqrt();
    let residual = correlation_peak(&omega, &w, &phi);
    let record_s = a.len() as f64 / fs;
    // eq. P87 with the integral over ω as a sum over bins of width 2π Δf.
    let sum = record_s / std::f64::consts::PI * info * std::f64::consts::TAU * df;
    let fine_std = if sum > 0.0 {
        sum.recip().sqrt()
    } else {
        f64::INFINITY
    };
    let period = 2.0 / (used.0 + used.1);
    let mut band_note = band_note;
    let delay_std_s = if envelope_std > period / PEAK_SEPARATION {
        band_note.push_str(&format!(
            "; the coherent band is too narrow to tell the correlation's neighbouring peaks \
             apart (envelope error {:.2} ms against a {:.2} ms period): the delay's error is \
             the envelope's",
            envelope_std * 1e3,
            period * 1e3
        ));
        fine_std.hypot(envelope_std)
    } else {
        fine_std
    };
    Ok(GccDelay {
        delay_s: coarse / fs + residual,
        delay_std_s,
        band_used_hz: used,
        band_note,
        freqs_hz: omega.iter().map(|&o| o / std::f64::consts::TAU).collect(),
        weights: w,
        record_s,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// White noise delayed by a fractional number of samples (in the frequency domain), plus
    /// independent noise: the delay comes back within a few of its own errors.
    #[test]
    fn recovers_a_fractional_delay() {
        let fs = 8000.0;
        let n = 8000 * 20;
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x: Vec<f64> = (0..n).map(|_| crate::stats::normal(&mut rng)).collect();
        let mut planner = RealFftPlanner::<f64>::new();
        let fwd = planner.plan_fft_forward(n);
        let inv = planner.plan_fft_inverse(n);
        let mut spec = fwd.make_output_vec();
        fwd.process(&mut x.clone(), &mut spec).unwrap();
        let delay = 0.0123456;
        for (k, z) in spec.iter_mut().enumerate() {
            let w = std::f64::consts::TAU * k as f64 * fs / n as f64;
            *z *= Complex64::from_polar(1.0 / n as f64, -w * delay);
        }
        let last = spec.len() - 1;
        spec[last].im = 0.0;
        let mut y = inv.make_output_vec();
        inv.process(&mut spec, &mut y).unwrap();
        let noisy = |v: &[f64], rng: &mut ChaCha8Rng| -> Vec<f64> {
            v.iter()
                .map(|a| a + 0.5 * crate::stats::normal(rng))
                .collect()
        };
        let rec = Recording {
            sample_rate: 8000,
            x1: noisy(&x, &mut rng),
            x2: noisy(&y, &mut rng),
        };
        for weighting in [Weighting::Phat, Weighting::Scot, Weighting::Plain] {
            let d = gcc_delay(&rec, (100.0, 800.0), weighting, (-0.05, 0.05)).unwrap();
            let z = (d.delay_s - delay) / d.delay_std_s;
            assert!(z.abs() < 4.0, "{weighting:?}: {} ({z})", d.delay_s);
            assert!(d.delay_std_s < 2e-5, "{}", d.delay_std_s);
            assert!(
                d.band_note.contains("all of it coherent"),
                "{}",
                d.band_note
            );
        }
    }
}
