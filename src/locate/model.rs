//! The delay a correlator measures for a leak on a path of several segments (P85), its
//! inversion for the position (P86) and the error of that position term by term.
//!
//! Each segment s contributes its own wavenumber k_s(ω) = ω/c_s(f) − i α_s(f) from its curve.
//! For a leak at path position x the cross-spectrum of the two sensors is
//! S₁₂ ∝ exp(−i Re(ψ₂ − ψ₁)) exp(Im ψ₁ + Im ψ₂) (P85), and the predicted delay T(x) is the peak
//! of the band-weighted correlation R₁₂(τ) = Σ_ω A(ω) cos(ωτ − Re(ψ₂ − ψ₁)), where A is the
//! magnitude of W S₁₂: the path's attenuation e^{Im ψ₁ + Im ψ₂} for a plain correlator (which
//! does not depend on x: the two stretches always add up to the whole path), one for PHAT, the
//! measured coherence for SCOT. No phase or group speed is chosen: the peak is found.

use nalgebra::DMatrix;
use num_complex::Complex64;

use crate::db::results::CurvePoint;
use crate::units::{db_to_np, hz_to_omega};

/// Frequencies of the model's band grid: enough to follow the phase of the longest path
/// smoothly, while one predicted delay stays a few tens of microseconds (the correlation is
/// searched only within a few envelope widths of the group delay, inside its 1/Δf period).
pub const MODEL_GRID_POINTS: usize = 160;
/// A Newton step on a crest moves by at most this fraction of a carrier period (so it cannot
/// slip to the next crest).
const NEWTON_MAX_STEP_PERIODS: f64 = 0.125;
/// Newton refinements of a crest of the correlation.
const NEWTON_STEPS: usize = 8;
/// Iterations of the position solve (Illinois regula falsi on a nearly linear T(x)).
const SOLVE_ITERATIONS: usize = 60;
/// The position solve stops when the delay matches to this, s.
const SOLVE_TOLERANCE_S: f64 = 1e-9;
/// Two-sided 95 % quantile of the normal distribution.
pub const Z95: f64 = 1.959_963_984_540_054;

/// How the correlation is weighted over frequency (Knapp & Carter 1976).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Weighting {
    /// The plain cross-correlation of band-filtered signals (a correlator's usual setting).
    Plain,
    /// Phase transform: every frequency of the band counts the same.
    Phat,
    /// Smoothed coherence transform: each frequency by its coherence.
    Scot,
}

impl Weighting {
    /// Name on the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            Weighting::Plain => "plain",
            Weighting::Phat => "phat",
            Weighting::Scot => "scot",
        }
    }
}

impl std::str::FromStr for Weighting {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "plain" | "cc" => Ok(Weighting::Plain),
            "phat" => Ok(Weighting::Phat),
            "scot" => Ok(Weighting::Scot),
            _ => Err(format!(
                "'{s}' is not a weighting; expected plain, phat or scot"
            )),
        }
    }
}

/// A segment's speed curve: slowness interpolated by a monotone cubic (Fritsch & Carlson 1980)
/// so that the group delay it implies is continuous, attenuation and relative speed error
/// linearly.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedCurve {
    freq: Vec<f64>,
    slowness: Vec<f64>,
    tangent: Vec<f64>,
    att_np: Vec<f64>,
    rel_std: Vec<f64>,
    /// Whether the stored curve gave a speed error.
    pub has_std: bool,
}

impl SpeedCurve {
    /// From stored curve points (frequency, phase speed, its error, attenuation); points
    /// without a speed are skipped. `None` when fewer than two remain.
    pub fn from_points(points: &[CurvePoint]) -> Option<SpeedCurve> {
        let mut pts: Vec<(f64, f64, Option<f64>, f64)> = points
            .iter()
            .filter_map(|p| {
                let c = p
                    .phase_speed_m_per_s
                    .filter(|c| c.is_finite() && *c > 0.0)?;
                Some((
                    p.frequency_hz,
                    c,
                    p.phase_speed_std_m_per_s
                        .filter(|s| s.is_finite() && *s >= 0.0),
                    db_to_np(p.attenuation_db_per_m.unwrap_or(0.0).max(0.0)),
                ))
            })
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        pts.dedup_by(|a, b| a.0 == b.0);
        if pts.len() < 2 {
            return None;
        }
        let freq: Vec<f64> = pts.iter().map(|p| p.0).collect();
        let slowness: Vec<f64> = pts.iter().map(|p| 1.0 / p.1).collect();
        Some(SpeedCurve {
            tangent: pchip_tangents(&freq, &slowness),
            freq,
            slowness,
            att_np: pts.iter().map(|p| p.3).collect(),
            rel_std: pts.iter().map(|p| p.2.unwrap_or(0.0) / p.1).collect(),
            has_std: pts.iter().all(|p| p.2.is_some()),
        })
    }

