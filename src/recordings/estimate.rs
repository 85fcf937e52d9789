//! Wavenumbers from the spectra of a hydrant test (model §10).
//!
//! For each segment:
//! 1. the delay of every sensor behind the one nearest the source, from the coherence-weighted
//!    cross-correlation (a sensor that hears the source before one nearer to it has its position
//!    on the wrong side, or swapped: an error);
//! 2. the channels shifted by those whole-sample delays, so every Welch segment holds the same
//!    stretch of the travelling wave in all channels (without this the finite segment biases
//!    |G_ab| low by the window's autocorrelation at the delay, ~3 % at 80 m of iron);
//! 3. for each pair of neighbouring sensors on one side of the source, the transfer function
//!    (P73; with a third channel, the estimator P77 that reference-sensor noise does not bias),
//!    its phase unwrapped from low frequency, and per bin Re k1 and the attenuation (P74) with
//!    their variances (P75, generalised to any ratio of cross-spectra below);
//! 4. per band: a weighted mean over the bins (P75 weights, and the choice of bins, from the
//!    variances and coherence of the *neighbouring* bins only, so neither depends on the bin's
//!    own noise: [`VARIANCE_SMOOTHING_BINS`]; the correlation of neighbouring Hann bins
//!    counted), then a generalised-least-squares mean over the pairs with their covariances;
//!    the two sides compared (P76) and combined.
//!
//! **Errors of a ratio of cross-spectra.** Every estimator used is ln H = Σ_r s_r ln Ĝ_{x_r y_r}
//! (H1: ln G_ab − ln G_aa; P77: ln G_cb − ln G_ca). For Gaussian signals, Isserlis' theorem gives
//! for Welch averages over n_d independent segments
//! E[δĜ_xy δĜ_uv*] = G_xu G_vy / n_d and E[δĜ_xy δĜ_uv] = G_xv G_uy / n_d, so to first order
//! (Bendat & Piersol, *Random Data*, §9.2, the method behind P75)
//! Cov(ln H, ln H') = Σ_r Σ_q s_r s'_q (…)/(G_r G'_q*), whose real part gives the covariance of
//! ln|H| and the imaginary part that of arg H. For H1 it is exactly P75:
//! var = (1 − γ²)/(2 n_d γ²) for both parts; for P77 with independent sensor noise it is
//! (1/γ²_cb + 1/γ²_ca − 2γ²_ab/(γ²_ac γ²_bc))/(2 n_d). The same formula gives the covariance of
//! two pairs' estimates that share channels, so pairs and sides are combined with their
//! correlation.

use std::path::Path;

use num_complex::Complex64;
use realfft::RealFftPlanner;

use super::layout::{SegmentLayout, Sensor};
use super::spectra::{welch, Spectra, MAX_CORRELATED_BIN_OFFSET};
use super::wav::{read_segment, SegmentAudio};
use super::{short, RecordingError};
use crate::optimize::linalg::solve_spd;

/// Length of a Welch segment, s: 1 Hz bins, fine enough to unwrap the phase of spans up to
/// about 100 m at 1,000 m/s (model §10).
pub const WELCH_SEGMENT_S: f64 = 1.0;
/// Length of the segments of the delay estimate, s: long, so delays up to half of it (2 s) are
/// unambiguous and the cross-correlation keeps its coherence at large delays.
pub const DELAY_SEGMENT_S: f64 = 4.0;
/// The shortest recording the analysis can use, s: one and a half delay segments.
pub const MIN_RECORDING_S: f64 = 1.5 * DELAY_SEGMENT_S;
/// Highest analysed frequency as a fraction of the sample rate (below the anti-alias filter).
pub const MAX_FREQUENCY_FRACTION: f64 = 0.45;
/// A bin is used only when the standard error of its phase is below this, rad: a 2π slip of
/// the unwrapping is then a 12-sigma event.
pub const UNWRAP_MAX_SIGMA_RAD: f64 = 0.5;
/// The unwrapping stops at a gap wider than this, Hz, in the usable bins: the phase trend
/// cannot be carried safely across it.
pub const UNWRAP_MAX_GAP_HZ: f64 = 20.0;
/// The unwrapping predicts each bin from a straight line fitted to this many preceding usable
/// bins: with a phase error of 0.5 rad per bin the line's slope is good to 0.01 rad per bin, so a
/// gap of [`UNWRAP_MAX_GAP_HZ`] adds well under π.
pub const UNWRAP_LINE_BINS: usize = 32;
/// Half-width, bins, of the running mean that smooths the variance and coherence estimates
/// before they weight or select a bin. The mean leaves out the bin itself and its neighbours up
/// to [`MAX_CORRELATED_BIN_OFFSET`] (whose Welch estimates are correlated with it), so a bin's
/// weight and its selection are statistically independent of its own estimate: a weight or a
/// threshold taken from a bin's own noisy spectra favours bins whose cross-spectrum G_cb of
/// eq. P77 happens to be high, which biases ln|H| up and the attenuation of eq. P74 low, by up
/// to half its P75–P76 standard error in the bands where the coherence falls towards
/// [`EstimateOptions::min_coherence`] (model §10: "averaging ln|H| over noisy bins is itself
/// biased; weight by (P75)"). Measured on 40 synthetic metal pipes (examples/
/// wavenumbers_calibration.rs): mean attenuation z −0.47 in each pipe's top 5 bands with the
/// bin included, and the fitted c_P 0.8σ low on average.
pub const VARIANCE_SMOOTHING_BINS: usize = 7;
/// A pair contributes to a band only when at least this fraction of the band's bins is usable.
pub const MIN_BAND_FILL: f64 = 0.5;
/// Sides disagreeing by more than this many standard errors of their difference (P76) are
/// reported as `reflection_suspected`.
pub const REFLECTION_Z: f64 = 3.0;
/// A delay is trusted only when at least this many bins of the delay spectra have
/// coherence ≥ 0.5.
pub const DELAY_MIN_COHERENT_BINS: usize = 20;
/// A sensor stated farther from the source than its neighbour must not hear the source more than
/// this many samples before it.
pub const ORDER_TOLERANCE_SAMPLES: i64 = 2;

