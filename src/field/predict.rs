//! A pipe's speed from the field's posterior of its soil (P81): the forward model averaged over
//! u ~ N(m*, S*) and the contact ξ ~ U[0, 1] by the unscented transform in (u, ξ) with κ = 0:
//! six sigma points at ±√3 standard deviations along the principal axes, each of weight 1/6
//! (exact for the mean and variance of a function quadratic in (u, ξ)). Along ξ, whose uniform
//! prior has σ = 1/√12, they fall exactly on its ends 0 and 1. The curve at the centre (the
//! posterior mean, ξ = ½) is computed by continuation on the standard grid, as a fit's stored
//! curve ([`crate::physics::curves::curve`]; its leak-band mean by [`band_mean`]) but with the
//! inversion's shorter ramp and stopping rule ([`PREDICTION_CONTINUATION`]), and starts every
//! other point's roots: seven curves of the pipe in all.

use crate::db::CurvePoint;
use crate::invert::problem::INVERSION_RAMP_POINTS;
use crate::invert::uncertainty::WithError;
use crate::invert::{Method, Param, Problem, SegmentData};
use crate::physics::curves::{band_mean, carried_band, LEAK_BAND_HZ, STANDARD_GRID_HZ};
use crate::physics::inputs::MAX_SOIL_POISSON;
use crate::physics::soil::{shear_to_compressional, soil_from_speeds};
use crate::physics::solver::{solve_from_guess_tol, RootMethod, Tolerance};
use crate::physics::{solve_curve, ContactMode, Continuation, Model, System};
use crate::units::{hz_to_omega, np_to_db};
use num_complex::Complex64;

use super::model::Sym2;

/// Dimensions of the unscented transform: ln c_P, ln c_S and ξ.
const UT_DIM: f64 = 3.0;

/// The continuation of a prediction's curves: the frequency continuation of model §5.4 (P41,
/// P42) with the inversion's 8-point ramp below the lowest frequency instead of the
/// reference's 29, and Newton's iteration with the analytic dF/dk₁ (model §5.3 allows it if it
/// passes the same tests) stopped at |dx| ≤ 1e-10|x| or |F| ≤ 1e-12, instead of Muller's (P40)
/// at the reference's step tolerance. Newton's step costs one evaluation of F and dF/dk₁ where
/// Muller's start costs three of F: the field update takes about 12 % less time.
///
/// Along the path the roots agree with the reference continuation to 1e-9 relative (tested
/// below on plastic and metal pipes across the soils a field predicts) for as long as the
/// wave's damping per radian −Im k₁/Re k₁ stays below [`STRONG_DAMPING`]. Past it the s = 1
/// root crowds with the roots of the other sheets of q_P and q_S (P44), and which one a
/// continuation step lands on depends on the step's history, for the reference as for this:
/// the reference itself is seen to jump from a wave at 623 m/s damped by 0.27 per radian to
/// the shear-grazing wave at 403 m/s in one step. Those points are still roots of F (P32).
pub const PREDICTION_CONTINUATION: Continuation = Continuation {
    ramp_points: INVERSION_RAMP_POINTS,
    tolerance: Tolerance {
        step_rtol: 1e-10,
        residual_stop: 1e-12,
        method: RootMethod::Newton,
    },
};

/// Damping per radian −Im k₁/Re k₁ beyond which a continuation's root depends on its step
/// history ([`PREDICTION_CONTINUATION`]): the wave's amplitude falls by e^(−2π·0.25) ≈ 0.2
/// over one wavelength, so no correlator measures it.
pub const STRONG_DAMPING: f64 = 0.25;

/// Standard deviation of ξ under its uniform prior on [0, 1]: 1/√12.
const XI_SD: f64 = 0.288_675_134_594_812_9;

/// Fraction of the quadrature weight that may be lost to nodes without a root at a frequency
/// before that point (or the band mean) is left empty rather than averaged over the rest.
const MAX_LOST_WEIGHT: f64 = 0.25;

