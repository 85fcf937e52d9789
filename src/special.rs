//! Special functions of complex argument used by the model: the Hankel ratio P(z) of eq. P16,
//! the fluid-loading factor ψ of eq. P24 and the branch rule of eq. P3.
//!
//! The Bessel and Hankel functions come from `complex-bessel`, a pure-Rust port of Amos'
//! TOMS 644 \[R17\]. We always use the exponentially scaled forms: the scale factor cancels in
//! every ratio we form, and the unscaled H⁽²⁾ underflows silently for large |Im z| (model §5.7:
//! H⁽²⁾(1 − 800i) returns 0 and the ratio becomes NaN).

use complex_bessel::{besselj_seq, hankel2_seq, Scaling};
use num_complex::Complex64;

/// Below this |z²| the fluid-loading factor uses its series ψ = 1 − z²/8 − z⁴/192 (model §5.5,
/// `PSI_SERIES_Z2`). The next term is below 5e-15 there.
pub const PSI_SERIES_Z2: f64 = 1e-6;

/// Why a special function could not be evaluated.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SpecialError {
    /// The argument is zero or not finite: the ratio is 0/0 or undefined (grazing, q = 0).
    #[error("special function argument {0} is zero or not finite")]
    BadArgument(Complex64),
    /// The Amos routine reported an error (overflow, total loss of precision, no convergence).
    #[error("Amos routine failed at z = {0}")]
    Amos(Complex64),
}

/// Square root with the branch cut on the positive imaginary axis of w, eq. P3.
///
/// r = principal √w; return r if Re r ≥ Im r, otherwise −r. Radiating fields (w > 0) get q > 0,
/// evanescent ones (w < 0) get q = −i√|w|. Same as Kalkowski's `root_sign` \[R12\].
#[inline]
pub fn sqrt_plus(w: Complex64) -> Complex64 {
    let r = principal_sqrt(w);
    if r.re >= r.im {
        r
    } else {
        -r
    }
}

/// Principal complex square root (Re ≥ 0; the cut on the negative real axis, where the sign of
/// a zero imaginary part picks the side), by the hypot form (Kahan's algorithm without the
/// polar round trip of `Complex::sqrt`, which costs an atan2, an exp and a sin/cos pair).
#[inline]
pub fn principal_sqrt(w: Complex64) -> Complex64 {
    let (x, y) = (w.re, w.im);
    if x == 0.0 && y == 0.0 {
        return Complex64::new(0.0, y);
    }
    let t = ((x.abs() + abs_xy(x, y)) * 0.5).sqrt();
    if x >= 0.0 {
        Complex64::new(t, y / (2.0 * t))
    } else {
        Complex64::new(y.abs() / (2.0 * t), t.copysign(y))
    }
}

/// √(x² + y²) without libm's `hypot` (which guards every call against overflow at several
/// times the cost): the plain form is within 1 ulp of it wherever x² + y² neither overflows
/// nor loses precision to subnormals, and `hypot` is used outside that range.
#[inline]
pub fn abs_xy(x: f64, y: f64) -> f64 {
    let s = x * x + y * y;
    if s > 1e-290 && s < 1e290 {
        s.sqrt()
    } else {
        x.hypot(y)
    }
}

/// |z| by [`abs_xy`]: the modulus used in the solver's hot loops.
#[inline]
pub fn abs(z: Complex64) -> f64 {
    abs_xy(z.re, z.im)
}

