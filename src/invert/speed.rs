//! The soil in the coordinates the data determine: (ln c_P, r = c_S/c_P) instead of
//! (E_m, ν_m), given the soil density ρ_m (fixed, model §7.5).
//!
//! The map is exact and one-to-one on ν_m ∈ [0, ½): c_P = √(M/ρ_m) with the P-wave modulus M of
//! P63, c_S = √(G/ρ_m) with the shear modulus G of P64, and r depends on ν_m alone,
//! r² = (1 − 2ν_m)/(2(1 − ν_m)). Its inverse: ν_m = (1 − 2r²)/(2(1 − r²)), M = ρ_m c_P² and
//! E_m from M at that ν_m.
//!
//! The search box of P51, E_m ∈ [1e3, 1e10] Pa and ν_m ∈ [0, 0.499], maps to the region
//! r ∈ [r(0.499), r(0)] = [0.04468, 1/√2] and, at each r, ln c_P between ½ ln(E_min f(ν_m)/ρ_m)
//! and ½ ln(E_max f(ν_m)/ρ_m), where f(ν) = M/E = (1 − ν)/((1 + ν)(1 − 2ν)) grows from 1 at
//! ν = 0 to 167.1 at ν = 0.499. Its bounding box in ln c_P is therefore
//! [½ ln(E_min/ρ_m), ½ ln(167.1 E_max/ρ_m)]: for ρ_m = 1,900 kg/m³, c_P from 0.73 m/s to
//! 29,700 m/s (ln c_P from −0.32 to 10.30). The region is not the whole box: a soft soil at
//! large r (small ν_m) or a stiff one at small r lies outside the search range, which
//! [`SpeedBox::contains`] tells.

use super::uncertainty::{shear_to_compressional, soil_moduli, youngs_from_p_wave_modulus};

/// Poisson's ratio ν_m of a soil with c_S/c_P = r, the inverse of [`shear_to_compressional`]:
/// (1 − 2r²)/(2(1 − r²)); `None` outside 0 < r ≤ 1/√2 (ν_m ≥ 0, ν_m < ½).
pub fn poisson_of_ratio(r: f64) -> Option<f64> {
    let r2 = r * r;
    (r > 0.0 && r2 <= 0.5 + 1e-15).then(|| ((1.0 - 2.0 * r2) / (2.0 * (1.0 - r2))).max(0.0))
}

/// (ln c_P, r) of a soil with Young's modulus `e` (Pa) and Poisson's ratio `nu`, density `rho`
/// (P63–P64).
pub fn speeds_of(e: f64, nu: f64, rho: f64) -> (f64, f64) {
    let (m, _) = soil_moduli(e, nu);
    (0.5 * (m / rho).ln(), shear_to_compressional(nu))
}

/// (E_m in Pa, ν_m) of the soil with ln c_P = `ln_cp` and c_S/c_P = `r`, density `rho`: the
/// inverse of [`speeds_of`]. `None` where r gives no Poisson's ratio in [0, ½).
pub fn soil_of(ln_cp: f64, r: f64, rho: f64) -> Option<(f64, f64)> {
    let nu = poisson_of_ratio(r)?;
    let m = rho * (2.0 * ln_cp).exp();
    Some((youngs_from_p_wave_modulus(m, nu), nu))
}

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
        self.ln_cp_range_at(r)
            .is_some_and(|(lo, hi)| ln_cp >= lo - 1e-12 && ln_cp <= hi + 1e-12)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::invert::problem::E_BOUNDS;
    use crate::invert::uncertainty::soil_speeds;
    use crate::physics::inputs::MAX_SOIL_POISSON;

    /// (E_m, ν_m) → (ln c_P, r) → (E_m, ν_m) returns the soil to 1e-12 relative over the whole
    /// search box, and the speeds agree with P63–P64 computed directly.
    #[test]
    fn the_map_round_trips_over_the_search_box() {
        let rho = 1_900.0;
        for i in 0..=40 {
            let log10_e = 3.0 + 7.0 * i as f64 / 40.0;
            let e = 10f64.powf(log10_e);
            for j in 0..=40 {
                let nu = MAX_SOIL_POISSON * j as f64 / 40.0;
                let (ln_cp, r) = speeds_of(e, nu, rho);
                let (cp, cs) = soil_speeds(e, nu, rho);
                assert!((ln_cp.exp() / cp - 1.0).abs() < 1e-12, "{e} {nu}");
                assert!((r * cp / cs - 1.0).abs() < 1e-12, "{e} {nu}");
                let (e2, nu2) = soil_of(ln_cp, r, rho).expect("a soil");
                assert!((e2 / e - 1.0).abs() < 1e-10, "{e} {nu}: {e2}");
                assert!((nu2 - nu).abs() < 1e-10, "{e} {nu}: {nu2}");
            }
        }
    }

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