/// Frequencies at which the six sigma points are solved (field algorithm 2; the centre is
/// solved on the whole standard grid): six of the grid's, spanning the leak band. The band mean
/// of each sigma point is taken over them, corrected by the centre's difference between its
/// whole-grid and six-point band means; elsewhere on the grid the curve's shift and spread
/// relative to the centre are interpolated in ln f (held at the band's ends outside it).
pub const SIGMA_FREQUENCIES_HZ: [f64; 6] = [100.0, 200.0, 350.0, 500.0, 650.0, 800.0];

/// The available points (ln f, value) of `v` (values at [`SIGMA_FREQUENCIES_HZ`], None where
/// missing), taken once per curve for [`interpolate_ln_f`].
fn ln_f_points(v: &[Option<f64>]) -> Vec<(f64, f64)> {
    SIGMA_FREQUENCIES_HZ
        .iter()
        .zip(v)
        .filter_map(|(&x, y)| y.map(|y| (x.ln(), y)))
        .collect()
}

/// Interpolate the points `pts` of [`ln_f_points`] linearly in ln f at `f`, held constant
/// beyond the first and last available.
fn interpolate_ln_f(pts: &[(f64, f64)], f: f64) -> Option<f64> {
    let (first, last) = (pts.first()?, pts.last()?);
    let x = f.ln();
    if x <= first.0 {
        return Some(first.1);
    }
    if x >= last.0 {
        return Some(last.1);
    }
    pts.windows(2).find(|w| x <= w[1].0).map(|w| {
        let t = (x - w[0].0) / (w[1].0 - w[0].0);
        w[0].1 + t * (w[1].1 - w[0].1)
    })
}

/// (Phase speed, attenuation in dB/m) per frequency of the grid, None without a root.
type GridCurve = Vec<Option<(f64, f64)>>;

/// One quadrature node: its weight, its curve on the grid, and its leak-band mean speed.
type Node = (f64, GridCurve, Option<f64>);

/// What the quadrature gives for one pipe.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedPrediction {
    /// The curve on the standard grid: mean phase speed and attenuation with their standard
    /// deviations over the posterior (P81).
    pub curve: Vec<CurvePoint>,
    /// The leak-band speed's mean and standard deviation, m/s.
    pub band: Option<WithError>,
    /// The band `band` is the mean over, Hz: the leak band, or its part below the frequency
    /// where the pipe's wave ends for most of the posterior (`propagating_band`).
    pub band_hz: (f64, f64),
    /// ∂(band speed)/∂u at the posterior mean, averaged over ξ (m/s per ln unit), from the
    /// sigma points: how the speed error follows the soil's (for `plan`).
    pub band_gradient: Option<[f64; 2]>,
}