/// P(z) = H₀(z)/H₀′(z) = −H₀⁽²⁾(z)/H₁⁽²⁾(z), eq. P16 (second kind, principal branch).
///
/// In the sector the model uses (−π < arg z ≤ π/4 and a little beyond, see
/// `in_modified_bessel_sector`) P comes from the modified Bessel functions of w = iz:
/// H_ν⁽²⁾(z) = (2i/π)·e^{iνπ/2}·K_ν(iz) (DLMF 10.27.8), so P(z) = i·K₀(w)/K₁(w), computed by
/// [`k0_over_k1`] without any Amos call. Elsewhere, and if that fails, [`hankel_ratio_amos`].
pub fn hankel_ratio(z: Complex64) -> Result<Complex64, SpecialError> {
    if !(z.re.is_finite() && z.im.is_finite()) || z == Complex64::new(0.0, 0.0) {
        return Err(SpecialError::BadArgument(z));
    }
    let w = Complex64::new(-z.im, z.re);
    if in_modified_bessel_sector(w) {
        if let Some(r) = k0_over_k1(w) {
            let p = Complex64::new(-r.im, r.re);
            if p.re.is_finite() && p.im.is_finite() {
                return Ok(p);
            }
        }
    }
    hankel_ratio_amos(z)
}

/// Whether w = iz lies where the principal K_ν(w) continues the principal H_ν⁽²⁾(z):
/// −π/2 < arg w ≤ 3π/4 (i.e. −π < arg z ≤ π/4, the sector of q·a under the branch rule of
/// eq. P3). The principal branches part where z crosses the positive imaginary axis.
#[inline]
fn in_modified_bessel_sector(w: Complex64) -> bool {
    w.re > 0.0 || (w.im > 0.0 && w.im >= -w.re)
}

/// Below this |w| the ratio K₁/K₀ comes from the power series (DLMF 10.31.1), above it from
/// Temme's continued fraction (Temme 1975; Thompson & Barnett 1987, J. Comput. Phys. 64, 490).
pub const K_SERIES_MAX_ABS: f64 = 2.0;
/// Near the imaginary axis (Re w < [`K_SERIES_MAX_RE`]) the series is used up to this |w|:
/// there I₀ and K₀ are of the same size (no e^{2 Re w} cancellation), the largest term is
/// below 20× the sum at |w| = 6, and the continued fraction is slowest (40–100 terms).
pub const K_SERIES_MAX_ABS_NEAR_IMAGINARY: f64 = 6.0;
/// See [`K_SERIES_MAX_ABS_NEAR_IMAGINARY`].
pub const K_SERIES_MAX_RE: f64 = 1.0;
/// Relative size of the last term at which the series and the continued fraction stop.
pub const K_RATIO_EPS: f64 = 1e-17;
/// Terms of the continued fraction beyond which it is declared not converged (then Amos).
pub const K_CF_MAX_TERMS: usize = 400;

/// K₀(w)/K₁(w) for −π/2 < arg w ≤ 3π/4, `None` if the continued fraction did not converge.
/// (The ratio P needs, so that it costs one complex division.)
///
/// |w| < [`K_SERIES_MAX_ABS`] (or up to [`K_SERIES_MAX_ABS_NEAR_IMAGINARY`] near the imaginary
/// axis): the ascending series of K₀ and K₁ (DLMF 10.31.1 with n = 0, 1). Otherwise the
/// continued fraction of Temme's method with order μ = 0 (`k0_over_k1_cf`); the
/// normalisation sum of that method is not needed for a ratio.
pub fn k0_over_k1(w: Complex64) -> Option<Complex64> {
    let r2 = w.norm_sqr();
    if r2 < K_SERIES_MAX_ABS * K_SERIES_MAX_ABS
        || (r2 < K_SERIES_MAX_ABS_NEAR_IMAGINARY * K_SERIES_MAX_ABS_NEAR_IMAGINARY
            && w.re < K_SERIES_MAX_RE)
    {
        return Some(k0_over_k1_series(w));
    }
    k0_over_k1_cf(w)
}

