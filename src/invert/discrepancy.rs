//! Honest errors where the model does not explain the data (model §7.13): a model discrepancy
//! δ(f) fitted to the residuals of each measured quantity (eq. P89, after Kennedy & O'Hagan
//! 2001), which corrects the predicted curve and enters its errors.
//!
//! The discrepancy of a quantity q (phase speed, attenuation) is described in ln q, so that
//! a model several times off (free air in the water) is corrected as readily as one a few per
//! cent off:
//!
//! ```text
//! r_i = ln q_meas(f_i) − ln q_model(f_i) = δ(f_i) + ε_i,        ε_i ~ N(0, σ_i²)
//! δ(f) = β₀ + β₁ (ln f − ln f̄) + η(f),   η ~ GP(0, s² exp(−½ (Δln f / ℓ)²))
//! ```
//!
//! a trend linear in ln f (a constant below [`MIN_POINTS_FOR_TREND`] points) plus a smooth
//! remainder η, a Gaussian process over ln f whose correlation length ℓ is a fixed fraction
//! of the measured band ([`CORRELATION_LENGTH_FRACTION`]). Its variance s² is set by the
//! method of moments (Paule & Mandel 1982, generalised to correlated errors): the generalised
//! residual sum of squares about the trend, (r − Xβ̂)ᵀ C⁻¹ (r − Xβ̂) with
//! C = s² R + diag(σ²), equals its degrees of freedom n − q; s² = 0 when the scatter about
//! the trend is already within the noise. The corrected value and its variance are the
//! universal-kriging predictor and its error (the trend's uncertainty included): at a
//! measured frequency the corrected curve follows the measurement as far as s² exceeds its
//! noise, and between them it follows its neighbours.
//!
//! Outside the measured band the trend is not continued: δ̂ and its variance stay at their
//! values at the nearest measured frequency, and the variance grows with the distance d (in
//! ln f) beyond it by (β̂₁² + V₁₁) d², as much as the trend would have moved the curve (by
//! the discrepancy's own size per octave, β̂₀² + V₀₀, when there is no trend term).

use crate::optimize::linalg::{cholesky, cholesky_solve};

/// Fewest measured frequencies for a trend in ln f (two coefficients) rather than a constant:
/// with three points the trend would leave one degree of freedom to estimate s², too few to
/// tell structure from noise.
pub const MIN_POINTS_FOR_TREND: usize = 4;

/// Correlation length ℓ of the remainder η as a fraction of the measured band's width in
/// ln f: long enough that a discrepancy seen at one measured frequency carries to the grid
/// points around it, short enough to follow a curvature the trend misses (a band holds 4–13
/// measured frequencies; ℓ of a third spans one to four of them).
pub const CORRELATION_LENGTH_FRACTION: f64 = 1.0 / 3.0;

/// Shortest correlation length, in ln f (a fifth of an octave): for bands of one or two close
/// frequencies.
pub const MIN_CORRELATION_LENGTH: f64 = 0.2 * std::f64::consts::LN_2;

/// Relative one-sigma error of Re k assumed where none is stated (the relative weighting's
/// noise level of P53, as the `high_misfit` test reads it).
pub const ASSUMED_RELATIVE_SPEED_STD: f64 = 0.01;

/// Relative one-sigma error of the attenuation assumed where none is stated.
pub const ASSUMED_RELATIVE_ATTENUATION_STD: f64 = 0.10;

/// How far beyond the measured frequencies, in octaves on each side, a corrected attenuation
/// is still reported: half an octave. Further out the correction rests on no measurement, and
/// a model attenuation near zero (a soil faster than the pipe's wave radiates almost nothing)
/// multiplied by the measured band's ratio gives values no pipe has; there the curve is not
/// given and the exports leave it blank.
pub const SUPPORT_MARGIN_OCTAVES: f64 = 0.5;

/// Bisection steps for s² (the interval shrinks 2⁻⁶⁰: far below any residual's precision).
const NUGGET_BISECTION_STEPS: usize = 60;