    /// The frequency range the curve covers, Hz.
    pub fn range_hz(&self) -> (f64, f64) {
        (self.freq[0], *self.freq.last().expect("two points"))
    }

    /// (phase speed m/s, relative error, attenuation Np/m) at `f` (clamped to the range).
    pub fn at(&self, f: f64) -> (f64, f64, f64) {
        let n = self.freq.len();
        let f = f.clamp(self.freq[0], self.freq[n - 1]);
        let i = self.freq.partition_point(|&v| v <= f).clamp(1, n - 1) - 1;
        let h = self.freq[i + 1] - self.freq[i];
        let t = (f - self.freq[i]) / h;
        let (t2, t3) = (t * t, t * t * t);
        let s = (2.0 * t3 - 3.0 * t2 + 1.0) * self.slowness[i]
            + (t3 - 2.0 * t2 + t) * h * self.tangent[i]
            + (-2.0 * t3 + 3.0 * t2) * self.slowness[i + 1]
            + (t3 - t2) * h * self.tangent[i + 1];
        let lin = |v: &[f64]| v[i] + t * (v[i + 1] - v[i]);
        (1.0 / s, lin(&self.rel_std), lin(&self.att_np))
    }

    /// The mean phase speed over a band, m/s (for messages).
    pub fn mean_speed(&self, band: (f64, f64)) -> f64 {
        let n = 20;
        (0..=n)
            .map(|i| self.at(band.0 + (band.1 - band.0) * i as f64 / n as f64).0)
            .sum::<f64>()
            / (n + 1) as f64
    }
}

/// Fritsch–Carlson tangents of a monotone piecewise cubic through (x, y).
fn pchip_tangents(x: &[f64], y: &[f64]) -> Vec<f64> {
    let n = x.len();
    let d: Vec<f64> = (0..n - 1)
        .map(|i| (y[i + 1] - y[i]) / (x[i + 1] - x[i]))
        .collect();
    let mut m = vec![0.0; n];
    m[0] = d[0];
    m[n - 1] = d[n - 2];
    for i in 1..n - 1 {
        if d[i - 1] * d[i] <= 0.0 {
            m[i] = 0.0;
        } else {
            let (h0, h1) = (x[i] - x[i - 1], x[i + 1] - x[i]);
            let (w1, w2) = (2.0 * h1 + h0, h1 + 2.0 * h0);
            m[i] = (w1 + w2) / (w1 / d[i - 1] + w2 / d[i]);
        }
    }
    m
}

/// One stretch of the path for the model: which curve, and its length, m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelPiece {
    /// Index into the model's segment curves.
    pub curve: usize,
    /// Length, m.
    pub length_m: f64,
}

/// The band-weighted correlation model of a path (P85).
#[derive(Debug, Clone)]
pub struct DelayModel {
    omega: Vec<f64>,
    /// A(ω) without the path's attenuation: the weighting's own magnitude.
    base_weight: Vec<f64>,
    /// Multiply A by the path's attenuation (plain correlation).
    tilt: bool,
    /// k_s(ω) of each curve on the grid.
    k: Vec<Vec<Complex64>>,
    /// Re k_s with the speed one standard error higher.
    k_fast: Vec<Vec<f64>>,
    pieces: Vec<ModelPiece>,
}

impl DelayModel {
    /// The model over the frequencies `freqs_hz` (increasing) with weights `weights` (the
    /// weighting's own magnitude: ones for PHAT and plain, or |W S₁₂| measured), the segment
    /// curves and the pieces of the path in order from sensor 1. With `path_attenuation` the
    /// weights are multiplied by the path's attenuation, as a plain correlation of a flat leak
    /// spectrum is.
    pub fn new(
        freqs_hz: &[f64],
        weights: &[f64],
        path_attenuation: bool,
        curves: &[&SpeedCurve],
        pieces: Vec<ModelPiece>,
    ) -> DelayModel {
        let omega: Vec<f64> = freqs_hz.iter().map(|&f| hz_to_omega(f)).collect();
        let mut k = Vec::with_capacity(curves.len());
        let mut k_fast = Vec::with_capacity(curves.len());
        for c in curves {
            let mut ks = Vec::with_capacity(freqs_hz.len());
            let mut kf = Vec::with_capacity(freqs_hz.len());
            for (&f, &w) in freqs_hz.iter().zip(&omega) {
                let (c, rel, att) = c.at(f);
                // The wavenumber ω/ĉ of the speed's estimate: for a speed error symmetric about
                // ĉ, 1/ĉ is the median slowness, so T(x̂) = τ puts x̂ at the median of the
                // position's posterior, the point of least expected distance in error (model
                // §11, under P85).
                let k_median = w / c;
                ks.push(Complex64::new(k_median, -att));
                kf.push(k_median / (1.0 + rel));
            }
            k.push(ks);
            k_fast.push(kf);
        }
        DelayModel {
            omega,
            base_weight: weights.to_vec(),
            tilt: path_attenuation,
            k,
            k_fast,
            pieces,
        }
    }