/// K₀(w)/K₁(w) by Temme's continued fraction for order 0, h = 1/(b₁ + a₂/(b₂ + a₃/(b₃ + ⋯)))
/// with b_i = 2(w + i), a_i = −(i − ½)², and K₁/K₀ = (w + ½ − h/4)/w (Numerical Recipes
/// §6.7, `bessik`). The convergents h_n = A_n/B_n come from Wallis' recurrences
/// A_n = b_n A_{n−1} + a_n A_{n−2} (B likewise), which multiply only: Steed's form, whose
/// every term waits on a complex division, takes 1.6× as long for the same terms. It stops
/// where Steed's does: |h_n − h_{n−1}| = |a₁⋯a_n|/|B_n B_{n−1}| ≤ ε|h_n|, i.e.
/// |a₁⋯a_n| ≤ ε|A_n||B_{n−1}|. `None` if that takes more than [`K_CF_MAX_TERMS`] terms.
fn k0_over_k1_cf(w: Complex64) -> Option<Complex64> {
    let one = Complex64::new(1.0, 0.0);
    let mut b = 2.0 * (one + w);
    // A_0 = 0, A_1 = 1, B_0 = 1, B_1 = b₁; p = |a₁⋯a_n| with a₁ = 1.
    let (mut a0, mut a1) = (Complex64::new(0.0, 0.0), one);
    let (mut b0, mut b1) = (one, b);
    let mut p = 1.0_f64;
    let eps2 = K_RATIO_EPS * K_RATIO_EPS;
    for i in 2..=K_CF_MAX_TERMS {
        let half = i as f64 - 0.5;
        let an = -half * half;
        b += 2.0;
        let a2 = b * a1 + a0 * an;
        let b2 = b * b1 + b0 * an;
        p *= half * half;
        if p * p <= eps2 * a2.norm_sqr() * b1.norm_sqr() {
            let h = 0.25 * (a2 / b2);
            return Some(w / (w + 0.5 - h));
        }
        (a0, a1, b0, b1) = (a1, a2, b1, b2);
        // The convergents' numerators and denominators grow like the partial products of b_i;
        // scaling all four (and p², with it p) keeps the ratios and the test unchanged.
        if b1.norm_sqr() > 1e120 {
            (a0, a1, b0, b1) = (a0 * 1e-60, a1 * 1e-60, b0 * 1e-60, b1 * 1e-60);
            p *= 1e-120;
        }
    }
    None
}

/// Terms of the ascending series of [`k0_over_k1_series`] at most. At |w| = 6, the largest
/// |w| it is used at, the term y^k/(k!)² (y = w²/4) is below 1e-17 of |I₀| ≥ 0.15 by k = 21;
/// the rest is room for w near a zero of I₀ (a zero of J₀ on the imaginary axis), where the
/// relative test cannot pass and the 40th term is below 1e-57.
const K_SERIES_TERMS: usize = 40;

/// The real coefficients of [`k0_over_k1_series`], built at compile time: with
/// t_k = y^k/(k!)², K₀ and K₁ need Σ t_k·c_k for c_k = 1, ψ(k+1), 1/(k+1) and
/// (2ψ(k+1) + 1/(k+1))/(k+1), and the step t_{k+1} = t_k·y/(k+1)².
struct KSeriesTable {
    /// 1/(k+1)², the step from t_k to t_{k+1}.
    step: [f64; K_SERIES_TERMS],
    /// ψ(k+1) = −γ + H_k (H_k the k-th harmonic number).
    psi: [f64; K_SERIES_TERMS],
    /// 1/(k+1): y^k/(k!(k+1)!) = t_k/(k+1).
    inv: [f64; K_SERIES_TERMS],
    /// (ψ(k+1) + ψ(k+2))/(k+1) = (2ψ(k+1) + 1/(k+1))/(k+1).
    psi_pair: [f64; K_SERIES_TERMS],
}

/// Euler–Mascheroni constant γ.
const EULER_GAMMA: f64 = 0.577_215_664_901_532_9;