/// Note on a band whose sides disagree beyond [`REFLECTION_Z`].
pub const NOTE_REFLECTION: &str = "reflection_suspected";
/// Note on a band estimated with H1 (only two channels): reference noise biases the attenuation
/// high (model §10).
pub const NOTE_H1: &str = "h1_reference_noise_bias";
/// Note on a band whose attenuation came out below zero and was set to zero.
pub const NOTE_ATT_CLIPPED: &str = "attenuation_below_zero_set_to_0";

/// Settings of the analysis (the `wavenumbers` options).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimateOptions {
    /// Band width, Hz.
    pub band_hz: f64,
    /// Lowest coherence γ² of a pair's bin to be used.
    pub min_coherence: f64,
    /// Lower edge of the first band, Hz.
    pub fmin_hz: f64,
    /// Upper edge of the bands, Hz (default: 0.45 × the sample rate).
    pub fmax_hz: Option<f64>,
}

impl Default for EstimateOptions {
    fn default() -> Self {
        Self {
            band_hz: 20.0,
            min_coherence: 0.3,
            fmin_hz: 10.0,
            fmax_hz: None,
        }
    }
}

impl EstimateOptions {
    /// Checked options.
    pub fn new(
        band_hz: f64,
        min_coherence: f64,
        fmin_hz: f64,
        fmax_hz: Option<f64>,
    ) -> Result<Self, String> {
        if !(band_hz.is_finite() && band_hz >= 2.0 * WELCH_SEGMENT_S.recip()) {
            return Err(format!(
                "--band-hz {} must be at least 2 Hz (two 1-Hz bins)",
                short(band_hz)
            ));
        }
        if !(min_coherence > 0.0 && min_coherence < 1.0) {
            return Err(format!(
                "--min-coherence {} must be between 0 and 1",
                short(min_coherence)
            ));
        }
        if !(fmin_hz.is_finite() && fmin_hz >= 0.0) {
            return Err(format!("--fmin {} must be 0 or more Hz", short(fmin_hz)));
        }
        if let Some(f) = fmax_hz {
            if !(f.is_finite() && f > fmin_hz + band_hz) {
                return Err(format!(
                    "--fmax {} must be above --fmin + --band-hz ({} Hz)",
                    short(f),
                    short(fmin_hz + band_hz)
                ));
            }
        }
        Ok(Self {
            band_hz,
            min_coherence,
            fmin_hz,
            fmax_hz,
        })
    }
}

/// The wavenumber of one band.
#[derive(Debug, Clone, PartialEq)]
pub struct BandEstimate {
    /// Frequency, Hz: the weighted mean frequency of the bins used (so a wavenumber linear in
    /// frequency across the band is reported at the right frequency).
    pub frequency_hz: f64,
    /// Re k1, rad/m (eq. P74).
    pub k_re: f64,
    /// Its standard error, rad/m (P75–P76).
    pub k_re_std: f64,
    /// Attenuation −Im k1, Np/m (eq. P74).
    pub attenuation: f64,
    /// Its standard error, Np/m.
    pub attenuation_std: f64,
    /// Sensor pairs that contributed.
    pub pairs: usize,
    /// Notes (codes).
    pub notes: Vec<&'static str>,
}

/// The result of one segment.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentWavenumbers {
    /// Asset id.
    pub segment_id: String,
    /// Usable bands, ascending in frequency.
    pub bands: Vec<BandEstimate>,
    /// Length of the analysed record, s.
    pub duration_s: f64,
    /// Sample rate, Hz.
    pub sample_rate: u32,
}