    /// The pieces.
    pub fn pieces(&self) -> &[ModelPiece] {
        &self.pieces
    }

    /// Span D, m.
    pub fn span_m(&self) -> f64 {
        self.pieces.iter().map(|p| p.length_m).sum()
    }

    /// T(x): the predicted delay t₂ − t₁ for a leak `x` m from sensor 1 (P85).
    pub fn delay(&self, x: f64) -> f64 {
        self.delay_with(x, None, 0.0)
    }

    /// T(x) with curve `fast` (if any) one standard error faster, and `extra_m` added to the
    /// last piece (the span's error, the leak's distance from sensor 1 kept).
    pub fn delay_with(&self, x: f64, fast: Option<usize>, extra_m: f64) -> f64 {
        let n = self.omega.len();
        let mut dphi = vec![0.0; n];
        let mut log_att = vec![0.0; n];
        let mut start = 0.0;
        let last = self.pieces.len() - 1;
        for (pi, p) in self.pieces.iter().enumerate() {
            let len = p.length_m + if pi == last { extra_m } else { 0.0 };
            // Length on sensor 2's side minus length on sensor 1's side.
            let on1 = (x - start).clamp(0.0, len);
            let signed = (len - on1) - on1;
            start += len;
            let ks = &self.k[p.curve];
            let re: &[f64] = if fast == Some(p.curve) {
                &self.k_fast[p.curve]
            } else {
                &[]
            };
            for i in 0..n {
                let kr = if re.is_empty() { ks[i].re } else { re[i] };
                dphi[i] += kr * signed;
                log_att[i] += ks[i].im * len;
            }
        }
        let w: Vec<f64> = if self.tilt {
            let m = log_att.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            self.base_weight
                .iter()
                .zip(&log_att)
                .map(|(b, a)| b * (a - m).exp())
                .collect()
        } else {
            self.base_weight.clone()
        };
        correlation_peak(&self.omega, &w, &dphi)
    }
}

