//! The distributions of the diagnosis's tests, from `statrs` (no hand-written tails);
//! the plain χ² tail is the crate's [`crate::stats::chi2_upper_tail`].

use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Upper-tail probability P(χ²_dof > x); 1 for x ≤ 0, NaN for dof ≤ 0 or a NaN x.
pub fn chi2_sf(x: f64, dof: f64) -> f64 {
    if x.is_nan() || dof <= 0.0 || dof.is_nan() {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    if x.is_infinite() {
        return 0.0;
    }
    crate::stats::chi2_upper_tail(x, dof)
}

/// Upper-tail probability of the χ̄² = ½χ²₀ + ½χ²₁ mixture: the likelihood-ratio (or score)
/// statistic of one parameter tested on the boundary of its range (Self & Liang 1987).
pub fn chibar_sf(x: f64) -> f64 {
    if x <= 0.0 {
        1.0
    } else {
        0.5 * chi2_sf(x, 1.0)
    }
}

/// Upper-tail probability of the sum of `n` independent χ̄² statistics: the sum has the
/// binomial mixture Σ_k C(n, k) 2⁻ⁿ χ²_k (χ²₀ a point mass at 0).
pub fn sum_chibar_sf(x: f64, n: usize) -> f64 {
    if n == 0 {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    let nf = n as f64;
    // log C(n, k) by lgamma-free recurrence.
    let mut log_c = 0.0f64;
    let mut p = 0.0;
    for k in 1..=n {
        log_c += ((nf - k as f64 + 1.0) / k as f64).ln();
        p += (log_c - nf * std::f64::consts::LN_2).exp() * chi2_sf(x, k as f64);
    }
    p.min(1.0)
}

/// The x with P(χ²_dof > x) = p (0 < p < 1).
pub fn chi2_isf(p: f64, dof: f64) -> f64 {
    ChiSquared::new(dof)
        .map(|d| d.inverse_cdf(1.0 - p))
        .unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tails_match_closed_forms() {
        // χ²₂: sf(x) = exp(−x/2) exactly; χ²₁ at 3.841459: 0.05.
        for x in [0.1, 1.0, 5.0, 20.0] {
            assert!((chi2_sf(x, 2.0) - (-x / 2.0f64).exp()).abs() < 1e-12, "{x}");
        }
        assert!((chi2_sf(3.841_458_820_694_124, 1.0) - 0.05).abs() < 1e-12);
        // The issue-11 case: 1 dof near 1e-4 (x = 15.1367 gives 1e-4).
        assert!((chi2_sf(15.136_705_226_623_606, 1.0) / 1e-4 - 1.0).abs() < 1e-6);
        assert_eq!(chibar_sf(0.0), 1.0);
        assert!((chibar_sf(3.841_458_820_694_124) - 0.025).abs() < 1e-12);
        // One χ̄² term is the mixture itself; two: ¼χ²₂ + ½χ²₁ (k = 1 twice).
        assert!((sum_chibar_sf(2.5, 1) - chibar_sf(2.5)).abs() < 1e-14);
        let two = 0.5 * chi2_sf(2.5, 1.0) + 0.25 * chi2_sf(2.5, 2.0);
        assert!((sum_chibar_sf(2.5, 2) - two).abs() < 1e-14);
        assert!((chi2_isf(0.05, 1.0) - 3.841_458_820_694_124).abs() < 1e-9);
    }
}