/// Read a segment's recordings and estimate its wavenumbers. `progress` is called with frames
/// processed (three times the frames of the files in all: reading and two spectral passes).
pub fn analyse_segment(
    layout_path: &Path,
    seg: &SegmentLayout,
    opts: &EstimateOptions,
    progress: &dyn Fn(u64),
) -> Result<SegmentWavenumbers, RecordingError> {
    let audio = read_segment(layout_path, seg, progress)?;
    analyse_audio(layout_path, seg, &audio, opts, progress)
}

/// One term s·ln G_xy of an estimator.
#[derive(Debug, Clone, Copy)]
struct Term {
    x: usize,
    y: usize,
    s: f64,
}

/// A pair of sensors on one side, a nearer `a` and a farther `b`, with its per-bin estimates.
struct Pair {
    side: i8,
    terms: Vec<Term>,
    /// Per bin: Re k1, attenuation, their (smoothed) variances, usable.
    k: Vec<f64>,
    att: Vec<f64>,
    var_k: Vec<f64>,
    var_att: Vec<f64>,
    usable: Vec<bool>,
}

/// ln H of an estimator at a bin, or `None` where a spectrum is zero.
fn ln_h(sp: &Spectra, terms: &[Term], k: usize) -> Option<Complex64> {
    let mut z = Complex64::new(0.0, 0.0);
    for t in terms {
        let g = sp.g(t.x, t.y, k);
        if g.norm().is_nan() || g.norm() <= 0.0 || !g.re.is_finite() || !g.im.is_finite() {
            return None;
        }
        z += t.s * g.ln();
    }
    Some(z)
}

/// First-order covariance of two estimators' ln H at a bin (module doc): (Re–Re, Im–Im).
fn ln_h_cov(sp: &Spectra, e1: &[Term], e2: &[Term], k: usize) -> (f64, f64) {
    let mut p = Complex64::new(0.0, 0.0);
    let mut q = Complex64::new(0.0, 0.0);
    for r in e1 {
        let gr = sp.g(r.x, r.y, k);
        for t in e2 {
            let gt = sp.g(t.x, t.y, k);
            let s = r.s * t.s;
            p += s * sp.g(r.x, t.x, k) * sp.g(t.y, r.y, k) / (gr * gt.conj());
            q += s * sp.g(r.x, t.y, k) * sp.g(t.x, r.y, k) / (gr * gt);
        }
    }
    let n2 = 2.0 * sp.n_eff;
    ((p + q).re / n2, (p - q).re / n2)
}

/// Running mean of the finite entries of `v` at offsets `skip` < |j − i| ≤ `half` from each
/// entry i: the entry itself and its `skip` nearest neighbours on each side are left out (see
/// [`VARIANCE_SMOOTHING_BINS`]). NaN where `v[i]` is NaN or no neighbour is finite.
fn smooth_others(v: &[f64], half: usize, skip: usize) -> Vec<f64> {
    (0..v.len())
        .map(|i| {
            if !v[i].is_finite() {
                return f64::NAN;
            }
            let lo = i.saturating_sub(half);
            let hi = (i + half + 1).min(v.len());
            let (s, n) = (lo..hi)
                .filter(|&j| j.abs_diff(i) > skip && v[j].is_finite())
                .fold((0.0, 0usize), |(s, n), j| (s + v[j], n + 1));
            if n == 0 {
                f64::NAN
            } else {
                s / n as f64
            }
        })
        .collect()
}

/// The delay of channel `x` behind channel `r`, s, from the coherence-weighted cross-correlation
/// (Hannan–Thomson weights γ²/(1 − γ²)); `None` when too few bins are coherent to trust it.
fn delay(sp: &Spectra, r: usize, x: usize, max_bin: usize) -> Option<f64> {
    let n = sp.nfft;
    let mut planner = RealFftPlanner::<f64>::new();
    let inv = planner.plan_fft_inverse(n);
    let mut spec = inv.make_input_vec();
    let mut coherent = 0usize;
    for (k, z) in spec.iter_mut().enumerate().take(max_bin + 1).skip(1) {
        let g = sp.g(r, x, k);
        let c = sp.coherence(r, x, k).min(0.99);
        if c >= 0.5 {
            coherent += 1;
        }
        if g.norm() > 0.0 {
            *z = g / g.norm() * (c / (1.0 - c));
        }
    }
    if coherent < DELAY_MIN_COHERENT_BINS {
        return None;
    }
    let mut out = inv.make_output_vec();
    inv.process(&mut spec, &mut out).ok()?;
    let (imax, _) =
        out.iter().enumerate().fold(
            (0, f64::NEG_INFINITY),
            |acc, (i, &v)| if v > acc.1 { (i, v) } else { acc },
        );
    let lag = if imax <= n / 2 {
        imax as f64
    } else {
        imax as f64 - n as f64
    };
    Some(lag / sp.sample_rate)
}