const K_SERIES: KSeriesTable = {
    let mut t = KSeriesTable {
        step: [0.0; K_SERIES_TERMS],
        psi: [0.0; K_SERIES_TERMS],
        inv: [0.0; K_SERIES_TERMS],
        psi_pair: [0.0; K_SERIES_TERMS],
    };
    let mut psi = -EULER_GAMMA;
    let mut k = 0;
    while k < K_SERIES_TERMS {
        if k > 0 {
            psi += 1.0 / k as f64;
        }
        let k1 = (k + 1) as f64;
        t.step[k] = 1.0 / (k1 * k1);
        t.psi[k] = psi;
        t.inv[k] = 1.0 / k1;
        t.psi_pair[k] = (2.0 * psi + 1.0 / k1) / k1;
        k += 1;
    }
    t
};

/// K₀(w)/K₁(w) by the ascending series, DLMF 10.31.1 (principal logarithm):
/// K₀ = −ln(w/2)·I₀ + Σ ψ(k+1) y^k/(k!)², K₁ = 1/w + ln(w/2)·I₁ − (w/4) Σ (ψ(k+1) + ψ(k+2))
/// y^k/(k!(k+1)!), with y = w²/4 and ψ the digamma function (ψ(1) = −γ). Every sum is
/// Σ t_k·c_k over t_k = y^k/(k!)² with the real coefficients of [`K_SERIES`], so a term costs
/// one complex product and no division.
fn k0_over_k1_series(w: Complex64) -> Complex64 {
    let y = w * w * 0.25;
    // ln(w/2) from |w/2|² (no hypot) and the argument.
    let h = w * 0.5;
    let lg = Complex64::new(0.5 * h.norm_sqr().ln(), h.im.atan2(h.re));
    let tab = &K_SERIES;
    let mut t = Complex64::new(1.0, 0.0);
    let (mut i0, mut s0) = (t, t * tab.psi[0]);
    let (mut i1, mut s1) = (t * tab.inv[0], t * tab.psi_pair[0]);
    let eps2 = K_RATIO_EPS * K_RATIO_EPS;
    for k in 1..K_SERIES_TERMS {
        t *= y * tab.step[k - 1];
        i0 += t;
        s0 += t * tab.psi[k];
        i1 += t * tab.inv[k];
        s1 += t * tab.psi_pair[k];
        // Stop once the terms of I₀ (t_k) and of I₁ (t_k/(k+1)) are below eps of their sums.
        let tn = t.norm_sqr();
        if tn <= eps2 * i0.norm_sqr() && tn * tab.step[k] <= eps2 * i1.norm_sqr() {
            break;
        }
    }
    let k0 = -lg * i0 + s0;
    let k1 = w.inv() + lg * h * i1 - w * 0.25 * s1;
    k0 / k1
}

/// P(z) of eq. P16 from one Amos call for the scaled pair H₀⁽²⁾, H₁⁽²⁾·e^{iz} (the scale
/// cancels): valid for every z ≠ 0, the reference for [`hankel_ratio`].
pub fn hankel_ratio_amos(z: Complex64) -> Result<Complex64, SpecialError> {
    if !(z.re.is_finite() && z.im.is_finite()) || z == Complex64::new(0.0, 0.0) {
        return Err(SpecialError::BadArgument(z));
    }
    let h = hankel2_seq(0.0, z, 2, Scaling::Exponential).map_err(|_| SpecialError::Amos(z))?;
    let (h0, h1) = (h.values[0], h.values[1]);
    let p = -h0 / h1;
    if p.re.is_finite() && p.im.is_finite() {
        Ok(p)
    } else {
        Err(SpecialError::Amos(z))
    }
}

/// P(z) of eq. P16 and its derivative P′(z) = 1 + P² + P/z, which follows from
/// H₀⁽²⁾′ = −H₁⁽²⁾ and H₁⁽²⁾′ = H₀⁽²⁾ − H₁⁽²⁾/z (DLMF 10.6.2) at no extra Amos cost.
pub fn hankel_ratio_d(z: Complex64) -> Result<(Complex64, Complex64), SpecialError> {
    let p = hankel_ratio(z)?;
    Ok((p, 1.0 + p * p + p / z))
}

