//! A pipe's speed from the field's posterior of its soil (P81): the forward model averaged over
//! u ~ N(m*, S*) and the contact ξ ~ U[0, 1], by a small product quadrature: the unscented
//! transform in u (5 points, κ = 1: exact for the mean and variance of a function quadratic in
//! u) times 3-point Gauss–Legendre in ξ. Fifteen curves of the pipe, each the very curve a fit
//! stores ([`crate::physics::curves::curve`] on the standard grid, its leak-band mean by
//! [`band_mean`]).

use crate::db::CurvePoint;
use crate::invert::uncertainty::{shear_to_compressional, soil_from_speeds, WithError};
use crate::invert::{Method, Param, Problem, SegmentData};
use crate::physics::curves::{band_mean, curve, LEAK_BAND_HZ, STANDARD_GRID_HZ};
use crate::physics::inputs::MAX_SOIL_POISSON;
use crate::physics::solver::{solve_from_guess_tol, Tolerance};
use crate::physics::{ContactMode, Model, System};
use crate::units::{db_to_np, hz_to_omega, np_to_db};
use num_complex::Complex64;

use super::model::Sym2;

/// κ of the unscented transform in two dimensions (n + κ = 3: the fourth moment of each
/// coordinate is right too).
const UT_KAPPA: f64 = 1.0;

/// Gauss–Legendre nodes on [0, 1] (3 points: exact for polynomials of degree 5 in ξ) and their
/// weights.
const XI_NODES: [(f64, f64); 3] = [
    (0.112_701_665_379_258_3, 5.0 / 18.0),
    (0.5, 8.0 / 18.0),
    (0.887_298_334_620_741_7, 5.0 / 18.0),
];

/// Fraction of the quadrature weight that may be lost to nodes without a root at a frequency
/// before that point (or the band mean) is left empty rather than averaged over the rest.
const MAX_LOST_WEIGHT: f64 = 0.25;

/// One quadrature node: its weight, (phase speed, attenuation in dB/m) per frequency of the
/// grid (None without a root), and its leak-band mean speed.
type Node = (f64, Vec<Option<(f64, f64)>>, Option<f64>);

/// What the quadrature gives for one pipe.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedPrediction {
    /// The curve on the standard grid: mean phase speed and attenuation with their standard
    /// deviations over the posterior (P81).
    pub curve: Vec<CurvePoint>,
    /// The leak-band speed's mean and standard deviation, m/s.
    pub band: Option<WithError>,
    /// ∂(band speed)/∂u at the posterior mean, averaged over ξ (m/s per ln unit), from the
    /// sigma points: how the speed error follows the soil's (for `plan`).
    pub band_gradient: Option<[f64; 2]>,
}

/// (E_m, ν_m) of u, with c_S/c_P held inside the range the search allows (ν_m in
/// [0, ν_max]) and c_P kept: a sigma point beyond that range stands for the nearest soil.
pub fn soil_of(u: [f64; 2], rho: f64) -> Option<(f64, f64)> {
    let cp = u[0].exp();
    let lo = shear_to_compressional(MAX_SOIL_POISSON);
    let hi = shear_to_compressional(0.0) * (1.0 - 1e-9);
    let cs = u[1].exp().clamp(cp * lo, cp * hi);
    soil_from_speeds(cp, cs, rho).map(|(e, nu)| (e, nu.clamp(0.0, MAX_SOIL_POISSON)))
}

