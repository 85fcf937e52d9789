//! The Cramér–Rao bound of a zone's soil (model §7.11, P67–P68): how well any unbiased
//! estimator can know (log10 E_z, ν_z) from the zone's members' pipes, frequency plans and noise.
//!
//! Each member s contributes its Fisher information H_s of (log10 E_s, ν_s) at its true
//! parameters (JᵀJ of the residuals weighted by the measurement standard deviations, from the
//! exact forward model; ξ and any effect parameters profiled out, [`soil_information`]). Its soil
//! is the zone's plus the scatter of P67, (log10 E_s, ν_s) = (log10 E_z, ν_z) + (δ_s, ε_s) with
//! covariance T = diag(τ_E², τ_ν²), so, linearised, the member sees the zone with covariance
//! H_s⁻¹ + T: its information on the zone is (H_s⁻¹ + T)⁻¹ = H_s (I + T H_s)⁻¹ (defined when
//! H_s is singular, e.g. a metal pipe that sees c_P only). The zone's information is the sum
//! over its members and the bound is its inverse.

use statrs::distribution::{ContinuousCDF, Normal};

use crate::invert::problem::Weighting;
use crate::invert::SegmentData;

use super::member::soil_information;
use super::FitSetup;

/// The Fisher information of (log10 E_m, ν_m) of one segment at its true parameters `x_true`
/// (default coordinates: log10 E_m, ν_m, ξ, effects…), the other parameters profiled out.
/// `None` without measurement standard deviations (no likelihood), or where the model or its
/// Jacobian cannot be evaluated.
pub fn member_fisher(data: &SegmentData, setup: &FitSetup, x_true: &[f64]) -> Option<[f64; 4]> {
    let problem = setup.problem(data);
    if problem.weighting != Weighting::ChiSquare || x_true.len() != problem.specs.len() {
        return None;
    }
    let k = problem.predict(x_true)?;
    soil_information(&problem, x_true, &k, 1.0)
}

/// A member's information on its zone's (log10 E_z, ν_z) given the scatter `tau` (τ_E decades,
/// τ_ν) of P67: (H⁻¹ + T)⁻¹ = H (I + T H)⁻¹, symmetrised.
pub fn information_on_zone(h: &[f64; 4], tau: (f64, f64)) -> [f64; 4] {
    let t = [tau.0 * tau.0, tau.1 * tau.1];
    // A = I + T H.
    let a = [
        1.0 + t[0] * h[0],
        t[0] * h[1],
        t[1] * h[2],
        1.0 + t[1] * h[3],
    ];
    let det = a[0] * a[3] - a[1] * a[2];
    let ai = [a[3] / det, -a[1] / det, -a[2] / det, a[0] / det];
    let g = [
        h[0] * ai[0] + h[1] * ai[2],
        h[0] * ai[1] + h[1] * ai[3],
        h[2] * ai[0] + h[3] * ai[2],
        h[2] * ai[1] + h[3] * ai[3],
    ];
    let off = 0.5 * (g[1] + g[2]);
    [g[0], off, off, g[3]]
}

/// The Cramér–Rao bound of one zone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZoneBound {
    /// The zone's Fisher information of (log10 E_z, ν_z), row-major 2 × 2.
    pub information: [f64; 4],
    /// Smallest one-sigma error of ln E_z an unbiased estimator can have.
    pub sd_ln_modulus: f64,
    /// Smallest one-sigma error of ν_z.
    pub sd_poisson: f64,
}

/// The bound of a zone from its members' Fisher informations ([`member_fisher`]) and the
/// scatter `tau` of P67. Infinite errors where the information is singular.
pub fn zone_bound(members: &[[f64; 4]], tau: (f64, f64)) -> ZoneBound {
    let mut j = [0.0; 4];
    for h in members {
        let g = information_on_zone(h, tau);
        for (a, b) in j.iter_mut().zip(g) {
            *a += b;
        }
    }
    let det = j[0] * j[3] - j[1] * j[2];
    let (var_le, var_nu) = if det.is_finite() && det > 0.0 {
        (j[3] / det, j[0] / det)
    } else {
        (f64::INFINITY, f64::INFINITY)
    };
    ZoneBound {
        information: j,
        sd_ln_modulus: std::f64::consts::LN_10 * var_le.sqrt(),
        sd_poisson: var_nu.sqrt(),
    }
}