/// J₀(z)/J₁(z) from the scaled pair (the scale e^{−|Im z|} cancels).
pub fn bessel_j_ratio(z: Complex64) -> Result<Complex64, SpecialError> {
    if !(z.re.is_finite() && z.im.is_finite()) || z == Complex64::new(0.0, 0.0) {
        return Err(SpecialError::BadArgument(z));
    }
    let j = besselj_seq(0.0, z, 2, Scaling::Exponential).map_err(|_| SpecialError::Amos(z))?;
    let r = j.values[0] / j.values[1];
    if r.re.is_finite() && r.im.is_finite() {
        Ok(r)
    } else {
        Err(SpecialError::Amos(z))
    }
}

/// Fluid-loading factor ψ(z) = z J₀(z) / (2 J₁(z)) as a function of w = z², eq. P24.
///
/// ψ is even in z, so it is a function of w alone. For |w| < [`PSI_SERIES_Z2`] the series
/// 1 − w/8 − w²/192 is used; ψ(0) = 1. Otherwise the continued fraction of `psi_cf`.
pub fn psi(z2: Complex64) -> Result<Complex64, SpecialError> {
    psi_d(z2).map(|(p, _)| p)
}

/// Largest |w| for the continued fraction of ψ; beyond it (far outside the model's validity,
/// eq. P7) the scaled Amos pair J₀, J₁ is used.
pub const PSI_CF_MAX_ABS: f64 = 1e4;

/// ψ(w) of eq. P24 and 1/(2C₂) by Gauss' continued fraction of J₁/J₀ (DLMF 10.10.1 with
/// ν = 0): J₁(z)/J₀(z) = z/C₁ with C_k = 2k − w/C_{k+1}, so ψ = C₁/2 = 1 − w/(2C₂), in w = z²
/// only (no square root, no branch). Evaluated backwards from a depth N that grows with |z|
/// ([`psi_cf_depth`]). `abs_w_squared` is |w|², which the caller has computed.
fn psi_cf(w: Complex64, abs_w_squared: f64) -> (Complex64, Complex64) {
    let depth = psi_cf_depth(abs_w_squared);
    // C_k = n_k/d_k: C_k = 2k − w/C_{k+1} gives n_k = 2k·n_{k+1} − w·d_{k+1}, d_k = n_{k+1},
    // so the backward pass multiplies only and divides once at the end. The pair grows like
    // Π 2k; it is scaled down (the ratio unchanged) before it could overflow.
    let mut n = Complex64::new(2.0 * (depth + 1) as f64, 0.0);
    let mut d = Complex64::new(1.0, 0.0);
    for k in (2..=depth).rev() {
        (n, d) = (n * (2.0 * k as f64) - w * d, n);
        if n.re.abs() + n.im.abs() > 1e150 {
            (n, d) = (n * 1e-150, d * 1e-150);
        }
    }
    // 1/(2C₂) = d/(2n).
    let half_inv_c2 = d * 0.5 / n;
    (1.0 - w * half_inv_c2, half_inv_c2)
}

/// Depth of [`psi_cf`] for small |w|: (largest |w|², N). Starting the backward pass at
/// C_{N+1} ≈ 2(N + 1) errs by about |w|/(4(N+1)(N+2)) relative, and each level k back to C₂
/// damps that by |w|/|C_k C_{k+1}| ≈ |w|/(4k(k+1)), so C₂ errs by about
/// 2|w|^N/(4^N (N+1)! (N+2)!). Each row is the largest |w| at which that is below 1e-17, with
/// N one above the smallest such depth. 84 % of the calls of a realistic fit have |w| < 0.5.
const PSI_CF_SHALLOW: [(f64, usize); 8] = [
    (0.0032 * 0.0032, 5),
    (0.028 * 0.028, 6),
    (0.126 * 0.126, 7),
    (0.38 * 0.38, 8),
    (0.90 * 0.90, 9),
    (1.79 * 1.79, 10),
    (3.16 * 3.16, 11),
    (5.11 * 5.11, 12),
];

