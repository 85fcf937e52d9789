//! Statistical tails used by the fit's misfit test and the diagnosis (from `statrs`), the
//! Birge ratio that widens errors where the model does not explain the data, sample quantiles,
//! and the standard normal deviate the synthetic data draw.

use rand::Rng;
use statrs::distribution::{ChiSquared, ContinuousCDF, Normal, StudentsT};

/// Upper-tail probability P(χ²_k > x); NaN for a non-finite x or k ≤ 0.
pub fn chi2_upper_tail(x: f64, k: f64) -> f64 {
    if !(x.is_finite() && k > 0.0) {
        return f64::NAN;
    }
    ChiSquared::new(k).map_or(f64::NAN, |d| d.sf(x.max(0.0)))
}

/// Birge ratio R_B = max(1, √(χ²_min / (n − p))), eq. P88: the factor by which a fit's errors
/// are widened when its misfit is larger than the measurement noise explains. 1 when there are
/// no degrees of freedom (n ≤ p) or χ² is not finite, since then the misfit says nothing.
pub fn birge_ratio(chi2_min: f64, n_measured: usize, n_fitted: usize) -> f64 {
    if n_measured <= n_fitted || !chi2_min.is_finite() {
        return 1.0;
    }
    (chi2_min / (n_measured - n_fitted) as f64).sqrt().max(1.0)
}

/// The ratio of Student's t quantile with `dof` degrees of freedom to the standard normal's, at
/// the two-sided `level` (e.g. 0.95): the factor by which a Gaussian standard deviation must be
/// widened for its interval to be the t interval. 1 for infinite `dof`; NaN for `dof` ≤ 0.
pub fn t_over_normal(dof: f64, level: f64) -> f64 {
    let p = 0.5 + 0.5 * level;
    let z = Normal::new(0.0, 1.0).map_or(f64::NAN, |n| n.inverse_cdf(p));
    if dof.is_infinite() && dof > 0.0 {
        return 1.0;
    }
    StudentsT::new(0.0, 1.0, dof).map_or(f64::NAN, |t| t.inverse_cdf(p) / z)
}

/// Linear-interpolated quantile `q` in [0, 1] of sorted finite values (type 7, as R's default
/// and numpy's `linear`). `None` for an empty slice.
pub fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let pos = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let i = pos.floor() as usize;
    let frac = pos - i as f64;
    let next = sorted.get(i + 1).copied().unwrap_or(sorted[i]);
    Some(sorted[i] + frac * (next - sorted[i]))
}

/// The finite values, sorted.
pub fn sorted_finite(values: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v
}

/// Standard normal deviate by Box–Muller.
pub fn normal<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    let u1: f64 = rng.gen_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn birge_ratio_is_root_chi2_per_dof_and_never_below_one() {
        assert_eq!(birge_ratio(36.0, 8, 4), 3.0);
        assert_eq!(birge_ratio(2.0, 8, 4), 1.0);
        assert_eq!(birge_ratio(50.0, 3, 3), 1.0);
        assert_eq!(birge_ratio(f64::INFINITY, 8, 3), 1.0);
    }

    #[test]
    fn chi2_tail_matches_tables() {
        // chi-square 0.999 quantiles (Abramowitz & Stegun Table 26.8): k = 1: 10.828;
        // k = 5: 20.515; k = 13: 34.528.
        for (x, k) in [(10.828, 1.0), (20.515, 5.0), (34.528, 13.0)] {
            let p = chi2_upper_tail(x, k);
            assert!((p / 1e-3 - 1.0).abs() < 1e-3, "k = {k}: p = {p}");
        }
        // Median of chi-square(10) is 9.342.
        assert!((chi2_upper_tail(9.342, 10.0) - 0.5).abs() < 1e-3);
        assert!(chi2_upper_tail(f64::NAN, 3.0).is_nan());
        assert_eq!(chi2_upper_tail(-1.0, 3.0), 1.0);
    }

    #[test]
    fn quantiles_interpolate_linearly() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(quantile(&v, 0.5), Some(3.0));
        assert_eq!(quantile(&v, 0.9), Some(4.6));
        assert_eq!(quantile(&v, 0.0), Some(1.0));
        assert_eq!(quantile(&v, 1.0), Some(5.0));
        assert_eq!(quantile(&[7.0], 0.9), Some(7.0));
        assert_eq!(quantile(&[], 0.5), None);
        assert_eq!(
            sorted_finite([3.0, f64::NAN, 1.0].into_iter()),
            vec![1.0, 3.0]
        );
    }
}