/// The τ at which Σ w cos(ωτ − φ) peaks, following the band the weights leave (P85).
///
/// Attenuation can leave a plain correlation only a narrow part of the nominal band (over
/// plastic pipe, a few tens of hertz at its low edge). Its correlation is then a carrier at
/// the weights' centre frequency under a broad envelope |Σ w e^{i(ωτ − φ)}|, and a search tied to
/// the nominal band's centre can miss the carrier's crests altogether. So: (1) find the
/// envelope's peak, scanning about the weighted group delay of φ in steps of half the
/// envelope's width 1/σ_ω (σ_ω the weights' RMS bandwidth); (2) take the envelope's main lobe,
/// where it is at least half its peak (and at least half a carrier period either side); (3)
/// take the highest crest of the correlation inside it, each crest refined by Newton's method.
pub fn correlation_peak(omega: &[f64], w: &[f64], phi: &[f64]) -> f64 {
    let n = omega.len();
    let wsum: f64 = w.iter().sum();
    if n == 0 || wsum <= 0.0 || !wsum.is_finite() {
        return 0.0;
    }
    let mut tg_num = 0.0;
    let mut tg_den = 0.0;
    for i in 0..n.saturating_sub(1) {
        let g = (phi[i + 1] - phi[i]) / (omega[i + 1] - omega[i]);
        let ww = 0.5 * (w[i] + w[i + 1]);
        tg_num += ww * g;
        tg_den += ww;
    }
    let tg = if tg_den > 0.0 { tg_num / tg_den } else { 0.0 };
    // The weights' centre and RMS width, rad/s.
    let om_c = omega.iter().zip(w).map(|(o, w)| o * w).sum::<f64>() / wsum;
    let var = omega
        .iter()
        .zip(w)
        .map(|(o, w)| w * (o - om_c) * (o - om_c))
        .sum::<f64>()
        / wsum;
    let spacing = if n > 1 {
        (omega[n - 1] - omega[0]) / (n - 1) as f64
    } else {
        om_c
    };
    // A single line (or none) still has a finite envelope: the grid's own resolution.
    let sigma = var.sqrt().max(0.5 * spacing).max(1e-9);
    let period = std::f64::consts::TAU / om_c.max(1e-9);
    // Z(τ) = Σ w e^{i(ωτ − φ)}: R = Re Z, the envelope |Z|.
    let envelope_parts = |tau: f64| -> (f64, f64, f64) {
        let (mut a, mut b) = (0.0, 0.0);
        for i in 0..n {
            let (s, c) = (omega[i] * tau - phi[i]).sin_cos();
            a += w[i] * c;
            b += w[i] * s;
        }
        (a.hypot(b), a, b)
    };
    let envelope = |tau: f64| envelope_parts(tau);
    // (1) The envelope's peak: a coarse scan over ±3 envelope widths (inside the grid's own
    // period 2π/Δω), refined by the parabola through the best sample and its neighbours.
    let env_step = 0.5 / sigma;
    let reach = (3.0 / sigma).min(0.45 * std::f64::consts::TAU / spacing.max(1e-9));
    let scan = (2.0 * reach / env_step).ceil() as usize;
    let samples: Vec<f64> = (0..=scan)
        .map(|j| envelope(tg - reach + j as f64 * env_step).0)
        .collect();
    let jb = (0..samples.len())
        .max_by(|&a, &b| samples[a].total_cmp(&samples[b]))
        .unwrap_or(0);
    let mut t_env = tg - reach + jb as f64 * env_step;
    if jb > 0 && jb + 1 < samples.len() {
        let (a, b, c) = (samples[jb - 1], samples[jb], samples[jb + 1]);
        let den = a - 2.0 * b + c;
        if den < 0.0 {
            t_env += 0.5 * env_step * (a - c) / den;
        }
    }
    let (e_max, z_re, z_im) = envelope_parts(t_env);
    // (2) The main lobe: where the envelope stays above half its peak, and at least half a
    // carrier period either side.
    let edge = |dir: f64| -> f64 {
        let mut t = t_env;
        for _ in 0..((reach / env_step).ceil() as usize) {
            let next = t + dir * env_step;
            if envelope(next).0 < 0.5 * e_max {
                break;
            }
            t = next;
        }
        t + dir * env_step
    };
    let lo = edge(-1.0).min(t_env - 0.5 * period);
    let hi = edge(1.0).max(t_env + 0.5 * period);
    // (3) Its crests: the correlation's phase turns at the centre frequency, so they lie near
    // t_env − arg Z(t_env)/ω_c + k·period; each is refined by Newton's method on R′ and the
    // highest taken.
    let first = t_env - z_im.atan2(z_re) / om_c;
    let k_lo = ((lo - first) / period).floor() as i64;
    let k_hi = ((hi - first) / period).ceil() as i64;
    let step = NEWTON_MAX_STEP_PERIODS * period;
    let r = |tau: f64| -> f64 { (0..n).map(|i| w[i] * (omega[i] * tau - phi[i]).cos()).sum() };
    let mut top = (f64::NEG_INFINITY, t_env);
    for k in k_lo..=k_hi {
        let t = newton_crest(omega, w, phi, first + k as f64 * period, step);
        if t < lo || t > hi {
            continue;
        }
        let v = r(t);
        if v > top.0 {
            top = (v, t);
        }
    }
    top.1
}

/// Newton's method on R′(τ) = 0 from `tau`, each step at most `step`.
fn newton_crest(omega: &[f64], w: &[f64], phi: &[f64], mut tau: f64, step: f64) -> f64 {
    let n = omega.len();
    for _ in 0..NEWTON_STEPS {
        let (mut d1, mut d2) = (0.0, 0.0);
        for i in 0..n {
            let a = omega[i] * tau - phi[i];
            d1 -= w[i] * omega[i] * a.sin();
            d2 -= w[i] * omega[i] * omega[i] * a.cos();
        }
        if d2 >= 0.0 {
            break;
        }
        let dt = (-d1 / d2).clamp(-step, step);
        tau += dt;
        if dt.abs() < 1e-12 {
            break;
        }
    }
    tau
}

/// One term of the position's error budget (P86).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TermKind {
    /// The measured delay.
    Delay,
    /// The speed of a curve (index into the model's curves).
    Speed(usize),
    /// The span's length.
    Span,
}