/// The fitted discrepancy of one quantity, in ln q over ln f.
#[derive(Debug, Clone, PartialEq)]
pub struct Discrepancy {
    /// ln f̄, the centre of the trend (mean of the measured ln f).
    centre: f64,
    /// ln f of the lowest and highest measured frequency.
    band: (f64, f64),
    /// ln f of the measured frequencies.
    lnf: Vec<f64>,
    /// Correlation length ℓ, in ln f.
    length: f64,
    /// Whether the trend term β₁ is fitted.
    trend: bool,
    /// Trend coefficients (β₀, β₁); β₁ = 0 without a trend term.
    beta: [f64; 2],
    /// Their covariance (XᵀC⁻¹X)⁻¹, row-major 2 × 2 (zero row and column for an absent β₁).
    cov: [f64; 4],
    /// Variance s² of the remainder η, (ln q)².
    s2: f64,
    /// Cholesky factor of C = s² R + diag(σ²).
    chol: Vec<f64>,
    /// C⁻¹ (r − Xβ̂).
    alpha: Vec<f64>,
}

/// One residual: frequency (Hz), r = ln q_meas − ln q_model, and σ of r (relative σ of q).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Residual {
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// ln(measured / model).
    pub ln_ratio: f64,
    /// One-sigma of the measurement in ln q (its relative error).
    pub sigma: f64,
}

/// The generalised least-squares fit of the trend at one s².
struct Gls {
    beta: [f64; 2],
    cov: [f64; 4],
    q: f64,
    chol: Vec<f64>,
    alpha: Vec<f64>,
}

impl Discrepancy {
    /// Fit the discrepancy to the residuals (those with a finite ratio and a positive, finite
    /// σ). `None` when none is usable.
    pub fn fit(residuals: &[Residual]) -> Option<Discrepancy> {
        let pts: Vec<Residual> = residuals
            .iter()
            .copied()
            .filter(|r| {
                r.frequency_hz > 0.0
                    && r.ln_ratio.is_finite()
                    && r.sigma.is_finite()
                    && r.sigma > 0.0
            })
            .collect();
        let n = pts.len();
        if n == 0 {
            return None;
        }
        let trend = n >= MIN_POINTS_FOR_TREND;
        let q = if trend { 2 } else { 1 };
        let lnf: Vec<f64> = pts.iter().map(|p| p.frequency_hz.ln()).collect();
        let lo = lnf.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = lnf.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let centre = lnf.iter().sum::<f64>() / n as f64;
        let length = (CORRELATION_LENGTH_FRACTION * (hi - lo)).max(MIN_CORRELATION_LENGTH);
        let solve = |s2: f64| gls(&pts, &lnf, centre, length, trend, s2);
        let dof = (n - q) as f64;
        let s2 = if n == q {
            // Nothing is left to tell noise from discrepancy: take the residuals' own size.
            pts.iter()
                .map(|p| (p.ln_ratio * p.ln_ratio - p.sigma * p.sigma).max(0.0))
                .sum::<f64>()
                / n as f64
        } else if solve(0.0)?.q <= dof {
            0.0
        } else {
            // Q(s²) falls from above n − q at 0 to below it once s² exceeds every residual².
            let mut hi_s2 = pts.iter().map(|p| p.ln_ratio * p.ln_ratio).sum::<f64>() + 1e-12;
            while solve(hi_s2)?.q > dof {
                hi_s2 *= 4.0;
            }
            let mut lo_s2 = 0.0;
            for _ in 0..NUGGET_BISECTION_STEPS {
                let mid = 0.5 * (lo_s2 + hi_s2);
                if solve(mid)?.q > dof {
                    lo_s2 = mid;
                } else {
                    hi_s2 = mid;
                }
            }
            hi_s2
        };
        let g = solve(s2)?;
        Some(Discrepancy {
            centre,
            band: (lo, hi),
            lnf,
            length,
            trend,
            beta: g.beta,
            cov: g.cov,
            s2,
            chol: g.chol,
            alpha: g.alpha,
        })
    }

    fn design(&self, lnf: f64) -> [f64; 2] {
        [1.0, if self.trend { lnf - self.centre } else { 0.0 }]
    }