/// The speed of the pipe `data` (measurements ignored) under the run's `model` and
/// `contact_mode`, averaged over u ~ N(`mean`, `cov`) and ξ ~ U[0, 1] (P81).
pub fn predict_speed(
    data: &SegmentData,
    model: Model,
    contact_mode: ContactMode,
    mean: [f64; 2],
    cov: Sym2,
) -> SpeedPrediction {
    let problem = Problem::new(data, Method::Default, model, contact_mode, &[]);
    let spread = (2.0 + UT_KAPPA).sqrt();
    let l = cov
        .cholesky()
        .unwrap_or([cov.pp.max(0.0).sqrt(), 0.0, cov.ss.max(0.0).sqrt()]);
    // Sigma points: the mean, then ± along each column of L.
    let cols = [[l[0], l[1]], [0.0, l[2]]];
    let mut points = vec![(mean, UT_KAPPA / (2.0 + UT_KAPPA))];
    for c in cols {
        for sign in [1.0, -1.0] {
            points.push((
                [
                    mean[0] + sign * spread * c[0],
                    mean[1] + sign * spread * c[1],
                ],
                0.5 / (2.0 + UT_KAPPA),
            ));
        }
    }
    let nf = STANDARD_GRID_HZ.len();
    let system_of = |u: [f64; 2], xi: f64| {
        soil_of(u, data.soil_density).and_then(|(e, nu)| {
            let x: Vec<f64> = problem
                .specs
                .iter()
                .map(|s| match s.param {
                    Param::SoilModulus => s.coordinate(e),
                    Param::SoilPoisson => nu,
                    _ => xi,
                })
                .collect();
            problem.system_at(&x)
        })
    };
    let full_curve = |sys: &System| -> Vec<Option<Complex64>> {
        curve(sys, &STANDARD_GRID_HZ)
            .into_iter()
            .map(|p| {
                (p.status.is_ok() && p.phase_speed.is_finite()).then(|| {
                    Complex64::new(
                        hz_to_omega(p.frequency_hz) / p.phase_speed,
                        -db_to_np(p.attenuation_db),
                    )
                })
            })
            .collect()
    };
    // The reference: the curve at the posterior mean and the middle contact, by continuation
    // (as a fit's stored curve); every other node starts each frequency's root from it (as the
    // fit's curve errors do), and falls back to its own continuation where that fails.
    let reference = system_of(mean, 0.5).map(|s| full_curve(&s));
    // Per node: weight, wavenumber per frequency, band mean.
    let mut nodes: Vec<Node> = Vec::new();
    // Band mean per sigma point, averaged over ξ (for the gradient).
    let mut band_by_point = vec![Some(0.0); points.len()];
    for (pi, (u, wu)) in points.iter().enumerate() {
        for &(xi, wx) in &XI_NODES {
            let ks: Vec<Option<Complex64>> = match system_of(*u, xi) {
                Some(sys) => {
                    let from_guess: Option<Vec<Option<Complex64>>> = reference.as_ref().map(|r| {
                        r.iter()
                            .zip(STANDARD_GRID_HZ)
                            .map(|(g, f)| {
                                g.and_then(|g| {
                                    solve_from_guess_tol(&sys, hz_to_omega(f), g, Tolerance::FAST)
                                        .ok()
                                        .map(|root| root.k1)
                                })
                            })
                            .collect()
                    });
                    match from_guess {
                        Some(k) if k.iter().all(Option::is_some) => k,
                        _ => full_curve(&sys),
                    }
                }
                None => vec![None; nf],
            };
            let pts: Vec<Option<(f64, f64)>> = ks
                .iter()
                .zip(STANDARD_GRID_HZ)
                .map(|(k, f)| {
                    k.filter(|k| k.re > 0.0)
                        .map(|k| (hz_to_omega(f) / k.re, np_to_db(-k.im)))
                })
                .collect();
            let speeds: Vec<(f64, Option<f64>)> = STANDARD_GRID_HZ
                .iter()
                .zip(&pts)
                .map(|(&f, p)| (f, p.map(|v| v.0)))
                .collect();
            let band = band_mean(&speeds, LEAK_BAND_HZ);
            band_by_point[pi] = match (band_by_point[pi], band) {
                (Some(acc), Some(b)) => Some(acc + wx * b),
                _ => None,
            };
            nodes.push((wu * wx, pts, band));
        }
    }
    let moments = |vals: &mut dyn Iterator<Item = (f64, Option<f64>)>| -> Option<WithError> {
        let v: Vec<(f64, f64)> = vals.filter_map(|(w, x)| x.map(|x| (w, x))).collect();
        let wsum: f64 = v.iter().map(|p| p.0).sum();
        if wsum < 1.0 - MAX_LOST_WEIGHT {
            return None;
        }
        let m = v.iter().map(|(w, x)| w * x).sum::<f64>() / wsum;
        let var = v.iter().map(|(w, x)| w * (x - m).powi(2)).sum::<f64>() / wsum;
        Some(WithError {
            value: m,
            std: var.max(0.0).sqrt(),
        })
    };
    let curve_pts = STANDARD_GRID_HZ
        .iter()
        .enumerate()
        .map(|(i, &f)| {
            let c = moments(&mut nodes.iter().map(|n| (n.0, n.1[i].map(|p| p.0))));
            let a = moments(&mut nodes.iter().map(|n| (n.0, n.1[i].map(|p| p.1))));
            CurvePoint {
                frequency_hz: f,
                phase_speed_m_per_s: c.map(|c| c.value),
                attenuation_db_per_m: a.map(|a| a.value),
                phase_speed_std_m_per_s: c.map(|c| c.std),
                attenuation_std_db_per_m: a.map(|a| a.std),
            }
        })
        .collect();
    let band = moments(&mut nodes.iter().map(|n| (n.0, n.2)));
    // Gradient: (b(+j) − b(−j)) / (2·spread) = g·L e_j, so g = L⁻ᵀ d.
    let band_gradient = match band_by_point[..] {
        [_, Some(p1), Some(m1), Some(p2), Some(m2)] if l[0] > 0.0 && l[2] > 0.0 => {
            let d = [(p1 - m1) / (2.0 * spread), (p2 - m2) / (2.0 * spread)];
            // Lᵀ g = d with L = [[l0, 0], [l1, l2]]: g1 = d1/l2, g0 = (d0 − l1 g1)/l0.
            let g1 = d[1] / l[2];
            Some([(d[0] - l[1] * g1) / l[0], g1])
        }
        _ => None,
    };
    SpeedPrediction {
        curve: curve_pts,
        band,
        band_gradient,
    }
}