/// A term: what it is and how far the position moves for one standard error of it, m (signed:
/// for a speed, the move when that speed is higher).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Term {
    /// Which input.
    pub kind: TermKind,
    /// Position change for +1σ of the input, m.
    pub shift_m: f64,
}

/// The position of a leak and its error.
#[derive(Debug, Clone, PartialEq)]
pub struct Position {
    /// Distance from sensor 1 along the path, m.
    pub x_m: f64,
    /// Its standard error, m.
    pub std_m: f64,
    /// 95 % interval, m from sensor 1 (inside the span).
    pub lo_m: f64,
    /// Upper end.
    pub hi_m: f64,
    /// ∂T/∂x, s/m.
    pub dt_dx: f64,
    /// The terms of the budget.
    pub terms: Vec<Term>,
    /// Set when the delay lies just beyond what the span allows (within its error and the
    /// speeds' and span's errors of that end), so the leak is put at that sensor.
    pub at_sensor: Option<u8>,
}

impl Position {
    /// The speeds' part of σ_x: √(sᵀ R s) over the speed terms s, R the correlation of the
    /// curves' errors indexed by curve (P86 in its covariance form); independent speeds without
    /// one.
    pub fn speeds_std_m(&self, corr: Option<&DMatrix<f64>>) -> f64 {
        let speeds: Vec<(usize, f64)> = self
            .terms
            .iter()
            .filter_map(|t| match t.kind {
                TermKind::Speed(c) => Some((c, t.shift_m)),
                _ => None,
            })
            .collect();
        let mut v = 0.0;
        for &(a, sa) in &speeds {
            for &(b, sb) in &speeds {
                let r = if a == b {
                    1.0
                } else {
                    corr.map_or(0.0, |m| m[(a, b)].clamp(-1.0, 1.0))
                };
                v += sa * sb * r;
            }
        }
        v.max(0.0).sqrt()
    }

    /// σ_x and the 95 % interval again with the speed errors correlated as `corr` (by curve),
    /// inside a span of `span_m`.
    pub fn correlate_speeds(&mut self, corr: &DMatrix<f64>, span_m: f64) {
        let others: f64 = self
            .terms
            .iter()
            .filter(|t| !matches!(t.kind, TermKind::Speed(_)))
            .map(|t| t.shift_m * t.shift_m)
            .sum();
        self.std_m = (others + self.speeds_std_m(Some(corr)).powi(2)).sqrt();
        self.lo_m = (self.x_m - Z95 * self.std_m).max(0.0);
        self.hi_m = (self.x_m + Z95 * self.std_m).min(span_m);
    }
}

/// Why no position can be given.
#[derive(Debug, Clone, PartialEq)]
pub struct OutsideSpan {
    /// Largest delay the span allows (leak at sensor 1), s.
    pub t_at_sensor1: f64,
    /// Smallest (leak at sensor 2), s.
    pub t_at_sensor2: f64,
}