/// The `p` quantile of |E_est / E_true − 1| over zones pooled, for an efficient estimator
/// whose ln E error in zone i is N(0, `sd_ln[i]`²): the x with
/// mean_i P(|exp(σ_i Z) − 1| ≤ x) = p, where P(…) = Φ(ln(1 + x)/σ_i) − Φ(ln(1 − x)/σ_i).
/// `NaN` without zones; 1 (or more) if the errors are that large.
pub fn pooled_error_quantile(sd_ln: &[f64], p: f64) -> f64 {
    if sd_ln.is_empty() || !(0.0..1.0).contains(&p) {
        return f64::NAN;
    }
    let phi = Normal::standard();
    let cdf = |x: f64| {
        sd_ln
            .iter()
            .map(|&s| {
                if s <= 0.0 {
                    1.0
                } else if !s.is_finite() {
                    0.0
                } else {
                    let lo = if x >= 1.0 {
                        0.0
                    } else {
                        phi.cdf((1.0 - x).ln() / s)
                    };
                    phi.cdf((1.0 + x).ln() / s) - lo
                }
            })
            .sum::<f64>()
            / sd_ln.len() as f64
    };
    // Bisection on x ∈ [0, hi], the pooled cdf rising from 0.
    let mut hi = 1.0;
    while cdf(hi) < p {
        hi *= 2.0;
        if hi > 1e6 {
            return f64::INFINITY;
        }
    }
    let (lo, hi) = crate::optimize::bisect(0.0, hi, 100, |x| cdf(x) < p);
    0.5 * (lo + hi)
}

/// The distribution of the sample `p` quantile of |E_est / E_true − 1| over one network's zones
/// for an efficient estimator (ln E error of zone i ~ N(0, `sd_ln[i]`²), independent), by
/// `draws` simulations from `seed`, the sample quantile taken as the zones_acceptance example
/// and the zones test take it (element round((n − 1) p) of the sorted errors): (its median,
/// the probability that it is at most `threshold`).
pub fn sample_quantile_distribution(
    sd_ln: &[f64],
    p: f64,
    threshold: f64,
    draws: usize,
    seed: u64,
) -> (f64, f64) {
    use rand::SeedableRng;
    let n = sd_ln.len();
    if n == 0 || draws == 0 {
        return (f64::NAN, f64::NAN);
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let idx = ((n - 1) as f64 * p).round() as usize;
    let mut q: Vec<f64> = (0..draws)
        .map(|_| {
            let mut e: Vec<f64> = sd_ln
                .iter()
                .map(|&s| (s * crate::stats::normal(&mut rng)).exp_m1().abs())
                .collect();
            e.sort_by(f64::total_cmp);
            e[idx]
        })
        .collect();
    let pass = q.iter().filter(|&&v| v <= threshold).count() as f64 / draws as f64;
    q.sort_by(f64::total_cmp);
    (q[draws / 2], pass)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pooled_quantile_of_one_small_sigma_is_the_half_normal_quantile() {
        // |exp(σZ) − 1| ≈ σ|Z| for small σ: the 0.9 quantile of |Z| is 1.6449.
        let q = pooled_error_quantile(&[1e-4], 0.9);
        assert!((q / 1e-4 - 1.644_853_6).abs() < 1e-3, "{q}");
        // Two zones, one exact: the pooled 0.9 quantile is the other's 0.8 quantile (1.2816 σ).
        let q = pooled_error_quantile(&[0.0, 1e-4], 0.9);
        assert!((q / 1e-4 - 1.281_551_6).abs() < 1e-3, "{q}");
    }

    #[test]
    fn zone_information_adds_members_seen_through_the_scatter() {
        // A member that knows its soil exactly tells the zone only up to the scatter.
        let exact = [1e12, 0.0, 0.0, 1e12];
        let g = information_on_zone(&exact, (0.04, 0.01));
        assert!((g[0] * 0.04 * 0.04 - 1.0).abs() < 1e-6, "{g:?}");
        assert!((g[3] * 0.01 * 0.01 - 1.0).abs() < 1e-6, "{g:?}");
        // Without scatter the member's own information; n equal members: n times it.
        let h = [400.0, 30.0, 30.0, 900.0];
        assert_eq!(information_on_zone(&h, (0.0, 0.0)), h);
        let b = zone_bound(&[h; 4], (0.0, 0.0));
        let det = h[0] * h[3] - h[1] * h[2];
        let var = h[3] / det / 4.0;
        assert!((b.sd_ln_modulus - std::f64::consts::LN_10 * var.sqrt()).abs() < 1e-12);
        // A c_P-only member (singular information) stays singular through the scatter.
        let cp_only = [100.0, 200.0, 200.0, 400.0];
        let j = zone_bound(&[cp_only], (0.04, 0.01)).information;
        let det = j[0] * j[3] - j[1] * j[2];
        assert!(det.abs() <= 1e-9 * (j[0] + j[3]).powi(2), "{j:?}");
    }
}