    /// δ̂ and its predictive variance (in ln q) at frequency `f_hz`: the kriging predictor
    /// inside the measured band; held at the nearest band edge outside it, with a variance
    /// growing as the square of the distance.
    pub fn at(&self, f_hz: f64) -> (f64, f64) {
        let lnf = f_hz.ln();
        let edge = lnf.clamp(self.band.0, self.band.1);
        let n = self.lnf.len();
        let k: Vec<f64> = self
            .lnf
            .iter()
            .map(|&l| self.s2 * correlation(edge - l, self.length))
            .collect();
        let x = self.design(edge);
        let mean = x[0] * self.beta[0]
            + x[1] * self.beta[1]
            + k.iter().zip(&self.alpha).map(|(a, b)| a * b).sum::<f64>();
        // Universal kriging variance: s² − kᵀC⁻¹k + uᵀVu, u = x − XᵀC⁻¹k.
        let cik = cholesky_solve(&self.chol, n, &k);
        let mut u = x;
        for (j, &l) in self.lnf.iter().enumerate() {
            let xj = self.design(l);
            u[0] -= xj[0] * cik[j];
            u[1] -= xj[1] * cik[j];
        }
        let c = &self.cov;
        let var_trend = u[0] * u[0] * c[0] + 2.0 * u[0] * u[1] * c[1] + u[1] * u[1] * c[3];
        let var_here = (self.s2 - k.iter().zip(&cik).map(|(a, b)| a * b).sum::<f64>()).max(0.0);
        let d = (lnf - edge).abs();
        let growth = if self.trend {
            self.beta[1] * self.beta[1] + c[3]
        } else {
            (self.beta[0] * self.beta[0] + c[0]) / (std::f64::consts::LN_2 * std::f64::consts::LN_2)
        };
        (mean, var_here + var_trend + growth * d * d)
    }

    /// The frequencies where the correction is supported, Hz: the measured band widened by
    /// [`SUPPORT_MARGIN_OCTAVES`] on each side.
    pub fn support_hz(&self) -> (f64, f64) {
        let m = SUPPORT_MARGIN_OCTAVES * std::f64::consts::LN_2;
        ((self.band.0 - m).exp(), (self.band.1 + m).exp())
    }

    /// Variance s² of the smooth remainder, (ln q)².
    pub fn remainder_variance(&self) -> f64 {
        self.s2
    }
}

/// Squared-exponential correlation at a distance `d` in ln f.
fn correlation(d: f64, length: f64) -> f64 {
    (-0.5 * (d / length).powi(2)).exp()
}

/// Generalised least squares of the trend with C = s² R + diag(σ²): coefficients, their
/// covariance (XᵀC⁻¹X)⁻¹, the generalised residual sum of squares Q, C's Cholesky factor and
/// C⁻¹(r − Xβ̂). `None` if C is not numerically positive definite.
fn gls(
    pts: &[Residual],
    lnf: &[f64],
    centre: f64,
    length: f64,
    trend: bool,
    s2: f64,
) -> Option<Gls> {
    let n = pts.len();
    let mut c: Vec<f64> = lnf
        .iter()
        .flat_map(|&a| lnf.iter().map(move |&b| s2 * correlation(a - b, length)))
        .collect();
    for (i, p) in pts.iter().enumerate() {
        c[i * n + i] += p.sigma * p.sigma;
    }
    let chol = cholesky(&c, n)?;
    let x1: Vec<f64> = lnf
        .iter()
        .map(|&l| if trend { l - centre } else { 0.0 })
        .collect();
    let ones = vec![1.0; n];
    let r: Vec<f64> = pts.iter().map(|p| p.ln_ratio).collect();
    let ci1 = cholesky_solve(&chol, n, &ones);
    let cix = cholesky_solve(&chol, n, &x1);
    let cir = cholesky_solve(&chol, n, &r);
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let (a00, a01, a11) = (dot(&ones, &ci1), dot(&ones, &cix), dot(&x1, &cix));
    let (b0, b1) = (dot(&ones, &cir), dot(&x1, &cir));
    let det = a00 * a11 - a01 * a01;
    let (beta, cov) = if trend && det > 0.0 {
        let cov = [a11 / det, -a01 / det, -a01 / det, a00 / det];
        ([cov[0] * b0 + cov[1] * b1, cov[2] * b0 + cov[3] * b1], cov)
    } else {
        ([b0 / a00, 0.0], [1.0 / a00, 0.0, 0.0, 0.0])
    };
    let e: Vec<f64> = r
        .iter()
        .zip(&x1)
        .map(|(ri, xi)| ri - beta[0] - beta[1] * xi)
        .collect();
    let alpha = cholesky_solve(&chol, n, &e);
    Some(Gls {
        beta,
        cov,
        q: dot(&e, &alpha),
        chol,
        alpha,
    })
}