/// Solve T(x̂) = τ (P86) and give σ_x term by term. `span_std_m` is the span's error;
/// `speed_terms` says which curves carry a speed error.
pub fn solve(
    model: &DelayModel,
    tau: f64,
    tau_std: f64,
    span_std_m: f64,
    speed_terms: &[usize],
) -> Result<Position, OutsideSpan> {
    let d = model.span_m();
    let (t0, t1) = (model.delay(0.0), model.delay(d));
    // T decreases from sensor 1 to sensor 2; a delay outside by more than three errors of the
    // difference τ − T(end) is not a leak between the sensors. T(end)'s error is that of the
    // speeds (each segment's term at that end, as P86 adds them) and of the span.
    let end_std = |x: f64, t: f64| -> f64 {
        let mut v = 0.0;
        for &c in speed_terms {
            v += (model.delay_with(x, Some(c), 0.0) - t).powi(2);
        }
        if span_std_m > 0.0 {
            v += (model.delay_with(x, None, span_std_m) - t).powi(2);
        }
        v
    };
    let outside = |t_end: f64, x_end: f64| {
        3.0 * (tau_std * tau_std + end_std(x_end, t_end)).sqrt() < (tau - t_end).abs()
    };
    if (tau > t0 && outside(t0, 0.0)) || (tau < t1 && outside(t1, d)) {
        return Err(OutsideSpan {
            t_at_sensor1: t0,
            t_at_sensor2: t1,
        });
    }
    let mut at_sensor = None;
    let x = if tau >= t0 {
        at_sensor = Some(1);
        0.0
    } else if tau <= t1 {
        at_sensor = Some(2);
        d
    } else {
        // Illinois regula falsi on f(x) = T(x) − τ, f(0) > 0 > f(D).
        let (mut a, mut fa, mut b, mut fb) = (0.0, t0 - tau, d, t1 - tau);
        let mut side = 0i8;
        let mut x = 0.5 * d;
        for _ in 0..SOLVE_ITERATIONS {
            x = (a * fb - b * fa) / (fb - fa);
            if !(x > a && x < b) {
                x = 0.5 * (a + b);
            }
            let fx = model.delay(x) - tau;
            if fx.abs() < SOLVE_TOLERANCE_S || (b - a) < 1e-6 {
                break;
            }
            if fx > 0.0 {
                a = x;
                fa = fx;
                if side == 1 {
                    fb *= 0.5;
                }
                side = 1;
            } else {
                b = x;
                fb = fx;
                if side == -1 {
                    fa *= 0.5;
                }
                side = -1;
            }
        }
        x
    };
    let h = (0.005 * d).clamp(1e-3, 0.5);
    let (xa, xb) = ((x - h).max(0.0), (x + h).min(d));
    let dt_dx = (model.delay(xb) - model.delay(xa)) / (xb - xa);
    let base = model.delay(x);
    let mut terms = vec![Term {
        kind: TermKind::Delay,
        shift_m: (tau_std / dt_dx).abs(),
    }];
    for &c in speed_terms {
        let dt = model.delay_with(x, Some(c), 0.0) - base;
        terms.push(Term {
            kind: TermKind::Speed(c),
            shift_m: -dt / dt_dx,
        });
    }
    if span_std_m > 0.0 {
        let dt = model.delay_with(x, None, span_std_m) - base;
        terms.push(Term {
            kind: TermKind::Span,
            shift_m: -dt / dt_dx,
        });
    }
    let std_m = terms
        .iter()
        .map(|t| t.shift_m * t.shift_m)
        .sum::<f64>()
        .sqrt();
    Ok(Position {
        x_m: x,
        std_m,
        lo_m: (x - Z95 * std_m).max(0.0),
        hi_m: (x + Z95 * std_m).min(d),
        dt_dx,
        terms,
        at_sensor,
    })
}

