//! The search box in the coordinates the data determine, (ln c_P, r = c_S/c_P) instead of
//! (E_m, ν_m), given the soil density ρ_m (fixed, model §7.5); the map itself is
//! [`crate::physics::soil`].
//!
//! The search box of P51, E_m ∈ [1e3, 1e10] Pa and ν_m ∈ [0, 0.499], maps to the region
//! r ∈ [r(0.499), r(0)] = [0.04468, 1/√2] and, at each r, ln c_P between ½ ln(E_min f(ν_m)/ρ_m)
//! and ½ ln(E_max f(ν_m)/ρ_m), where f(ν) = M/E = (1 − ν)/((1 + ν)(1 − 2ν)) grows from 1 at
//! ν = 0 to 167.1 at ν = 0.499. Its bounding box in ln c_P is therefore
//! [½ ln(E_min/ρ_m), ½ ln(167.1 E_max/ρ_m)]: for ρ_m = 1,900 kg/m³, c_P from 0.73 m/s to
//! 29,700 m/s (ln c_P from −0.32 to 10.30). The region is not the whole box: a soft soil at
//! large r (small ν_m) or a stiff one at small r lies outside the search range, which
//! [`SpeedBox::contains`] tells.

use crate::physics::soil::{poisson_of_ratio, shear_to_compressional, speeds_of};

/// The image of a box of (E_m, ν_m) in (ln c_P, r) at one soil density.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedBox {
    /// E_m range, Pa.
    pub e: (f64, f64),
    /// ν_m range.
    pub nu: (f64, f64),
    /// Soil density ρ_m, kg/m³.
    pub rho: f64,
}

impl SpeedBox {
    /// The image of E_m ∈ `e`, ν_m ∈ `nu` (0 ≤ ν_lo < ν_hi < ½) at density `rho`.
    pub fn new(e: (f64, f64), nu: (f64, f64), rho: f64) -> Self {
        Self { e, nu, rho }
    }

    /// The range of r: [r(ν_hi), r(ν_lo)] (r falls as ν_m grows).
    pub fn r_range(&self) -> (f64, f64) {
        (
            shear_to_compressional(self.nu.1),
            shear_to_compressional(self.nu.0),
        )
    }

    /// The range of ln c_P of the soils in the box with c_S/c_P = r: E_m's range at the ν_m
    /// of r, through M = E f(ν) (P63). `None` when r lies outside [`Self::r_range`].
    pub fn ln_cp_range_at(&self, r: f64) -> Option<(f64, f64)> {
        let nu = poisson_of_ratio(r)?;
        if nu < self.nu.0 - 1e-12 || nu > self.nu.1 + 1e-12 {
            return None;
        }
        Some((
            speeds_of(self.e.0, nu, self.rho).0,
            speeds_of(self.e.1, nu, self.rho).0,
        ))
    }

    /// The bounding box of ln c_P: from the softest soil at the smallest M/E (ν_lo) to the
    /// stiffest at the largest (ν_hi); f(ν) = M/E grows with ν_m.
    pub fn ln_cp_range(&self) -> (f64, f64) {
        (
            speeds_of(self.e.0, self.nu.0, self.rho).0,
            speeds_of(self.e.1, self.nu.1, self.rho).0,
        )
    }

    /// Whether the soil (ln c_P, r) lies in the box of (E_m, ν_m).
    pub fn contains(&self, ln_cp: f64, r: f64) -> bool {
        self.range_holding(ln_cp, r).is_some()
    }

    /// [`Self::ln_cp_range_at`] `r` when it holds `ln_cp` (to 1e-12), else `None`: the test of
    /// [`Self::contains`] and the range it found, for a caller that needs both.
    pub fn range_holding(&self, ln_cp: f64, r: f64) -> Option<(f64, f64)> {
        self.ln_cp_range_at(r)
            .filter(|&(lo, hi)| ln_cp >= lo - 1e-12 && ln_cp <= hi + 1e-12)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::invert::problem::E_BOUNDS;
    use crate::physics::inputs::MAX_SOIL_POISSON;
    use crate::physics::soil::soil_of;

    /// The ratio's range over ν_m ∈ [0, 0.499] is [0.04468, 1/√2], and r outside (0, 1/√2]
    /// has no Poisson's ratio.
    #[test]
    fn the_ratio_spans_the_incompressible_corner_to_nu_zero() {
        let b = SpeedBox::new(E_BOUNDS, (0.0, MAX_SOIL_POISSON), 1_900.0);
        let (lo, hi) = b.r_range();
        assert!((lo - 0.044_68).abs() < 1e-5, "{lo}");
        assert!((hi - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-15, "{hi}");
        assert_eq!(poisson_of_ratio(hi), Some(0.0));
        assert!((poisson_of_ratio(lo).unwrap() - MAX_SOIL_POISSON).abs() < 1e-12);
        assert!(poisson_of_ratio(0.0).is_none());
        assert!(poisson_of_ratio(0.71).is_none());
        assert!(b.ln_cp_range_at(0.03).is_none());
    }

    /// The bounding box in ln c_P at ρ_m = 1,900 kg/m³ is [−0.321, 10.30]; a soil inside it
    /// lies in the search box only where its E_m does, and every corner of the (E_m, ν_m) box
    /// maps to the edge of the region.
    #[test]
    fn the_region_is_the_image_of_the_search_box() {
        let rho = 1_900.0;
        let b = SpeedBox::new(E_BOUNDS, (0.0, MAX_SOIL_POISSON), rho);
        let (lo, hi) = b.ln_cp_range();
        assert!((lo - 0.5 * (1e3f64 / rho).ln()).abs() < 1e-12);
        assert!((lo + 0.3209).abs() < 1e-3, "{lo}");
        assert!((hi - 10.297).abs() < 1e-3, "{hi}");
        for e in [E_BOUNDS.0, E_BOUNDS.1] {
            for nu in [0.0, MAX_SOIL_POISSON] {
                let (l, r) = speeds_of(e, nu, rho);
                assert!(b.contains(l, r));
                assert!(!b.contains(l + if e == E_BOUNDS.0 { -1e-6 } else { 1e-6 }, r));
                // The range it holds the soil in is the range at its r, one end at the soil.
                let (lo, hi) = b.range_holding(l, r).expect("inside");
                assert_eq!(Some((lo, hi)), b.ln_cp_range_at(r));
                assert!((if e == E_BOUNDS.0 { lo } else { hi } - l).abs() < 1e-12);
            }
        }
        // A soft soil at ν_m = 0 (large r) exists only down to E_min; at ν_m = 0.499 the same c_P
        // needs E_m far below it.
        let (l0, r0) = speeds_of(E_BOUNDS.0, 0.0, rho);
        let r_incompressible = shear_to_compressional(MAX_SOIL_POISSON);
        assert!(b.contains(l0, r0));
        assert!(!b.contains(l0, r_incompressible));
        let (e, _) = soil_of(l0, r_incompressible, rho).unwrap();
        assert!(e < E_BOUNDS.0 / 100.0, "{e}");
    }
}
