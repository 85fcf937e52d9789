//! The soil's elastic moduli and its wave speeds (P63–P65), in both directions: E_m and ν_m
//! to the P-wave and shear moduli M and G, to c_P = √(M/ρ_m) and c_S = √(G/ρ_m), and back; the
//! ratio r = c_S/c_P, which depends on ν_m alone; and the logarithmic coordinates (ln c_P, r)
//! in which the search, the intervals and the soil field work.
//!
//! The map is exact and one-to-one on ν_m ∈ [0, ½): c_P = √(M/ρ_m) with the P-wave modulus M of
//! P63, c_S = √(G/ρ_m) with the shear modulus G of P64, and r depends on ν_m alone,
//! r² = (1 − 2ν_m)/(2(1 − ν_m)). Its inverse: ν_m = (1 − 2r²)/(2(1 − r²)), M = ρ_m c_P² and
//! E_m from M at that ν_m.

/// The soil's P-wave modulus M and shear modulus G from E_m and ν_m, Pa (P63, P64).
pub fn soil_moduli(e: f64, nu: f64) -> (f64, f64) {
    let m = e * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let g = e / (2.0 * (1.0 + nu));
    (m, g)
}

/// E_m (Pa) of the soil with P-wave modulus M (Pa) at Poisson's ratio ν_m, the same c_P at
/// another ν_m: the inverse of [`soil_moduli`]'s M (P63).
pub fn youngs_from_p_wave_modulus(m: f64, nu: f64) -> f64 {
    m * (1.0 + nu) * (1.0 - 2.0 * nu) / (1.0 - nu)
}

/// The soil's compressional and shear wave speeds c_P = √(M/ρ_m), c_S = √(G/ρ_m), m/s (P63,
/// P64).
pub fn soil_speeds(e: f64, nu: f64, rho: f64) -> (f64, f64) {
    let (m, g) = soil_moduli(e, nu);
    ((m / rho).sqrt(), (g / rho).sqrt())
}

/// c_S/c_P of a soil with Poisson's ratio ν_m, from P63–P64: √((1 − 2ν)/(2(1 − ν))), √½ at
/// ν = 0 and 0 at ν = ½. The soils of one c_P in a box of ν_m have c_S between c_P times this
/// at the upper and at the lower bound.
pub fn shear_to_compressional(nu: f64) -> f64 {
    ((1.0 - 2.0 * nu) / (2.0 * (1.0 - nu))).max(0.0).sqrt()
}

/// E_m (Pa) and ν_m from the soil speeds (the inverse of P63–P64); `None` unless
/// 0 < c_S and ν_m > −1 and ν_m < 0.5 (i.e. 0 < G < 3M/4).
pub fn soil_from_speeds(cp: f64, cs: f64, rho: f64) -> Option<(f64, f64)> {
    let (m, g) = (rho * cp * cp, rho * cs * cs);
    if !(g > 0.0 && 4.0 * g < 3.0 * m && m.is_finite()) {
        return None;
    }
    let nu = (m - 2.0 * g) / (2.0 * (m - g));
    Some((2.0 * g * (1.0 + nu), nu))
}

/// ∂ln c_P/∂ν_m (P65): ½(−1/(1−ν) − 1/(1+ν) + 2/(1−2ν)).
pub fn dln_cp_dnu(nu: f64) -> f64 {
    0.5 * (-1.0 / (1.0 - nu) - 1.0 / (1.0 + nu) + 2.0 / (1.0 - 2.0 * nu))
}

/// ∂ln c_S/∂ν_m (P65): −½/(1+ν).
pub fn dln_cs_dnu(nu: f64) -> f64 {
    -0.5 / (1.0 + nu)
}