fn sensor_text(s: &Sensor) -> String {
    format!(
        "the sensor of line {} ({} channel {}, position {} m)",
        s.line,
        s.file,
        s.channel,
        short(s.position_m)
    )
}

/// The chains of sensors from the source outward on each side (a sensor at position 0 starts
/// both), as indices into `sensors`.
fn side_chains(sensors: &[Sensor]) -> Vec<(i8, Vec<usize>)> {
    let at_source: Vec<usize> = (0..sensors.len())
        .filter(|&i| sensors[i].position_m == 0.0)
        .collect();
    let mut out = Vec::new();
    for side in [-1i8, 1] {
        let mut chain: Vec<usize> = (0..sensors.len())
            .filter(|&i| sensors[i].position_m * side as f64 > 0.0)
            .collect();
        chain.sort_by(|&i, &j| sensors[i].distance_m().total_cmp(&sensors[j].distance_m()));
        let mut full = at_source.clone();
        full.extend(chain);
        if full.len() >= 2 {
            out.push((side, full));
        }
    }
    out
}

/// The unwrapped phase at bin `k` predicted by a least-squares line through the last
/// [`UNWRAP_LINE_BINS`] unwrapped bins `done` (the last value when there is only one).
fn line_prediction(done: &[usize], psi: &[f64], k: usize) -> f64 {
    let last = &done[done.len().saturating_sub(UNWRAP_LINE_BINS)..];
    let n = last.len() as f64;
    let mx = last.iter().map(|&i| i as f64).sum::<f64>() / n;
    let my = last.iter().map(|&i| psi[i]).sum::<f64>() / n;
    let sxx: f64 = last.iter().map(|&i| (i as f64 - mx).powi(2)).sum();
    let sxy: f64 = last.iter().map(|&i| (i as f64 - mx) * (psi[i] - my)).sum();
    if sxx > 0.0 {
        my + sxy / sxx * (k as f64 - mx)
    } else {
        my
    }
}