/// How far a band (Hz) reaches beyond the measured frequencies, in octaves: the distance of
/// its lower end below the lowest measured frequency plus that of its upper end above the
/// highest (0 when the measurements span it). `None` without measurements.
pub fn extrapolation_octaves(band_hz: (f64, f64), measured_hz: &[f64]) -> Option<f64> {
    let lo = measured_hz.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = measured_hz
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0) {
        return None;
    }
    Some((lo / band_hz.0).log2().max(0.0) + (band_hz.1 / hi).log2().max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn res(f: f64, r: f64, s: f64) -> Residual {
        Residual {
            frequency_hz: f,
            ln_ratio: r,
            sigma: s,
        }
    }

    #[test]
    fn a_residual_trend_within_the_noise_has_no_remainder_and_is_recovered() {
        // r = 0.05 + 0.02 ln(f/f̄) exactly: the trend is the data, s² = 0.
        let fs = [200.0, 300.0, 450.0, 700.0, 1000.0];
        let c = fs.iter().map(|f: &f64| f.ln()).sum::<f64>() / 5.0;
        let pts: Vec<Residual> = fs
            .iter()
            .map(|&f| res(f, 0.05 + 0.02 * (f.ln() - c), 0.01))
            .collect();
        let d = Discrepancy::fit(&pts).unwrap();
        assert_eq!(d.remainder_variance(), 0.0);
        for p in &pts {
            let (m, v) = d.at(p.frequency_hz);
            assert!((m - p.ln_ratio).abs() < 1e-12, "{m} vs {}", p.ln_ratio);
            // Trend variance only: below the noise of one point (5 points share it).
            assert!(v > 0.0 && v < 1e-4, "{v}");
        }
    }

    #[test]
    fn structure_beyond_the_noise_sets_the_remainder_and_the_curve_follows_it() {
        // A bump the linear trend cannot follow, 0.1 high in the middle, σ = 0.01.
        let fs = [100.0, 150.0, 200.0, 300.0, 400.0, 600.0, 800.0];
        let bump = |f: f64| 0.1 * (-0.5 * ((f / 300.0f64).ln() / 0.4).powi(2)).exp();
        let pts: Vec<Residual> = fs.iter().map(|&f| res(f, bump(f), 0.01)).collect();
        let d = Discrepancy::fit(&pts).unwrap();
        let s2 = d.remainder_variance();
        assert!(s2 > 1e-4, "{s2}");
        // The defining equation holds at the estimate: Q = n − q.
        let g = gls(&pts, &d.lnf, d.centre, d.length, true, s2).unwrap();
        assert!((g.q - 5.0).abs() < 1e-6, "{}", g.q);
        // At the measured frequencies the corrected value is within the noise of the data,
        // and the data within 2σ of it.
        for p in &pts {
            let (m, v) = d.at(p.frequency_hz);
            assert!((m - p.ln_ratio).abs() < 0.01, "{} {m}", p.frequency_hz);
            assert!(
                (m - p.ln_ratio).abs() < 2.0 * v.sqrt(),
                "{} {v}",
                p.frequency_hz
            );
        }
    }

    #[test]
    fn the_error_grows_with_distance_outside_the_measured_band() {
        let pts: Vec<Residual> = [500.0, 700.0, 1000.0, 1400.0]
            .iter()
            .map(|&f| res(f, -0.05 + 0.01 * (f / 500.0f64).ln(), 0.01))
            .collect();
        let d = Discrepancy::fit(&pts).unwrap();
        let (m_edge, v_edge) = d.at(500.0);
        let (m_250, v_250) = d.at(250.0);
        let (m_100, v_100) = d.at(100.0);
        assert_eq!(m_edge, m_250);
        assert_eq!(m_edge, m_100);
        assert!(v_edge < v_250 && v_250 < v_100, "{v_edge} {v_250} {v_100}");
        // Held at the edge, the variance reaches the trend's move over the distance.
        let trend_move = 0.01 * (500.0f64 / 100.0).ln();
        assert!(v_100 >= trend_move * trend_move, "{v_100}");
    }

    #[test]
    fn extrapolation_is_counted_in_octaves_on_each_side() {
        assert_eq!(
            extrapolation_octaves((100.0, 800.0), &[100.0, 800.0]),
            Some(0.0)
        );
        let o = extrapolation_octaves((100.0, 800.0), &[400.0, 600.0]).unwrap();
        assert!((o - (2.0 + (800.0f64 / 600.0).log2())).abs() < 1e-12, "{o}");
        assert_eq!(extrapolation_octaves((100.0, 800.0), &[]), None);
    }
}