/// The depth N of [`psi_cf`] for |w|² = `abs_w_squared`: [`PSI_CF_SHALLOW`] for |w| up to 5,
/// otherwise 12 + 2|z|, whose truncation error falls like (|z|/2)^{2N}/(N!)².
fn psi_cf_depth(abs_w_squared: f64) -> usize {
    PSI_CF_SHALLOW
        .iter()
        .find(|(w2, _)| abs_w_squared <= *w2)
        .map(|&(_, n)| n)
        .unwrap_or_else(|| 12 + (2.0 * abs_w_squared.sqrt().sqrt()) as usize)
}

/// ψ of eq. P24 as a function of w = z², and dψ/dw. With Q = J₀/J₁, Q′ = −1 − Q² + Q/z
/// (DLMF 10.6.2), dψ/dw = (ψ − ψ²)/w − 1/4 = ψ·(1 − ψ)/w − 1/4; with the continued fraction
/// (1 − ψ)/w = 1/(2C₂) exactly, without cancellation. The series branch differentiates
/// 1 − w/8 − w²/192.
pub fn psi_d(w: Complex64) -> Result<(Complex64, Complex64), SpecialError> {
    if !(w.re.is_finite() && w.im.is_finite()) {
        return Err(SpecialError::BadArgument(w));
    }
    // |w|² against the squared limits: the same branches without a hypot per call.
    let r2 = w.norm_sqr();
    if r2 < PSI_SERIES_Z2 * PSI_SERIES_Z2 {
        return Ok((1.0 - w / 8.0 - w * w / 192.0, -1.0 / 8.0 - w / 96.0));
    }
    if r2 <= PSI_CF_MAX_ABS * PSI_CF_MAX_ABS {
        let (psi, one_minus_psi_over_w) = psi_cf(w, r2);
        if psi.is_finite() && one_minus_psi_over_w.is_finite() {
            return Ok((psi, psi * one_minus_psi_over_w - 0.25));
        }
    }
    let z = principal_sqrt(w);
    let q = bessel_j_ratio(z)?;
    let psi = z * q * 0.5;
    let dpsi_dz = q - z * 0.5 - z * q * q * 0.5;
    Ok((psi, dpsi_dz / (2.0 * z)))
}

#[cfg(test)]
#[allow(clippy::excessive_precision)] // reference values copied verbatim from tests/data/vectors (model Appendix A)
mod tests {
    use super::*;

    fn c(re: f64, im: f64) -> Complex64 {
        Complex64::new(re, im)
    }

    fn rel(a: Complex64, b: Complex64) -> f64 {
        (a - b).norm() / b.norm()
    }

    /// Model Appendix A.1, branch rule table.
    #[test]
    fn branch_rule_matches_appendix_a1() {
        let cases = [
            (c(4.0, 0.0), c(2.0, 0.0)),
            (c(-4.0, 0.0), c(0.0, -2.0)),
            (
                c(-4.0, 1e-3),
                c(-2.499999980468751e-04, -2.000000015625000e+00),
            ),
            (
                c(3.0, -0.5),
                c(1.738013415533538e+00, -1.438423879618067e-01),
            ),
            (
                c(-2.0, -1.0),
                c(3.435607497225124e-01, -1.455346690225355e+00),
            ),
            (
                c(1e-3, 5.0),
                c(1.581296951872102e+00, 1.580980724107666e+00),
            ),
        ];
        for (w, want) in cases {
            let got = sqrt_plus(w);
            assert!(
                rel(got, want) < 1e-14,
                "sqrt_plus({w}) = {got}, want {want}"
            );
        }
        // Insensitive to the sign of a zero imaginary part.
        assert_eq!(sqrt_plus(c(-4.0, -0.0)), sqrt_plus(c(-4.0, 0.0)));
    }