/// Estimate a segment's wavenumbers from its channels (one per sensor, layout order).
pub fn analyse_audio(
    layout_path: &Path,
    seg: &SegmentLayout,
    audio: &SegmentAudio,
    opts: &EstimateOptions,
    progress: &dyn Fn(u64),
) -> Result<SegmentWavenumbers, RecordingError> {
    let sensors = &seg.sensors;
    let pos_err = |message: String| RecordingError::Positions {
        segment_id: seg.segment_id.clone(),
        layout: layout_path.to_path_buf(),
        message,
    };
    let fs = audio.sample_rate as f64;
    let chains = side_chains(sensors);
    if chains.is_empty() {
        return Err(pos_err(
            "no two sensors on one side of the source (nor one at position 0): a wavenumber needs a pair on one side"
                .into(),
        ));
    }
    let nfft_delay = (DELAY_SEGMENT_S * fs).round() as usize;
    let nfft = (WELCH_SEGMENT_S * fs).round() as usize;
    let needed_s = MIN_RECORDING_S;
    if audio.duration_s() < needed_s || nfft < 16 {
        return Err(pos_err(format!(
            "the recordings are {} s long at {} Hz; at least {} s are needed",
            short(audio.duration_s()),
            audio.sample_rate,
            short(needed_s)
        )));
    }
    let fmax = opts
        .fmax_hz
        .unwrap_or(f64::INFINITY)
        .min(MAX_FREQUENCY_FRACTION * fs);
    // 1. Delays behind the sensor nearest the source.
    let refi = (0..sensors.len())
        .min_by(|&i, &j| sensors[i].distance_m().total_cmp(&sensors[j].distance_m()))
        .unwrap_or(0);
    let raw: Vec<&[f64]> = audio.channels.iter().map(Vec::as_slice).collect();
    let sp_d = welch(&raw, fs, nfft_delay, progress)
        .ok_or_else(|| pos_err("the recordings are too short".into()))?;
    let max_bin_d = ((fmax / sp_d.bin_hz()).floor() as usize).min(sp_d.bins() - 1);
    let delays: Vec<Option<f64>> = (0..sensors.len())
        .map(|x| {
            if x == refi {
                Some(0.0)
            } else {
                delay(&sp_d, refi, x, max_bin_d)
            }
        })
        .collect();
    for (_, chain) in &chains {
        for w in chain.windows(2) {
            let (a, b) = (w[0], w[1]);
            if let (Some(ta), Some(tb)) = (delays[a], delays[b]) {
                if ((tb - ta) * fs).round() < -(ORDER_TOLERANCE_SAMPLES as f64) {
                    return Err(pos_err(format!(
                        "positions on the wrong side or swapped: {} hears the source {} s before {}, \
                         although it is stated farther from the source (check the sign and order of position_m)",
                        sensor_text(&sensors[b]),
                        short(ta - tb),
                        sensor_text(&sensors[a])
                    )));
                }
            }
        }
    }
    // 2. Align the channels by whole samples.
    let shifts: Vec<i64> = delays
        .iter()
        .map(|d| d.map_or(0, |t| (t * fs).round() as i64))
        .collect();
    let base = shifts.iter().copied().min().unwrap_or(0);
    let shifts: Vec<usize> = shifts.iter().map(|&d| (d - base) as usize).collect();
    let max_shift = shifts.iter().copied().max().unwrap_or(0);
    let n_all = audio.channels.iter().map(Vec::len).min().unwrap_or(0);
    if n_all <= max_shift + 2 * nfft {
        return Err(pos_err(
            "the recordings are too short for the delays between the sensors".into(),
        ));
    }
    let n_common = n_all - max_shift;
    let aligned: Vec<&[f64]> = audio
        .channels
        .iter()
        .zip(&shifts)
        .map(|(c, &d)| &c[d..d + n_common])
        .collect();
    let sp = welch(&aligned, fs, nfft, progress)
        .ok_or_else(|| pos_err("the recordings are too short".into()))?;
    let max_bin = ((fmax / sp.bin_hz()).floor() as usize).min(sp.bins() - 1);
    let lo_bin = ((opts.fmin_hz / sp.bin_hz()).ceil() as usize).max(1);
    // 3. Pairs and their per-bin estimates.
    let m = sensors.len();
    let mut pairs: Vec<Pair> = Vec::new();
    for (side, chain) in &chains {
        for w in chain.windows(2) {
            let (a, b) = (w[0], w[1]);
            let delta = sensors[b].distance_m() - sensors[a].distance_m();
            // The third channel with the best coherence with both (P77); H1 with two channels.
            let third = (0..m).filter(|&c| c != a && c != b).max_by(|&c1, &c2| {
                let score = |c: usize| {
                    let mut v: Vec<f64> = (lo_bin..=max_bin)
                        .map(|k| sp.coherence(c, a, k).min(sp.coherence(c, b, k)))
                        .collect();
                    v.sort_by(f64::total_cmp);
                    v.get(v.len() / 2).copied().unwrap_or(0.0)
                };
                score(c1).total_cmp(&score(c2))
            });
            let terms = match third {
                Some(c) => vec![
                    Term { x: c, y: b, s: 1.0 },
                    Term {
                        x: c,
                        y: a,
                        s: -1.0,
                    },
                ],
                None => vec![
                    Term { x: a, y: b, s: 1.0 },
                    Term {
                        x: a,
                        y: a,
                        s: -1.0,
                    },
                ],
            };
            pairs.push(pair_curve(
                &sp,
                a,
                b,
                *side,
                delta,
                terms,
                max_bin,
                shifts[b] as f64 - shifts[a] as f64,
                opts,
            ));
        }
    }
    // 4. Bands.
    let mut bands = Vec::new();
    let mut f_lo = opts.fmin_hz;
    while f_lo + opts.band_hz <= fmax + 1e-9 {
        let f_hi = f_lo + opts.band_hz;
        if let Some(mut b) = band(&sp, &pairs, f_lo, f_hi) {
            if m == 2 {
                b.notes.push(NOTE_H1);
            }
            bands.push(b);
        }
        f_lo = f_hi;
    }
    Ok(SegmentWavenumbers {
        segment_id: seg.segment_id.clone(),
        bands,
        duration_s: audio.duration_s(),
        sample_rate: audio.sample_rate,
    })
}