/// The position a correlator would give with one speed per segment (its Korteweg speed, P45),
/// piecewise: t₂ − t₁ = Σ (ℓ₂ − ℓ₁)/c_s solved for x. `speeds` by piece.
pub fn table_position(lengths: &[f64], speeds: &[f64], tau: f64) -> f64 {
    let d: f64 = lengths.iter().sum();
    let t = |x: f64| {
        let mut start = 0.0;
        let mut s = 0.0;
        for (&l, &c) in lengths.iter().zip(speeds) {
            let on1 = (x - start).clamp(0.0, l);
            s += ((l - on1) - on1) / c;
            start += l;
        }
        s
    };
    if tau >= t(0.0) {
        return 0.0;
    }
    if tau <= t(d) {
        return d;
    }
    // T is piecewise linear and decreasing: bisection to a micrometre.
    let (mut a, mut b) = (0.0, d);
    while b - a > 1e-6 {
        let m = 0.5 * (a + b);
        if t(m) > tau {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

/// An even grid of `n` frequencies over `band`, Hz.
pub fn band_grid(band: (f64, f64), n: usize) -> Vec<f64> {
    let n = n.max(2);
    (0..n)
        .map(|i| band.0 + (band.1 - band.0) * i as f64 / (n - 1) as f64)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(c: f64, rel: f64, att_db: f64) -> SpeedCurve {
        let pts: Vec<CurvePoint> = [50.0, 400.0, 1500.0]
            .iter()
            .map(|&f| CurvePoint {
                frequency_hz: f,
                phase_speed_m_per_s: Some(c),
                attenuation_db_per_m: Some(att_db),
                phase_speed_std_m_per_s: Some(rel * c),
                attenuation_std_db_per_m: None,
                model_phase_speed_m_per_s: None,
                model_attenuation_db_per_m: None,
            })
            .collect();
        SpeedCurve::from_points(&pts).unwrap()
    }

    /// One pipe of uniform speed: x = (D − cτ)/2 and its error terms, P84.
    #[test]
    fn single_pipe_is_the_correlators_formula() {
        let c = flat(1200.0, 0.01, 0.2);
        let grid = band_grid((100.0, 800.0), MODEL_GRID_POINTS);
        for weighting in [Weighting::Plain, Weighting::Phat] {
            let m = DelayModel::new(
                &grid,
                &vec![1.0; grid.len()],
                weighting == Weighting::Plain,
                &[&c],
                vec![ModelPiece {
                    curve: 0,
                    length_m: 200.0,
                }],
            );
            // The median slowness of 1200 ± 1 %: 1/1200.
            let slowness = 1.0 / 1200.0;
            for x in [0.0, 37.2, 100.0, 163.0, 200.0] {
                let t = m.delay(x);
                assert!((t - (200.0 - 2.0 * x) * slowness).abs() < 1e-9, "{x}: {t}");
            }
            let tau = (200.0 - 2.0 * 37.2) * slowness;
            let p = solve(&m, tau, 1e-4, 2.0, &[0]).unwrap();
            assert!((p.x_m - 37.2).abs() < 1e-5, "{}", p.x_m);
            // δx = τ δc / 2 for the speed; σ_D / 2 for the span; c σ_τ / 2 for the delay.
            let shift = |k: TermKind| p.terms.iter().find(|t| t.kind == k).unwrap().shift_m;
            let speed = shift(TermKind::Speed(0));
            let expect = -tau * 12.0 / 2.0 * 1200.0 / 1212.0;
            assert!(
                (speed - expect).abs() < 1e-3 * expect.abs(),
                "{speed} {expect}"
            );
            assert!((shift(TermKind::Span) - 1.0).abs() < 1e-6);
            // σ_τ / (2 × slowness) = 1200 m/s × 0.1 ms / 2.
            assert!((shift(TermKind::Delay) - 0.06).abs() < 1e-6);
        }
    }

    /// Two segments: the delay is the sum of the pieces' travel times, and the speed terms of
    /// the two sides have opposite signs.
    #[test]
    fn two_segments_add_their_travel_times() {
        let (a, b) = (flat(400.0, 0.02, 0.0), flat(1250.0, 0.002, 0.0));
        let grid = band_grid((100.0, 600.0), MODEL_GRID_POINTS);
        let m = DelayModel::new(
            &grid,
            &vec![1.0; grid.len()],
            false,
            &[&a, &b],
            vec![
                ModelPiece {
                    curve: 0,
                    length_m: 60.0,
                },
                ModelPiece {
                    curve: 1,
                    length_m: 140.0,
                },
            ],
        );
        let x = 25.0;
        // The median slownesses of 400 ± 2 % and 1250 ± 0.2 %.
        let (sa, sb) = (1.0 / 400.0, 1.0 / 1250.0);
        let expect = (35.0 * sa + 140.0 * sb) - 25.0 * sa;
        assert!((m.delay(x) - expect).abs() < 1e-9);
        let p = solve(&m, expect, 1e-4, 0.0, &[0, 1]).unwrap();
        assert!((p.x_m - x).abs() < 1e-5);
        let s = |k| p.terms.iter().find(|t| t.kind == k).unwrap().shift_m;
        // A faster segment on sensor 2's side shortens t₂, so every T(x) is smaller and the
        // same τ is met nearer sensor 1 (a negative shift). Segment 1 lies wholly on sensor 2's
        // side; segment 0 has 25 m on sensor 1's side and 35 m on sensor 2's: net sensor 2.
        assert!(s(TermKind::Speed(1)) < 0.0);
        assert!(s(TermKind::Speed(0)) < 0.0);
        // Move the leak into segment 1: segment 0 is now wholly on sensor 1's side, and its
        // term changes sign.
        let x2 = 120.0;
        let p2 = solve(&m, m.delay(x2), 1e-4, 0.0, &[0, 1]).unwrap();
        let s2 = |k| p2.terms.iter().find(|t| t.kind == k).unwrap().shift_m;
        assert!(s2(TermKind::Speed(0)) > 0.0, "{:?}", p2.terms);
        assert!(s2(TermKind::Speed(1)) < 0.0, "{:?}", p2.terms);
        assert!((p2.x_m - x2).abs() < 1e-5);
        // Outside the span.
        let e = solve(&m, m.delay(0.0) + 0.01, 1e-4, 0.0, &[]).unwrap_err();
        assert!((e.t_at_sensor1 - m.delay(0.0)).abs() < 1e-12);
    }

    /// Weights that attenuation leaves only at the band's low edge, and a phase offset of two
    /// radians (dispersion): the peak is the correlation's highest crest under the envelope,
    /// a quarter of a carrier period and more away from the group delay, wherever the nominal
    /// band's centre is.
    #[test]
    fn the_peak_follows_the_band_the_weights_leave() {
        let grid = band_grid((100.0, 800.0), MODEL_GRID_POINTS);
        let omega: Vec<f64> = grid.iter().map(|&f| hz_to_omega(f)).collect();
        let w: Vec<f64> = grid.iter().map(|&f| (-(f - 100.0) / 12.0).exp()).collect();
        let tau0 = 0.031;
        let phi: Vec<f64> = omega.iter().map(|o| o * tau0 + 2.0).collect();
        let r = |t: f64| -> f64 {
            (0..omega.len())
                .map(|i| w[i] * (omega[i] * t - phi[i]).cos())
                .sum()
        };
        let got = correlation_peak(&omega, &w, &phi);
        // The highest value of R within ±20 ms, on a 1-µs grid.
        let best = (0..=40_000).map(|j| tau0 - 0.02 + j as f64 * 1e-6).fold(
            (f64::NEG_INFINITY, 0.0),
            |b, t| {
                let v = r(t);
                if v > b.0 {
                    (v, t)
                } else {
                    b
                }
            },
        );
        assert!((got - best.1).abs() < 2e-6, "{got} vs {}", best.1);
        assert!((got - tau0).abs() > 2.0e-3, "{got}");
        // A flat band: the crest of a pure delay is the delay itself.
        let flat = vec![1.0; omega.len()];
        let lin: Vec<f64> = omega.iter().map(|o| o * tau0).collect();
        assert!((correlation_peak(&omega, &flat, &lin) - tau0).abs() < 1e-9);
    }

    #[test]
    fn table_position_solves_the_piecewise_travel_times() {
        let x = table_position(&[60.0, 140.0], &[400.0, 1250.0], 0.1245);
        let t = (60.0 - x) / 400.0 + 140.0 / 1250.0 - x / 400.0;
        assert!((t - 0.1245).abs() < 1e-8, "{x}");
    }

    #[test]
    fn monotone_interpolation_keeps_the_points() {
        let pts: Vec<CurvePoint> = [
            (100.0, 300.0),
            (200.0, 320.0),
            (400.0, 330.0),
            (800.0, 331.0),
        ]
        .iter()
        .map(|&(f, c)| CurvePoint {
            frequency_hz: f,
            phase_speed_m_per_s: Some(c),
            attenuation_db_per_m: Some(0.1),
            phase_speed_std_m_per_s: None,
            attenuation_std_db_per_m: None,
            model_phase_speed_m_per_s: None,
            model_attenuation_db_per_m: None,
        })
        .collect();
        let s = SpeedCurve::from_points(&pts).unwrap();
        assert!(!s.has_std);
        for &(f, c) in &[(100.0, 300.0), (200.0, 320.0), (400.0, 330.0)] {
            assert!((s.at(f).0 - c).abs() < 1e-9);
        }
        let mid = s.at(300.0).0;
        assert!(mid > 320.0 && mid < 330.0, "{mid}");
    }

    /// An uncertain speed enters the delay by its median slowness 1/ĉ, not its mean
    /// (1 + (σ/ĉ)²)/ĉ: a uniform 400 m/s pipe known to ±10 % gives the delay of a known one,
    /// so the position solved is the median of its posterior (model §11).
    #[test]
    fn an_uncertain_speed_enters_by_its_median_slowness() {
        let curve = |std: Option<f64>| {
            let pts: Vec<CurvePoint> = [100.0, 300.0, 600.0]
                .iter()
                .map(|&f| CurvePoint {
                    frequency_hz: f,
                    phase_speed_m_per_s: Some(400.0),
                    attenuation_db_per_m: Some(0.0),
                    phase_speed_std_m_per_s: std,
                    attenuation_std_db_per_m: None,
                    model_phase_speed_m_per_s: None,
                    model_attenuation_db_per_m: None,
                })
                .collect();
            SpeedCurve::from_points(&pts).unwrap()
        };
        let pieces = vec![ModelPiece {
            length_m: 100.0,
            curve: 0,
        }];
        let grid: Vec<f64> = (0..=100).map(|i| 200.0 + 2.0 * f64::from(i)).collect();
        let ones = vec![1.0; grid.len()];
        let delay =
            |c: &SpeedCurve| DelayModel::new(&grid, &ones, false, &[c], pieces.clone()).delay(20.0);
        let (known, uncertain) = (curve(None), curve(Some(40.0)));
        // A leak 20 m from sensor 1 of 100 m: T = (80 − 20) s = 60 m × slowness.
        let t_known = delay(&known);
        let t_uncertain = delay(&uncertain);
        assert!((t_known - 60.0 / 400.0).abs() < 1e-6, "{t_known}");
        // The mean slowness would give 60 × 1.01/400.
        assert!((t_uncertain - 60.0 / 400.0).abs() < 1e-6, "{t_uncertain}");
    }
}