    /// Model Appendix A.1, P(z) from mpmath at ≥ 40 + |Im z| digits; tolerance 1e-13 (§5.7).
    #[test]
    fn hankel_ratio_matches_appendix_a1() {
        let cases = [
            (
                c(0.5, -0.01),
                c(-3.894831004867382e-01, 5.722228369731683e-01),
            ),
            (
                c(2.0, 0.0),
                c(-2.165174832343734e-01, 9.251380522829356e-01),
            ),
            (
                c(3.0, 0.2),
                c(-1.590356292313445e-01, 9.723232876826373e-01),
            ),
            (
                c(0.01, -5.0),
                c(-1.535075255091532e-04, 9.125963405413178e-01),
            ),
            (
                c(0.02, -30.0),
                c(-1.058181500793111e-05, 9.837366932490409e-01),
            ),
            (
                c(40.0, 1.0),
                c(-1.249804809193063e-02, 1.000078121903966e+00),
            ),
            (
                c(-1.0, -2.0),
                c(6.113831843959056e-02, 8.377331133774679e-01),
            ),
            (
                c(1e-4, 1e-5),
                c(-9.488342715582841e-04, 7.383352883323120e-05),
            ),
            (
                c(1.0, -800.0),
                c(-7.797866807020735e-07, 9.993755861800985e-01),
            ),
        ];
        for (z, want) in cases {
            let got = hankel_ratio(z).unwrap();
            assert!(rel(got, want) < 1e-13, "P({z}) = {got}, want {want}");
        }
    }

    /// Model Appendix A.1, ψ as a function of z².
    #[test]
    fn psi_matches_appendix_a1() {
        let cases = [
            (c(-1.0, 0.0), c(1.120096861935045, 0.0)),
            (c(-100.0, 1.0), c(5.270988083278432, -2.488229541549134e-02)),
            (c(2.5, 0.0), c(0.6488410556267773, 0.0)),
            (c(-0.3, -0.02), c(1.037041837456653, 2.439209693238545e-03)),
            (c(1e-8, 0.0), c(0.99999999875, 0.0)),
            (c(-1e-7, 0.0), c(1.0000000125, 0.0)),
        ];
        for (z2, want) in cases {
            let got = psi(z2).unwrap();
            assert!(rel(got, want) < 1e-13, "psi({z2}) = {got}, want {want}");
        }
    }

    #[test]
    fn principal_sqrt_agrees_with_num_complex() {
        for &(x, y) in &[
            (4.0, 0.0),
            (-4.0, 0.0),
            (-4.0, -0.0),
            (3.0, -0.5),
            (-2.0, -1.0),
            (1e-3, 5.0),
            (-1e-300, 1e-300),
            (2.5e10, -3.0e9),
            (0.0, -2.0),
        ] {
            let w = c(x, y);
            let (a, b) = (principal_sqrt(w), w.sqrt());
            assert!((a - b).norm() <= 1e-15 * b.norm(), "sqrt({w}) = {a} vs {b}");
        }
    }

    /// The analytic derivatives against central differences.
    #[test]
    fn derivatives_match_finite_differences() {
        for z in [c(0.5, -0.01), c(2.3, -0.1), c(0.02, -3.0), c(12.0, 0.5)] {
            let h = 1e-6 * z.norm();
            let (_, d) = hankel_ratio_d(z).unwrap();
            let fd = (hankel_ratio(z + h).unwrap() - hankel_ratio(z - h).unwrap()) / (2.0 * h);
            // |P| ~ 1 while P' can be ~1e-3: the differences carry ~1e-9 of Amos noise.
            assert!(
                (d - fd).norm() < 1e-8 * d.norm().max(1.0),
                "P'({z}) = {d} vs {fd}"
            );
        }
        for w in [
            c(-1.0, 0.0),
            c(-100.0, 1.0),
            c(2.5, 0.1),
            c(3e-7, 1e-7),
            c(-0.3, -0.02),
        ] {
            let h = 1e-6 * w.norm().max(1e-3);
            let (_, d) = psi_d(w).unwrap();
            let fd = (psi(w + h).unwrap() - psi(w - h).unwrap()) / (2.0 * h);
            assert!(rel(d, fd) < 1e-7, "dpsi/dw({w}) = {d} vs {fd}");
        }
    }