/// Per-bin estimates of one pair: ln H, its variances (smoothed), the usable bins and the phase
/// unwrapped from low frequency (`shift_ab` = d_b − d_a, the alignment in samples, put back).
#[allow(clippy::too_many_arguments)]
fn pair_curve(
    sp: &Spectra,
    a: usize,
    b: usize,
    side: i8,
    delta: f64,
    terms: Vec<Term>,
    max_bin: usize,
    shift_ab: f64,
    opts: &EstimateOptions,
) -> Pair {
    let nb = max_bin + 1;
    let mut lnh = vec![Complex64::new(f64::NAN, f64::NAN); nb];
    let mut v_re = vec![f64::NAN; nb];
    let mut v_im = vec![f64::NAN; nb];
    for k in 1..nb {
        if let Some(z) = ln_h(sp, &terms, k) {
            let (vr, vi) = ln_h_cov(sp, &terms, &terms, k);
            if vr.is_finite() && vi.is_finite() {
                lnh[k] = z;
                v_re[k] = vr.max(1e-12);
                v_im[k] = vi.max(1e-12);
            }
        }
    }
    // Weights and selection from the neighbours only (VARIANCE_SMOOTHING_BINS).
    let skip = MAX_CORRELATED_BIN_OFFSET;
    let v_re = smooth_others(&v_re, VARIANCE_SMOOTHING_BINS, skip);
    // A bin's own phase variance, before smoothing: it decides only whether the bin may carry
    // the phase trend of the unwrapping, never whether the bin is used.
    let own_im = v_im.clone();
    let v_im = smooth_others(&v_im, VARIANCE_SMOOTHING_BINS, skip);
    let coh: Vec<f64> = (0..nb)
        .map(|k| {
            if lnh[k].re.is_finite() {
                sp.coherence(a, b, k)
            } else {
                f64::NAN
            }
        })
        .collect();
    let coh = smooth_others(&coh, VARIANCE_SMOOTHING_BINS, skip);
    // Used: the neighbours say the bin carries information (independent of its own estimate).
    let mut usable: Vec<bool> = (0..nb)
        .map(|k| {
            k >= 1
                && v_im[k].is_finite()
                && coh[k] >= opts.min_coherence
                && v_im[k].sqrt() <= UNWRAP_MAX_SIGMA_RAD
        })
        .collect();
    // Anchors of the unwrapping: bins whose own phase is good to UNWRAP_MAX_SIGMA_RAD and whose
    // own coherence passes, so one bin with a wild phase cannot slip the trend by 2π.
    let anchor: Vec<bool> = (0..nb)
        .map(|k| {
            k >= 1
                && lnh[k].im.is_finite()
                && sp.coherence(a, b, k) >= opts.min_coherence
                && own_im[k].sqrt() <= UNWRAP_MAX_SIGMA_RAD
        })
        .collect();
    // Unwrap the aligned phase from the lowest anchor upward, predicting each bin from the
    // slope of the last anchors; it starts near 0 because the alignment removed the delay.
    // A used bin that is not an anchor takes the branch nearest the prediction (its error is
    // then within ±π, symmetric: no bias) and does not move the trend.
    let mut psi = vec![f64::NAN; nb];
    let mut done: Vec<usize> = Vec::new();
    let max_gap = (UNWRAP_MAX_GAP_HZ / sp.bin_hz()).ceil() as usize;
    for k in 1..nb {
        if !(usable[k] || anchor[k]) {
            continue;
        }
        let w = lnh[k].im;
        let value = match done.last() {
            None if anchor[k] => w,
            None => continue,
            Some(&p) if k - p > max_gap => {
                // Lost the trend: nothing above can be trusted.
                for u in usable.iter_mut().skip(k) {
                    *u = false;
                }
                break;
            }
            Some(_) => {
                let pred = line_prediction(&done, &psi, k);
                w + std::f64::consts::TAU * ((pred - w) / std::f64::consts::TAU).round()
            }
        };
        psi[k] = value;
        if anchor[k] {
            done.push(k);
        }
    }
    let mut k_re = vec![f64::NAN; nb];
    let mut att = vec![f64::NAN; nb];
    for k in 1..nb {
        if !(usable[k] && psi[k].is_finite()) {
            continue;
        }
        let omega_shift = std::f64::consts::TAU * k as f64 / sp.nfft as f64 * shift_ab;
        let phi = psi[k] - omega_shift;
        k_re[k] = -phi / delta;
        att[k] = -lnh[k].re / delta;
    }
    let d2 = delta * delta;
    Pair {
        side,
        terms,
        k: k_re,
        att,
        var_k: v_im.iter().map(|v| v / d2).collect(),
        var_att: v_re.iter().map(|v| v / d2).collect(),
        usable,
    }
}

/// A pair's band mean: bins used, weights, centroid frequency, mean k and attenuation.
struct PairBand {
    bins: Vec<usize>,
    w: Vec<f64>,
    wsum: f64,
    f: f64,
    k: f64,
    att: f64,
}

fn pair_band(sp: &Spectra, p: &Pair, k_lo: usize, k_hi: usize) -> Option<PairBand> {
    let all = k_hi.saturating_sub(k_lo);
    let bins: Vec<usize> = (k_lo..k_hi.min(p.usable.len()))
        .filter(|&k| p.usable[k] && p.k[k].is_finite())
        .collect();
    if all == 0 || (bins.len() as f64) < MIN_BAND_FILL * all as f64 {
        return None;
    }
    let w: Vec<f64> = bins
        .iter()
        .map(|&k| 2.0 / (p.var_k[k] + p.var_att[k]))
        .collect();
    let wsum: f64 = w.iter().sum();
    let mean = |v: &dyn Fn(usize) -> f64| {
        bins.iter().zip(&w).map(|(&k, wi)| wi * v(k)).sum::<f64>() / wsum
    };
    Some(PairBand {
        f: mean(&|k| k as f64 * sp.bin_hz()),
        k: mean(&|k| p.k[k]),
        att: mean(&|k| p.att[k]),
        bins,
        w,
        wsum,
    })
}