/// Poisson's ratio ν_m of a soil with c_S/c_P = r, the inverse of [`shear_to_compressional`]
/// (P63–P64): (1 − 2r²)/(2(1 − r²)); `None` outside 0 < r ≤ 1/√2 (ν_m ≥ 0, ν_m < ½).
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
/// inverse of [`speeds_of`] (P63–P64), ν_m from r and E_m from M = ρ_m c_P² at that ν_m. `None`
/// where r gives no Poisson's ratio in [0, ½).
pub fn soil_of(ln_cp: f64, r: f64, rho: f64) -> Option<(f64, f64)> {
    let nu = poisson_of_ratio(r)?;
    let m = rho * (2.0 * ln_cp).exp();
    Some((youngs_from_p_wave_modulus(m, nu), nu))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::inputs::MAX_SOIL_POISSON;

    #[test]
    fn speeds_round_trip_and_match_closed_forms() {
        // Loam of model §3.4-like values: E = 2e7 Pa, ν = 0.3, ρ = 1800.
        let (cp, cs) = soil_speeds(2e7, 0.3, 1800.0);
        // M = E(1−ν)/((1+ν)(1−2ν)) = 2e7·0.7/(1.3·0.4) = 2.6923e7; c_P = √(M/ρ) = 122.30.
        assert!((cp - (2e7 * 0.7 / (1.3 * 0.4) / 1800.0f64).sqrt()).abs() < 1e-9);
        assert!((cs - (2e7 / 2.6 / 1800.0f64).sqrt()).abs() < 1e-9);
        let (e, nu) = soil_from_speeds(cp, cs, 1800.0).unwrap();
        assert!((e / 2e7 - 1.0).abs() < 1e-12 && (nu - 0.3).abs() < 1e-12);
        // c_S ≥ c_P·√(3/4) has no soil (ν ≤ −1).
        assert!(soil_from_speeds(100.0, 90.0, 1800.0).is_none());
        // The same c_P at another ν_m (the moves to the faces r = r_min and r = r_max): at
        // ν = 0, E = M = 2.6923e7; at ν = 0.49, E = M·1.49·0.02/0.51.
        let m = 2e7 * 0.7 / (1.3 * 0.4);
        assert!((youngs_from_p_wave_modulus(m, 0.0) / m - 1.0).abs() < 1e-15);
        for nu in [0.0, 0.2, 0.49, 0.499] {
            let e = youngs_from_p_wave_modulus(m, nu);
            assert!(
                (soil_speeds(e, nu, 1800.0).0 / cp - 1.0).abs() < 1e-12,
                "{nu}"
            );
        }
    }

    /// The ratio of [`soil_speeds`]' c_S to c_P, whatever E_m and ρ_m; its closed-form ends.
    #[test]
    fn the_speed_ratio_is_that_of_the_soil_speeds() {
        for nu in [0.0, 0.1, 0.3, 0.45, 0.499] {
            for (e, rho) in [(2e7, 1800.0), (3e8, 2100.0)] {
                let (cp, cs) = soil_speeds(e, nu, rho);
                assert!(
                    (shear_to_compressional(nu) / (cs / cp) - 1.0).abs() < 1e-12,
                    "{nu}"
                );
            }
        }
        assert!((shear_to_compressional(0.0) - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-15);
        assert_eq!(shear_to_compressional(0.5), 0.0);
        // ν = 0.499: c_P/c_S = √(2·0.501/0.002) = √501.
        assert!((1.0 / shear_to_compressional(0.499) / 501f64.sqrt() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn speed_derivatives_match_central_differences() {
        for nu in [0.05, 0.25, 0.45, 0.49] {
            let h = 1e-6;
            let f = |v: f64| soil_speeds(1e7, v, 1900.0);
            let (p1, s1) = f(nu + h);
            let (p0, s0) = f(nu - h);
            let dp = (p1.ln() - p0.ln()) / (2.0 * h);
            let ds = (s1.ln() - s0.ln()) / (2.0 * h);
            assert!(
                (dp - dln_cp_dnu(nu)).abs() < 1e-6 * dp.abs().max(1.0),
                "{nu}"
            );
            assert!((ds - dln_cs_dnu(nu)).abs() < 1e-6, "{nu}");
        }
    }

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
}