    /// The Amos-free ratio against Amos over the sector the model uses (−π < arg z ≤ π/4, and
    /// the edge of the second quadrant where Amos takes over), |z| from 1e-5 to 3000.
    #[test]
    fn fast_hankel_ratio_matches_amos_over_the_sector() {
        let mut worst: f64 = 0.0;
        let mut fast = 0usize;
        for i in 0..=80 {
            let r = 10f64.powf(-5.0 + 8.5 * i as f64 / 80.0);
            for j in 0..=72 {
                let th = -std::f64::consts::PI + 1.5 * std::f64::consts::PI * j as f64 / 72.0;
                let z = Complex64::from_polar(r, th);
                if z.im.abs() > 700.0 {
                    continue;
                }
                let w = c(-z.im, z.re);
                let (a, b) = (hankel_ratio(z).unwrap(), hankel_ratio_amos(z).unwrap());
                worst = worst.max(rel(a, b));
                if in_modified_bessel_sector(w) {
                    // The series or continued fraction itself, not a silent fall-back to Amos.
                    let r = k0_over_k1(w).unwrap_or_else(|| panic!("no K0/K1 at w = {w}"));
                    worst = worst.max(rel(c(-r.im, r.re), b));
                    fast += 1;
                }
            }
        }
        assert!(fast > 4000, "{fast} points on the fast path");
        assert!(
            worst < 1e-13,
            "worst relative difference from Amos {worst:e}"
        );
    }

    /// ψ and dψ/dw by the continued fraction against the scaled Amos pair J₀, J₁.
    #[test]
    fn psi_continued_fraction_matches_amos() {
        let mut worst: f64 = 0.0;
        let mut worst_d: f64 = 0.0;
        for i in 0..=60 {
            let r = 10f64.powf(-5.9 + 9.8 * i as f64 / 60.0);
            for j in 0..72 {
                let w = Complex64::from_polar(r, std::f64::consts::TAU * j as f64 / 72.0);
                // Stay clear of the poles of ψ (zeros of J₁ on the positive real w axis).
                if (w.im.abs() < 0.05 * r) && w.re > 0.0 {
                    continue;
                }
                let z = principal_sqrt(w);
                let q = bessel_j_ratio(z).unwrap();
                let want = z * q * 0.5;
                let want_d = (q - z * 0.5 - z * q * q * 0.5) / (2.0 * z);
                let (got, got_d) = psi_d(w).unwrap();
                worst = worst.max(rel(got, want));
                worst_d = worst_d.max((got_d - want_d).norm() / want_d.norm().max(1.0));
                if (PSI_SERIES_Z2..=PSI_CF_MAX_ABS).contains(&r) {
                    // The continued fraction itself (its rescaling included at large |w|), not
                    // a silent fall-back to Amos.
                    let (cf, _) = psi_cf(w, w.norm_sqr());
                    worst = worst.max(rel(cf, want));
                }
            }
        }
        assert!(worst < 1e-13, "worst relative difference in psi {worst:e}");
        assert!(worst_d < 1e-9, "worst difference in dpsi/dw {worst_d:e}");
    }

    #[test]
    fn zero_argument_is_an_error_not_a_nan() {
        assert!(hankel_ratio(c(0.0, 0.0)).is_err());
        assert!(hankel_ratio(c(f64::NAN, 0.0)).is_err());
        assert_eq!(psi(c(0.0, 0.0)).unwrap(), c(1.0, 0.0));
    }
}