/// Covariances (k, attenuation) of two pairs' band means, neighbouring-bin correlation counted.
fn band_cov(
    sp: &Spectra,
    p: &Pair,
    bp: &PairBand,
    q: &Pair,
    bq: &PairBand,
    same: bool,
) -> (f64, f64) {
    // Per-bin correlation coefficient of the two estimators (1 for a pair with itself).
    let rho = |k: usize| -> (f64, f64) {
        if same {
            return (1.0, 1.0);
        }
        let (c_re, c_im) = ln_h_cov(sp, &p.terms, &q.terms, k);
        let (pr, pi) = ln_h_cov(sp, &p.terms, &p.terms, k);
        let (qr, qi) = ln_h_cov(sp, &q.terms, &q.terms, k);
        let clamp = |x: f64| {
            if x.is_finite() {
                x.clamp(-0.99, 0.99)
            } else {
                0.0
            }
        };
        (
            clamp(c_im / (pi * qi).sqrt()),
            clamp(c_re / (pr * qr).sqrt()),
        )
    };
    let (mut ck, mut ca) = (0.0, 0.0);
    let mut j0 = 0usize;
    for (i, &ki) in bp.bins.iter().enumerate() {
        while j0 < bq.bins.len() && bq.bins[j0] + MAX_CORRELATED_BIN_OFFSET < ki {
            j0 += 1;
        }
        let (ri_k, ri_a) = rho(ki);
        for (j, &kj) in bq.bins.iter().enumerate().skip(j0) {
            if kj > ki + MAX_CORRELATED_BIN_OFFSET {
                break;
            }
            let r = sp.bin_correlation[ki.abs_diff(kj)];
            let (rk, ra) = if ki == kj {
                (ri_k, ri_a)
            } else {
                let (a, b) = rho(kj);
                ((ri_k + a) / 2.0, (ri_a + b) / 2.0)
            };
            let ww = bp.w[i] * bq.w[j] * r;
            ck += ww * rk * (p.var_k[ki] * q.var_k[kj]).sqrt();
            ca += ww * ra * (p.var_att[ki] * q.var_att[kj]).sqrt();
        }
    }
    let norm = bp.wsum * bq.wsum;
    (ck / norm, ca / norm)
}

/// Generalised least squares mean of correlated estimates: (mean, variance, weights).
fn gls(e: &[f64], c: &[f64]) -> (f64, f64, Vec<f64>) {
    let n = e.len();
    let ones = vec![1.0; n];
    let x = solve_spd(c, n, &ones);
    let s: f64 = x.iter().sum();
    if s > 0.0 && s.is_finite() && x.iter().all(|v| v.is_finite()) {
        let lambda: Vec<f64> = x.iter().map(|v| v / s).collect();
        let mean = lambda.iter().zip(e).map(|(l, v)| l * v).sum();
        (mean, 1.0 / s, lambda)
    } else {
        // Independent weights as a fallback.
        let w: Vec<f64> = (0..n).map(|i| 1.0 / c[i * n + i]).collect();
        let s: f64 = w.iter().sum();
        let lambda: Vec<f64> = w.iter().map(|v| v / s).collect();
        let mean = lambda.iter().zip(e).map(|(l, v)| l * v).sum();
        (mean, 1.0 / s, lambda)
    }
}

/// Sub-matrix of `c` (n × n) on the index list `idx`.
fn sub(c: &[f64], n: usize, idx: &[usize]) -> Vec<f64> {
    idx.iter()
        .flat_map(|&i| idx.iter().map(move |&j| c[i * n + j]))
        .collect()
}