impl SpeedPrediction {
    /// The leave-one-out check of a measured segment (P82) against its own fit's leak-band
    /// speed `fitted` = (ĉ_s, σ_s): this prediction's band mean and error and
    /// z = (ĉ_−s − ĉ_s)/√(σ²_−s + σ²_s). `None` where the prediction's band was cut below the
    /// leak band (a fit's leak-band speed is always the whole band's mean, so the two would be
    /// different quantities), where it has no band speed, or where z is not finite.
    pub fn leave_one_out(&self, fitted: (f64, f64)) -> Option<(WithError, f64)> {
        let b = self.band.filter(|_| self.band_hz == LEAK_BAND_HZ)?;
        let (c, s) = fitted;
        let z = (b.value - c) / (b.std * b.std + s * s).sqrt();
        z.is_finite().then_some((b, z))
    }
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

/// The roots k₁ of `sys` on the standard grid by [`PREDICTION_CONTINUATION`] (None where the
/// solve failed or the phase speed is not finite).
pub fn continued_roots(sys: &System) -> Vec<Option<Complex64>> {
    let omegas = STANDARD_GRID_HZ.map(hz_to_omega);
    solve_curve(sys, &omegas, PREDICTION_CONTINUATION)
        .into_iter()
        .zip(omegas)
        .map(|(r, w)| {
            r.ok()
                .map(|root| root.k1)
                .filter(|k| (w / k.re).is_finite())
        })
        .collect()
}

/// (phase speed, attenuation in dB/m) per frequency of the standard grid from the roots k₁.
fn speeds_of(ks: &[Option<Complex64>]) -> Vec<Option<(f64, f64)>> {
    ks.iter()
        .zip(STANDARD_GRID_HZ)
        .map(|(k, f)| {
            k.filter(|k| k.re > 0.0)
                .map(|k| (hz_to_omega(f) / k.re, np_to_db(-k.im)))
        })
        .collect()
}

/// A sigma point's curve with every frequency where its forward solve found no root replaced
/// by its mirror point's, reflected through the centre: 2 f(m) − f(m − δ), exact for a
/// function linear along that axis, so the transform keeps its mean and its variance to first
/// order (P81) instead of losing the node's weight. Where the centre has no root either, the
/// mirror's value itself stands in (a function even along that axis); where the reflection
/// would not be a positive speed, likewise.
fn mirrored(
    own: &[Option<(f64, f64)>],
    mirror: &[Option<(f64, f64)>],
    centre: &[Option<(f64, f64)>],
) -> Vec<Option<(f64, f64)>> {
    own.iter()
        .zip(mirror)
        .zip(centre)
        .map(|((o, m), c)| {
            o.or_else(|| {
                let m = (*m)?;
                Some(match c {
                    Some(c) if 2.0 * c.0 - m.0 > 0.0 => (2.0 * c.0 - m.0, 2.0 * c.1 - m.1),
                    _ => m,
                })
            })
        })
        .collect()
}

/// The speed of the pipe `data` (measurements ignored) under the run's `model` and
/// `contact_mode`, averaged over u ~ N(`mean`, `cov`) and ξ ~ U[0, 1] (P81). The soil's part
/// of the stated errors is widened for θ estimated from few members (P92): by `widening` per
/// axis of u, taken along the band speed's gradient g as q² = gᵀ D S D g / gᵀ S g, D =
/// diag(`widening`). The estimates themselves are the plug-in posterior's: the t distribution
/// P92 stands for is centred where the Gaussian is.
pub fn predict_speed(
    data: &SegmentData,
    model: Model,
    contact_mode: ContactMode,
    mean: [f64; 2],
    cov: Sym2,
    widening: [f64; 2],
) -> SpeedPrediction {
    let problem = Problem::new(data, Method::Default, model, contact_mode, &[]);
    let spread = UT_DIM.sqrt();
    let l = cov
        .cholesky()
        .unwrap_or([cov.pp.max(0.0).sqrt(), 0.0, cov.ss.max(0.0).sqrt()]);
    // Sigma points (u, ξ, weight): ± along each column of L in u at ξ = ½, and ξ at its ends.
    let cols = [[l[0], l[1]], [0.0, l[2]]];
    let w = 1.0 / (2.0 * UT_DIM);
    let mut points: Vec<([f64; 2], f64, f64)> = Vec::new();
    for c in cols {
        for sign in [1.0, -1.0] {
            points.push((
                [
                    mean[0] + sign * spread * c[0],
                    mean[1] + sign * spread * c[1],
                ],
                0.5,
                w,
            ));
        }
    }
    for sign in [1.0, -1.0] {
        points.push((mean, (0.5 + sign * spread * XI_SD).clamp(0.0, 1.0), w));
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
    // The reference: the curve at the posterior mean and the middle contact, by continuation
    // (as a fit's stored curve); every other node starts each frequency's root from it (as the
    // fit's curve errors do), and falls back to its own continuation where that fails.
    let reference = system_of(mean, 0.5).map(|s| continued_roots(&s));
    // With the centre's curve the sigma points are solved at the six frequencies only.
    let at = |f: f64| reference.is_none() || SIGMA_FREQUENCIES_HZ.contains(&f);
    let mut solved: Vec<Vec<Option<(f64, f64)>>> = Vec::new();
    for &(u, xi, _) in &points {
        let ks: Vec<Option<Complex64>> = match system_of(u, xi) {
            Some(sys) => {
                let from_guess: Option<Vec<Option<Complex64>>> = reference.as_ref().map(|r| {
                    r.iter()
                        .zip(STANDARD_GRID_HZ)
                        .map(|(g, f)| {
                            g.filter(|_| at(f)).and_then(|g| {
                                solve_from_guess_tol(&sys, hz_to_omega(f), g, Tolerance::FAST)
                                    .ok()
                                    .map(|root| root.k1)
                            })
                        })
                        .collect()
                });
                let complete = |k: &[Option<Complex64>]| {
                    k.iter()
                        .zip(STANDARD_GRID_HZ)
                        .all(|(k, f)| k.is_some() || !at(f))
                };
                match from_guess {
                    Some(k) if complete(&k) => k,
                    _ => continued_roots(&sys),
                }
            }
            None => vec![None; nf],
        };
        let mut pts = speeds_of(&ks);
        for (p, f) in pts.iter_mut().zip(STANDARD_GRID_HZ) {
            if !at(f) {
                *p = None;
            }
        }
        solved.push(pts);
    }
    let centre: Vec<Option<(f64, f64)>> = reference
        .as_ref()
        .map_or_else(|| vec![None; nf], |r| speeds_of(r));
    // A curve's band mean over the frequencies the sigma points are solved at.
    let band_at = |pts: &[Option<(f64, f64)>], band: (f64, f64)| {
        let speeds: Vec<(f64, Option<f64>)> = STANDARD_GRID_HZ
            .iter()
            .zip(pts)
            .filter(|(&f, _)| at(f))
            .map(|(&f, p)| (f, p.map(|v| v.0)))
            .collect();
        band_mean(&speeds, band)
    };
    let mirrored_nodes: Vec<(f64, GridCurve)> = points
        .iter()
        .enumerate()
        .map(|(j, &(_, _, weight))| (weight, mirrored(&solved[j], &solved[j ^ 1], &centre)))
        .collect();
    let band_hz = propagating_band(&mirrored_nodes);
    let nodes: Vec<Node> = mirrored_nodes
        .into_iter()
        .map(|(weight, pts)| {
            let band = band_at(&pts, band_hz);
            (weight, pts, band)
        })
        .collect();
    // The centre's whole-grid band mean less its band mean at the sigma frequencies: the
    // quadrature's discretisation offset, the same for every node to first order.
    let whole: Vec<(f64, Option<f64>)> = STANDARD_GRID_HZ
        .iter()
        .zip(&centre)
        .map(|(&f, p)| (f, p.map(|v| v.0)))
        .collect();
    let offset = match (band_mean(&whole, band_hz), band_at(&centre, band_hz)) {
        (Some(a), Some(b)) => a - b,
        _ => 0.0,
    };
    // Gradient: (b(+j) − b(−j)) / (2·spread) = g·L e_j, so g = L⁻ᵀ d.
    let band_of = |i: usize| nodes.get(i).and_then(|n| n.2);
    let band_gradient = match (band_of(0), band_of(1), band_of(2), band_of(3)) {
        (Some(p1), Some(m1), Some(p2), Some(m2)) if l[0] > 0.0 && l[2] > 0.0 => {
            let d = [(p1 - m1) / (2.0 * spread), (p2 - m2) / (2.0 * spread)];
            // Lᵀ g = d with L = [[l0, 0], [l1, l2]]: g1 = d1/l2, g0 = (d0 − l1 g1)/l0.
            let g1 = d[1] / l[2];
            Some([(d[0] - l[1] * g1) / l[0], g1])
        }
        _ => None,
    };
    // P92 along g; without a gradient, the wider axis's.
    let q2 = band_gradient
        .and_then(|g| {
            let plain = cov.quad(g);
            let wide = cov.scale_axes(widening).quad(g);
            (plain > 0.0 && wide.is_finite()).then(|| wide / plain)
        })
        .unwrap_or_else(|| widening[0].max(widening[1]).powi(2))
        .max(1.0);
    // The soil's nodes (the first four) carry q² of their squared deviation, the contact's 1.
    let var_factor: Vec<f64> = (0..nodes.len())
        .map(|j| if j < 4 { q2 } else { 1.0 })
        .collect();
    let moments = |vals: &mut dyn Iterator<Item = (f64, Option<f64>)>| -> Option<WithError> {
        let v: Vec<(f64, f64, f64)> = vals
            .zip(&var_factor)
            .filter_map(|((w, x), k)| x.map(|x| (w, x, *k)))
            .collect();
        let wsum: f64 = v.iter().map(|p| p.0).sum();
        if wsum < 1.0 - MAX_LOST_WEIGHT {
            return None;
        }
        let m = v.iter().map(|(w, x, _)| w * x).sum::<f64>() / wsum;
        let var = v
            .iter()
            .map(|(w, x, k)| w * k * (x - m).powi(2))
            .sum::<f64>()
            / wsum;
        Some(WithError {
            value: m,
            std: var.max(0.0).sqrt(),
        })
    };
    let solved_moments = |i: usize| {
        (
            moments(&mut nodes.iter().map(|n| (n.0, n.1[i].map(|p| p.0)))),
            moments(&mut nodes.iter().map(|n| (n.0, n.1[i].map(|p| p.1)))),
        )
    };
    // Relative shift and spread of the mean against the centre at the sigma frequencies.
    let relative: Vec<[Option<f64>; 4]> = SIGMA_FREQUENCIES_HZ
        .iter()
        .map(|&f| {
            let i = STANDARD_GRID_HZ.iter().position(|&g| g == f);
            let (c, a) = i.map_or((None, None), solved_moments);
            let mid = i.and_then(|i| centre[i]);
            let rel = |m: Option<WithError>, x: Option<f64>| match (m, x) {
                (Some(m), Some(x)) if x.abs() > 0.0 => [Some(m.value / x - 1.0), Some(m.std / x)],
                _ => [None, None],
            };
            let [cs, cd] = rel(c, mid.map(|p| p.0));
            let [as_, ad] = rel(a, mid.map(|p| p.1));
            [cs, cd, as_, ad]
        })
        .collect();
    let columns: Vec<Vec<(f64, f64)>> = (0..4)
        .map(|k| ln_f_points(&relative.iter().map(|r| r[k]).collect::<Vec<_>>()))
        .collect();
    let curve_pts = STANDARD_GRID_HZ
        .iter()
        .enumerate()
        .map(|(i, &f)| {
            let (c, a) = if at(f) {
                solved_moments(i)
            } else {
                let scaled = |x: Option<f64>, shift: usize, spread: usize| {
                    let x = x?;
                    Some(WithError {
                        value: x * (1.0 + interpolate_ln_f(&columns[shift], f)?),
                        std: (x * interpolate_ln_f(&columns[spread], f)?).abs(),
                    })
                };
                (
                    scaled(centre[i].map(|p| p.0), 0, 1),
                    scaled(centre[i].map(|p| p.1), 2, 3),
                )
            };
            CurvePoint {
                frequency_hz: f,
                phase_speed_m_per_s: c.map(|c| c.value),
                attenuation_db_per_m: a.map(|a| a.value),
                phase_speed_std_m_per_s: c.map(|c| c.std),
                attenuation_std_db_per_m: a.map(|a| a.std),
                model_phase_speed_m_per_s: None,
                model_attenuation_db_per_m: None,
            }
        })
        .collect();
    let band = moments(&mut nodes.iter().map(|n| (n.0, n.2))).map(|b| WithError {
        value: b.value + offset,
        std: b.std,
    });
    SpeedPrediction {
        curve: curve_pts,
        band,
        band_hz,
        band_gradient,
    }
}

/// The band a prediction's speed is the mean over (P81): [`carried_band`] of the leak band with
/// the wave counted as carried at a sigma frequency where the nodes with a root hold at least
/// 1 − [`MAX_LOST_WEIGHT`] of the weight. Below that the wave ends for most of the posterior (a
/// plastic pipe in stiff, nearly incompressible ground at a middle contact is damped by more
/// than [`STRONG_DAMPING`] per radian and its root is lost).
fn propagating_band(nodes: &[(f64, GridCurve)]) -> (f64, f64) {
    let held = |f: f64| {
        STANDARD_GRID_HZ
            .iter()
            .position(|&g| g == f)
            .map_or(0.0, |i| {
                nodes
                    .iter()
                    .filter(|n| n.1[i].is_some())
                    .map(|n| n.0)
                    .sum::<f64>()
            })
    };
    let carried: Vec<(f64, bool)> = SIGMA_FREQUENCIES_HZ
        .iter()
        .map(|&f| (f, held(f) >= 1.0 - MAX_LOST_WEIGHT))
        .collect();
    carried_band(&carried, LEAK_BAND_HZ)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{Fluid, Material, Pipe, Soil};

    /// A PVC pipe in ordinary soft soil (c_P 250 m/s, c_S 100 m/s, a posterior 10 % wide): its
    /// wave crosses the whole leak band.
    fn pvc_in_soft_soil() -> SpeedPrediction {
        pvc_in_soft_soil_widened(1.0)
    }

    /// [`pvc_in_soft_soil`] with its soil's error widened by `q` on both axes (P92).
    fn pvc_in_soft_soil_widened(q: f64) -> SpeedPrediction {
        let pvc = unmeasured(Material::Pvc, 0.110, 0.0053, 1900.0);
        let soft = [(250.0f64).ln(), (100.0f64).ln()];
        let cov = Sym2::new(0.01, 0.005, 0.01);
        predict_speed(
            &pvc,
            Model::default(),
            ContactMode::default(),
            soft,
            cov,
            [q, q],
        )
    }

    /// An HDPE pipe in stiff, nearly incompressible ground (c_P ≈ 1,300 m/s, c_S ≈ 300 m/s, a
    /// posterior that knows c_S to 1 % and c_P to 25 %).
    fn hdpe_in_stiff_ground() -> SpeedPrediction {
        let hdpe = unmeasured(Material::Hdpe, 0.250, 0.0148, 2065.0);
        let mean = [7.164, 5.7158];
        let cov = Sym2::new(0.0604, -0.000405, 7.6e-5);
        predict_speed(
            &hdpe,
            Model::default(),
            ContactMode::default(),
            mean,
            cov,
            [1.0; 2],
        )
    }

    /// A pipe of `material` (outside diameter and wall in m) in soil of density `soil_density`,
    /// without measurements: what the field predicts for.
    fn unmeasured(material: Material, od: f64, wall: f64, soil_density: f64) -> SegmentData {
        SegmentData {
            fluid: Fluid::water(),
            pipe: Pipe::from_outside_diameter(material.typical(), od, wall).unwrap(),
            soil_density,
            material: Some(material),
            measurements: Vec::new(),
        }
    }

    /// The prediction's continuation finds the reference continuation's roots (model §5.4's
    /// 29-point ramp, Muller to the reference tolerance) to 1e-9 relative at every frequency of
    /// the standard grid, and fails where it fails, up to the first frequency where the
    /// reference root's damping reaches [`STRONG_DAMPING`]: on plastic and metal pipes, over
    /// soils from soft clay to dense gravel (c_S 60–400 m/s, c_S/c_P 0.2–0.6, both sides of the
    /// pipes' phase speeds) and at both ends of the contact prior. Beyond that frequency it
    /// finds another root on fewer than 1 % of the grid's points (15 of 5,760 when written),
    /// and each is a root of F (P32): Muller's iteration to the reference tolerance started
    /// there moves it by less than 1e-9 relative.
    #[test]
    fn prediction_continuation_finds_the_reference_roots() {
        let omegas = STANDARD_GRID_HZ.map(hz_to_omega);
        let pipes = [
            (Material::Pvc, 0.110, 0.0053),
            (Material::Mdpe, 0.090, 0.0082),
            (Material::Pvc, 0.250, 0.0119),
            (Material::CastIron, 0.122, 0.011),
            (Material::DuctileIron, 0.326, 0.0072),
        ];
        let (mut compared, mut beyond) = (0, 0);
        for (material, od, wall) in pipes {
            let pipe = Pipe::from_outside_diameter(material.typical(), od, wall).unwrap();
            for cs in [60.0f64, 120.0, 250.0, 400.0] {
                for ratio in [0.2, 0.4, 0.6] {
                    for xi in [0.0, 0.5, 1.0] {
                        let rho = 1900.0;
                        let (e, nu) = soil_of([(cs / ratio).ln(), cs.ln()], rho).unwrap();
                        let soil = Soil::new_unbounded(e, nu, rho, 0.0).unwrap();
                        let sys = System::new(
                            Fluid::water(),
                            pipe,
                            soil,
                            xi,
                            Model::default(),
                            ContactMode::default(),
                        )
                        .unwrap();
                        let reference = solve_curve(&sys, &omegas, Continuation::default());
                        let mut damped = false;
                        for ((r, k), w) in reference.iter().zip(continued_roots(&sys)).zip(omegas) {
                            damped |= r
                                .as_ref()
                                .is_ok_and(|r| -r.k1.im > STRONG_DAMPING * r.k1.re);
                            if damped {
                                // Past strong damping: the same root, or another root of F.
                                let same = match (r, k) {
                                    (Ok(r), Some(k)) => (k - r.k1).norm() < 1e-9 * r.k1.norm(),
                                    (r, k) => r.is_err() && k.is_none(),
                                };
                                if !same {
                                    beyond += 1;
                                }
                                if let (false, Some(k)) = (same, k) {
                                    let polished =
                                        solve_from_guess_tol(&sys, w, k, Tolerance::REFERENCE)
                                            .unwrap()
                                            .k1;
                                    let d = (polished - k).norm() / k.norm();
                                    assert!(d < 1e-9, "{material:?} c_S {cs}: {d}");
                                }
                                continue;
                            }
                            match (r, k) {
                                (Ok(r), Some(k)) => {
                                    compared += 1;
                                    let d = (k - r.k1).norm() / r.k1.norm();
                                    assert!(d < 1e-9, "{material:?} c_S {cs} ratio {ratio}: {d}");
                                }
                                (Err(_), None) => {}
                                (r, k) => {
                                    panic!("{material:?} c_S {cs} ratio {ratio}: {r:?} {k:?}")
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(compared > 5 * 36 * 20, "{compared}");
        // Another root on fewer than 1 % of the points.
        assert!(beyond < 5 * 36 * 32 / 100, "{beyond}");
    }

    /// A plastic pipe in stiff, nearly incompressible ground (c_P ≈ 1,300 m/s, c_S ≈ 300 m/s, a
    /// posterior that knows c_S to 1 % and c_P to 25 %): at the middle contact its wave is
    /// damped beyond 0.25 per radian and ends inside the leak band, at either end of the contact
    /// prior it crosses the whole band. The speed is the mean below the wave's end, with the
    /// contact's spread in its error; a PVC pipe in ordinary soil keeps the whole leak band.
    #[test]
    fn a_wave_that_ends_inside_the_band_is_averaged_below_its_end() {
        let p = hdpe_in_stiff_ground();
        assert!(
            p.band_hz.0 == 100.0 && p.band_hz.1 < 800.0,
            "{:?}",
            p.band_hz
        );
        let b = p.band.expect("a speed over the cut band");
        assert!((420.0..560.0).contains(&b.value), "{b:?}");
        // The contact's ends differ by over 100 m/s on this band: the error carries it.
        assert!(b.std > 30.0, "{b:?}");
        // The curve keeps the frequencies where the wave is found, none above its end.
        let at = |f: f64| {
            p.curve
                .iter()
                .find(|c| c.frequency_hz == f)
                .and_then(|c| c.phase_speed_m_per_s)
        };
        assert!(at(100.0).is_some() && at(p.band_hz.1).is_some());
        assert!(at(800.0).is_none());

        let p = pvc_in_soft_soil();
        assert_eq!(p.band_hz, LEAK_BAND_HZ);
        assert!(p.band.is_some());
    }

    /// A measured segment's leave-one-out z (P82) compares like with like: on a whole-band
    /// prediction it is (ĉ_−s − ĉ_s)/√(σ²_−s + σ²_s); on a band cut below the leak band (whose
    /// mean is another quantity than the fit's leak-band speed) there is none.
    #[test]
    fn the_leave_one_out_check_skips_a_cut_band() {
        let whole = pvc_in_soft_soil();
        let b = whole.band.expect("a whole-band speed");
        let fitted = (b.value + 10.0, 5.0);
        let (own, z) = whole.leave_one_out(fitted).expect("a z on the whole band");
        assert_eq!(own, b);
        let expected = -10.0 / (b.std * b.std + 25.0).sqrt();
        assert!((z - expected).abs() < 1e-12, "{z} against {expected}");

        let cut = hdpe_in_stiff_ground();
        let c = cut.band.expect("a speed over the cut band");
        assert!(cut.band_hz.1 < LEAK_BAND_HZ.1);
        assert!(cut.leave_one_out((c.value, c.std)).is_none());
    }

    /// A sigma point without a root takes its mirror's value reflected through the centre
    /// (the centre's missing too: the mirror's own value); a node with a root keeps it.
    #[test]
    fn a_failed_sigma_point_is_its_mirror_reflected() {
        let own = [None, None, Some((290.0, 0.2))];
        let mirror = [Some((300.0, 0.10)), Some((300.0, 0.10)), Some((330.0, 0.3))];
        let centre = [Some((310.0, 0.12)), None, Some((310.0, 0.25))];
        let m = mirrored(&own, &mirror, &centre);
        let (c, a) = m[0].unwrap();
        assert!(
            (c - 320.0).abs() < 1e-12 && (a - 0.14).abs() < 1e-12,
            "{m:?}"
        );
        assert_eq!(m[1], Some((300.0, 0.10)));
        assert_eq!(m[2], Some((290.0, 0.2)));
    }

    /// P92 in the quadrature: a widening moves no speed, and widens only the soil's share of
    /// the variance (q² of it), not the contact's: var(q) = q² A + C with C > 0.
    #[test]
    fn a_widening_widens_the_soils_share_of_the_error_only() {
        let at = pvc_in_soft_soil_widened;
        let (p1, p2, p3) = (at(1.0), at(2.0), at(1.3));
        let (b1, b2, b3) = (p1.band.unwrap(), p2.band.unwrap(), p3.band.unwrap());
        assert_eq!(b1.value, b3.value);
        for (a, b) in p1.curve.iter().zip(&p3.curve) {
            assert_eq!(a.phase_speed_m_per_s, b.phase_speed_m_per_s);
        }
        let (v1, v2, v3) = (b1.std.powi(2), b2.std.powi(2), b3.std.powi(2));
        let soil = (v2 - v1) / 3.0;
        let contact = v1 - soil;
        assert!(
            soil > 0.0 && contact > 0.0,
            "soil {soil}, contact {contact}"
        );
        let expected = 1.69 * soil + contact;
        assert!((v3 - expected).abs() < 1e-9 * v3, "{v3} vs {expected}");
        assert!(v3 < 1.69 * v1 && v3 > v1, "{v3} vs {v1}");
    }

    /// The curve's relative shift and spread off the sigma frequencies: linear in ln f between
    /// them (at √(100·200) Hz halfway between their values), held beyond the band's ends.
    #[test]
    fn relative_spread_is_interpolated_in_ln_f() {
        let v = [
            Some(0.02),
            Some(0.04),
            None,
            Some(0.05),
            Some(0.05),
            Some(0.06),
        ];
        let pts = ln_f_points(&v);
        let mid = interpolate_ln_f(&pts, (100.0f64 * 200.0).sqrt()).unwrap();
        assert!((mid - 0.03).abs() < 1e-12, "{mid}");
        assert_eq!(interpolate_ln_f(&pts, 10.0), Some(0.02));
        assert_eq!(interpolate_ln_f(&pts, 2000.0), Some(0.06));
        assert_eq!(interpolate_ln_f(&ln_f_points(&[None; 6]), 300.0), None);
    }
}
