//! A prototype global stage in the coordinates the data determine (not the default; selected by
//! [`GlobalStage::SpeedSweep`]): a deterministic sweep over the soil's c_P, with the intervals
//! between the measured phase speeds sampled apart, then a polish of the best few.
//!
//! χ² jumps where c_P crosses a model phase speed (the cliffs of P44), so at a fixed c_P the
//! misfit is smooth in (r = c_S/c_P, ξ) but across c_P it falls into pieces. The sweep takes
//! ln c_P every [`SWEEP_LN_CP_STEP`] over the image of the search box (P51, [`SpeedBox`]), plus
//! ⅛, ½ and ⅞ of each gap between consecutive measured phase speeds and 3 % outside their
//! range; at each value of ln c_P the best of a small grid in (r, ξ), [`SWEEP_R_POINTS`] by
//! [`SWEEP_XI`], on the search's lower-precision roots. The local minima of that profile over
//! ln c_P, best [`SWEEP_STARTS`] first, are polished by Levenberg–Marquardt in the search
//! coordinates. Its cost is fixed by the number of measurements, not by conditional retries.

use crate::optimize::{Bounds, Objective};

use super::fit::{polish, Optimum, POLISH_ITERATIONS};
use super::problem::{Param, Problem, Scale};
use super::speed::{soil_of, SpeedBox};

/// Which global stage the default method runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GlobalStage {
    /// Differential evolution (SHADE) restarts, then the probes: today's search.
    #[default]
    De,
    /// The prototype sweep over c_P ([`sweep`]) without DE or probes, where the problem fits
    /// E_m, ν_m and ξ only (otherwise the DE).
    SpeedSweep,
}

/// Spacing of the sweep in ln c_P (22 % in c_P).
pub const SWEEP_LN_CP_STEP: f64 = 0.2;
/// Values of r = c_S/c_P at each c_P, evenly from r(ν_m = 0.499) to 1/√2.
pub const SWEEP_R_POINTS: usize = 6;
/// Values of ξ at each c_P.
pub const SWEEP_XI: [f64; 3] = [0.0, 0.5, 1.0];
/// Local minima of the profile over ln c_P polished.
pub const SWEEP_STARTS: usize = 6;
/// How far outside the range of the measured phase speeds the sweep also samples c_P.
pub const SWEEP_OUTSIDE: f64 = 0.03;

/// Whether the sweep can run on this problem: log10 E_m, ν_m and ξ only.
pub(super) fn applies(problem: &Problem<'_>) -> bool {
    let layout = [Param::SoilModulus, Param::SoilPoisson, Param::Contact];
    problem.specs.len() == 3
        && problem.specs.iter().zip(layout).all(|(s, p)| s.param == p)
        && problem.specs[0].scale == Scale::Log10
}

/// The sweep's polished optima, with whether each polish was capped.
pub(super) fn sweep(problem: &Problem<'_>, bounds: &Bounds) -> Vec<(Optimum, bool)> {
    let s = &problem.specs;
    let region = SpeedBox::new(
        (s[0].value(s[0].lower), s[0].value(s[0].upper)),
        (s[1].lower, s[1].upper),
        problem.data.soil_density,
    );
    let (l_lo, l_hi) = region.ln_cp_range();
    let (r_lo, r_hi) = region.r_range();
    let mut v: Vec<f64> = problem
        .data
        .measurements
        .iter()
        .map(|m| m.phase_speed())
        .collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    let steps = ((l_hi - l_lo) / SWEEP_LN_CP_STEP).floor() as usize;
    let mut ln_cp: Vec<f64> = (0..=steps)
        .map(|i| l_lo + SWEEP_LN_CP_STEP * i as f64)
        .collect();
    for w in v.windows(2) {
        ln_cp.extend([0.125, 0.5, 0.875].map(|f| (w[0] + f * (w[1] - w[0])).ln()));
    }
    if let (Some(lo), Some(hi)) = (v.first(), v.last()) {
        ln_cp.push((lo * (1.0 - SWEEP_OUTSIDE)).ln());
        ln_cp.push((hi * (1.0 + SWEEP_OUTSIDE)).ln());
    }
    ln_cp.retain(|l| (l_lo..=l_hi).contains(l));
    ln_cp.sort_by(f64::total_cmp);
    ln_cp.dedup();
    // The profile: at each ln c_P the best point of the (r, ξ) grid inside the box.
    let profile: Vec<Option<(f64, Vec<f64>)>> = ln_cp
        .iter()
        .map(|&l| {
            let mut best: Option<(f64, Vec<f64>)> = None;
            for i in 0..SWEEP_R_POINTS {
                let r = r_lo + (r_hi - r_lo) * i as f64 / (SWEEP_R_POINTS - 1) as f64;
                if !region.contains(l, r) {
                    continue;
                }
                let Some((e, nu)) = soil_of(l, r, region.rho) else {
                    continue;
                };
                for xi in SWEEP_XI {
                    let mut x = vec![
                        e.log10().clamp(s[0].lower, s[0].upper),
                        nu.clamp(s[1].lower, s[1].upper),
                        xi.clamp(s[2].lower, s[2].upper),
                    ];
                    bounds.clamp(&mut x);
                    let f = problem.search_value(&x);
                    if f.is_finite() && best.as_ref().is_none_or(|(b, _)| f < *b) {
                        best = Some((f, x));
                    }
                }
            }
            best
        })
        .collect();
    let value = |i: usize| profile[i].as_ref().map_or(f64::INFINITY, |p| p.0);
    let mut minima: Vec<usize> = (0..profile.len())
        .filter(|&i| {
            let f = value(i);
            f.is_finite()
                && (i == 0 || f <= value(i - 1))
                && (i + 1 == profile.len() || f < value(i + 1))
        })
        .collect();
    minima.sort_by(|&a, &b| value(a).total_cmp(&value(b)));
    minima.truncate(SWEEP_STARTS);
    minima
        .into_iter()
        .filter_map(|i| {
            let (_, x) = profile[i].as_ref()?;
            polish(problem, x, bounds, POLISH_ITERATIONS)
        })
        .collect()
}