/// The estimate of one band, or `None` when no pair has information there.
fn band(sp: &Spectra, pairs: &[Pair], f_lo: f64, f_hi: f64) -> Option<BandEstimate> {
    let k_lo = (f_lo / sp.bin_hz()).ceil() as usize;
    let k_hi = (f_hi / sp.bin_hz()).ceil() as usize;
    let used: Vec<(usize, PairBand)> = pairs
        .iter()
        .enumerate()
        .filter_map(|(i, p)| pair_band(sp, p, k_lo, k_hi).map(|b| (i, b)))
        .collect();
    if used.is_empty() {
        return None;
    }
    let n = used.len();
    let mut ck = vec![0.0; n * n];
    let mut ca = vec![0.0; n * n];
    for i in 0..n {
        for j in i..n {
            let (pi, bi) = (&pairs[used[i].0], &used[i].1);
            let (pj, bj) = (&pairs[used[j].0], &used[j].1);
            let (k, a) = band_cov(sp, pi, bi, pj, bj, i == j);
            ck[i * n + j] = k;
            ck[j * n + i] = k;
            ca[i * n + j] = a;
            ca[j * n + i] = a;
        }
    }
    let ek: Vec<f64> = used.iter().map(|u| u.1.k).collect();
    let ea: Vec<f64> = used.iter().map(|u| u.1.att).collect();
    let fr: Vec<f64> = used.iter().map(|u| u.1.f).collect();
    let (mut k, vk, lk) = gls(&ek, &ck);
    let (mut att, va, _) = gls(&ea, &ca);
    let f: f64 = lk.iter().zip(&fr).map(|(l, f)| l * f).sum();
    let (mut sk, mut sa) = (vk.sqrt(), va.sqrt());
    let mut notes = Vec::new();
    // The two sides (P76): compare, and widen the errors where they disagree.
    let left: Vec<usize> = (0..n).filter(|&i| pairs[used[i].0].side < 0).collect();
    let right: Vec<usize> = (0..n).filter(|&i| pairs[used[i].0].side > 0).collect();
    if !left.is_empty() && !right.is_empty() {
        // The sides' weighted mean frequencies differ slightly; compare them at one frequency,
        // moving each along the band's own slope (a weighted regression over all its bins).
        let slope = |v: &dyn Fn(&Pair, usize) -> f64| {
            let (mut sw, mut sf, mut sv, mut sff, mut sfv) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (pi, b) in &used {
                for (&k, &w) in b.bins.iter().zip(&b.w) {
                    let (f, y) = (k as f64 * sp.bin_hz(), v(&pairs[*pi], k));
                    sw += w;
                    sf += w * f;
                    sv += w * y;
                    sff += w * f * f;
                    sfv += w * f * y;
                }
            }
            let d = sw * sff - sf * sf;
            if d > 0.0 {
                (sw * sfv - sf * sv) / d
            } else {
                0.0
            }
        };
        let (slope_k, slope_a) = (slope(&|p, k| p.k[k]), slope(&|p, k| p.att[k]));
        let ek_f: Vec<f64> = (0..n).map(|i| ek[i] - slope_k * (fr[i] - f)).collect();
        let ea_f: Vec<f64> = (0..n).map(|i| ea[i] - slope_a * (fr[i] - f)).collect();
        let z = |e: &[f64], c: &[f64]| {
            let sel = |idx: &[usize]| idx.iter().map(|&i| e[i]).collect::<Vec<_>>();
            let (ml, vl, ll) = gls(&sel(&left), &sub(c, n, &left));
            let (mr, vr, lr) = gls(&sel(&right), &sub(c, n, &right));
            let mut clr = 0.0;
            for (a, &i) in left.iter().enumerate() {
                for (b, &j) in right.iter().enumerate() {
                    clr += ll[a] * lr[b] * c[i * n + j];
                }
            }
            let vd = (vl + vr - 2.0 * clr).max(0.1 * (vl + vr));
            (ml - mr).abs() / vd.sqrt()
        };
        let (zk, za) = (z(&ek_f, &ck), z(&ea_f, &ca));
        if zk > REFLECTION_Z || za > REFLECTION_Z {
            notes.push(NOTE_REFLECTION);
            sk *= zk.max(1.0);
            sa *= za.max(1.0);
        }
    }
    if !(k.is_finite() && k > 0.0 && sk.is_finite() && att.is_finite() && sa.is_finite()) {
        return None;
    }
    if att < 0.0 {
        att = 0.0;
        notes.push(NOTE_ATT_CLIPPED);
    }
    k = k.max(f64::MIN_POSITIVE);
    Some(BandEstimate {
        frequency_hz: f,
        k_re: k,
        k_re_std: sk,
        attenuation: att,
        attenuation_std: sa,
        pairs: n,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn p75_is_the_h1_case_of_the_ratio_variance() {
        // Two channels: b = 2a + independent noise; the variance of ln H1 from the general
        // formula equals P75's (1 − γ²)/(2 n_d γ²) for both parts.
        let n = 64_000;
        let mut state = 12345u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let a: Vec<f64> = (0..n).map(|_| rnd()).collect();
        let b: Vec<f64> = a.iter().map(|x| 2.0 * x + 1.5 * rnd()).collect();
        let sp = welch(&[&a, &b], 1000.0, 256, &|_| {}).unwrap();
        let terms = [
            Term { x: 0, y: 1, s: 1.0 },
            Term {
                x: 0,
                y: 0,
                s: -1.0,
            },
        ];
        for k in [5, 40, 100] {
            let g2 = sp.coherence(0, 1, k);
            let p75 = (1.0 - g2) / (2.0 * sp.n_eff * g2);
            let (vr, vi) = ln_h_cov(&sp, &terms, &terms, k);
            assert!(
                (vr - p75).abs() < 1e-9 * p75 && (vi - p75).abs() < 1e-9 * p75,
                "{vr} {vi} {p75}"
            );
        }
    }

    #[test]
    fn chains_start_at_the_source_sensor() {
        let s = |x: f64, line: u64| Sensor {
            line,
            file: "a.wav".into(),
            path: "a.wav".into(),
            channel: line as u16,
            position_m: x,
        };
        let c = side_chains(&[s(40.0, 2), s(0.0, 3), s(-25.0, 4), s(12.0, 5)]);
        assert_eq!(c, vec![(-1, vec![1, 2]), (1, vec![1, 3, 0])]);
    }
}
