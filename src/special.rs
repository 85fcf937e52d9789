//! Special functions of complex argument used by the model: the Hankel ratio P(z) of eq. P16,
//! the fluid-loading factor ψ of eq. P24 and the branch rule of eq. P3.
//!
//! The Bessel and Hankel functions come from `complex-bessel`, a pure-Rust port of Amos'
//! TOMS 644 [R17]. We always use the exponentially scaled forms: the scale factor cancels in
//! every ratio we form, and the unscaled H⁽²⁾ underflows silently for large |Im z| (spec §5.7:
//! H⁽²⁾(1 − 800i) returns 0 and the ratio becomes NaN).

use complex_bessel::{besselj_seq, hankel2_seq, Scaling};
use num_complex::Complex64;

/// Below this |z²| the fluid-loading factor uses its series ψ = 1 − z²/8 − z⁴/192 (spec §5.5,
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
/// evanescent ones (w < 0) get q = −i√|w|. Same as Kalkowski's `root_sign` [R12].
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
    let t = ((x.abs() + x.hypot(y)) * 0.5).sqrt();
    if x >= 0.0 {
        Complex64::new(t, y / (2.0 * t))
    } else {
        Complex64::new(y.abs() / (2.0 * t), t.copysign(y))
    }
}

/// P(z) = H₀(z)/H₀′(z) = −H₀⁽²⁾(z)/H₁⁽²⁾(z), eq. P16 (second kind, principal branch).
///
/// Computed from one call for the scaled pair H₀⁽²⁾, H₁⁽²⁾·e^{iz}; the scale cancels.
pub fn hankel_ratio(z: Complex64) -> Result<Complex64, SpecialError> {
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

/// Fluid-loading factor ψ(z) = z J₀(z) / (2 J₁(z)) as a function of z², eq. P24.
///
/// ψ is even in z, so z is the principal √(z²). For |z²| < [`PSI_SERIES_Z2`] the series
/// 1 − z²/8 − z⁴/192 is used; ψ(0) = 1.
pub fn psi(z2: Complex64) -> Result<Complex64, SpecialError> {
    if z2.norm() < PSI_SERIES_Z2 {
        return Ok(1.0 - z2 / 8.0 - z2 * z2 / 192.0);
    }
    let z = principal_sqrt(z2);
    Ok(z * bessel_j_ratio(z)? * 0.5)
}

/// ψ of eq. P24 as a function of w = z², and dψ/dw. With Q = J₀/J₁, Q′ = −1 − Q² + Q/z
/// (DLMF 10.6.2), so dψ/dz = Q − z/2 − zQ²/2 and dψ/dw = (dψ/dz)/(2z); the series branch
/// differentiates 1 − w/8 − w²/192.
pub fn psi_d(w: Complex64) -> Result<(Complex64, Complex64), SpecialError> {
    if w.norm() < PSI_SERIES_Z2 {
        return Ok((1.0 - w / 8.0 - w * w / 192.0, -1.0 / 8.0 - w / 96.0));
    }
    let z = principal_sqrt(w);
    let q = bessel_j_ratio(z)?;
    let psi = z * q * 0.5;
    let dpsi_dz = q - z * 0.5 - z * q * q * 0.5;
    Ok((psi, dpsi_dz / (2.0 * z)))
}

#[cfg(test)]
#[allow(clippy::excessive_precision)] // reference values copied verbatim from the spec
mod tests {
    use super::*;

    fn c(re: f64, im: f64) -> Complex64 {
        Complex64::new(re, im)
    }

    fn rel(a: Complex64, b: Complex64) -> f64 {
        (a - b).norm() / b.norm()
    }

    /// Spec Appendix A.1, branch rule table.
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

    /// Spec Appendix A.1, P(z) from mpmath at ≥ 40 + |Im z| digits; tolerance 1e-13 (§5.7).
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

    /// Spec Appendix A.1, ψ as a function of z².
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

    #[test]
    fn zero_argument_is_an_error_not_a_nan() {
        assert!(hankel_ratio(c(0.0, 0.0)).is_err());
        assert!(hankel_ratio(c(f64::NAN, 0.0)).is_err());
        assert_eq!(psi(c(0.0, 0.0)).unwrap(), c(1.0, 0.0));
    }
}
