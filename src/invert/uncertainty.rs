//! What the data determine (model §7.10): the soil's compressional and shear speeds c_P and c_S
//! (P63–P64) with one-sigma errors (P65), 95 % intervals for every fitted parameter (a
//! construction standing in for the profile likelihood P66), and the errors of the predicted
//! curves.
//!
//! The misfit valley of a buried pipe is curved in (log10 E_m, ν_m) but nearly straight in the
//! soil speeds: a metal pipe sees the radiation damper ρ_m c_P, a plastic pipe also the shear
//! stiffness μ_m = ρ_m c_S² (P47). So the quadratic model of the misfit is built in the
//! coordinates u = (ln c_P, ln c_S, ξ, effect coordinates), checked against the misfit itself
//! along its principal axes (widened where the valley is flatter than the model), and the 95 %
//! region of (c_P, c_S) is mapped back to (E_m, ν_m) exactly, clipped to the search box. The
//! profile interval of a function g of the parameters under the quadratic model is the range
//! of g over the ellipsoid Δχ² ≤ 3.84; E_m and ν_m are monotone in (c_P, c_S) (E increases with
//! both; ν increases with c_P and decreases with c_S), so their extremes over the (convex)
//! feasible part of the ellipse lie on its boundary: the ellipse's arc and the chords cut by
//! the bounds ν_m = 0 and ν_m = ν_max, which are straight lines c_S/c_P = const in u.

use crate::optimize::linalg::{cholesky, cholesky_solve, widen_along_flat_directions, Covariance};
use crate::optimize::Bounds;

use super::problem::{Param, ParamSpec, Scale};
use crate::physics::soil::{dln_cp_dnu, dln_cs_dnu, soil_from_speeds, soil_moduli, soil_speeds};

/// Δχ² of a two-sided 95 % interval of one parameter (the 0.95 quantile of χ²₁), eq. P66.
pub const DCHI2_95: f64 = 3.841_458_820_694_124;
/// z of a two-sided 95 % normal interval (√3.84).
pub const Z_95: f64 = 1.959_963_984_540_054;
/// Points of the coarse scan of the 95 % ellipse's boundary in (ln c_P, ln c_S) whose local
/// extremes of ln E_m are then refined to the stationary point (`soil_intervals`).
pub const ELLIPSE_POINTS: usize = 48;
/// Halvings of the bracket (one scan step, 7.5°) of a stationary point of ln E_m on the
/// ellipse: 2⁻⁴⁰ of it, far below where the range of E_m changes in double precision.
const ELLIPSE_REFINE_STEPS: usize = 40;
/// An interval end within this fraction of the search range from a bound "reaches" it.
pub const BOUND_REACH_FRACTION: f64 = 1e-3;

/// A 95 % interval in physical units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
    /// The lower end is the search bound (the data do not bound it from below).
    pub reaches_lower_bound: bool,
    /// The upper end is the search bound.
    pub reaches_upper_bound: bool,
}

impl Interval {
    /// Whether `v` lies inside.
    pub fn contains(&self, v: f64) -> bool {
        self.lo <= v && v <= self.hi
    }

    /// Widen to contain `v`, a physical value of the coordinate `spec`, noting an end that now
    /// reaches its search bound.
    pub fn include(&mut self, spec: &ParamSpec, v: f64) {
        self.lo = self.lo.min(v);
        self.hi = self.hi.max(v);
        self.note_bounds_reached(spec);
    }

    /// Note an end within [`BOUND_REACH_FRACTION`] of the search range from its bound of the
    /// coordinate `spec`.
    pub fn note_bounds_reached(&mut self, spec: &ParamSpec) {
        let reach = BOUND_REACH_FRACTION * (spec.upper - spec.lower);
        self.reaches_lower_bound |= spec.coordinate(self.lo) <= spec.lower + reach;
        self.reaches_upper_bound |= spec.coordinate(self.hi) >= spec.upper - reach;
    }
}

/// A value with its one-sigma error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WithError {
    /// The value.
    pub value: f64,
    /// One standard deviation.
    pub std: f64,
}

impl WithError {
    /// Relative error σ/|value|.
    pub fn relative(&self) -> f64 {
        self.std / self.value.abs()
    }

    /// Widen σ so that `other`, the value at a point inside the 95 % region (P66), lies within
    /// 1.96 σ: the quadratic model at the optimum does not see how far a flat valley or
    /// another basin reaches.
    pub fn reach(&mut self, other: f64) {
        self.std = self.std.max((other - self.value).abs() / Z_95);
    }
}

/// What the data determine about the soil and the fitted parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct Determined {
    /// Compressional speed c_P, m/s, with its error (P63, P65).
    pub p_wave_speed: WithError,
    /// Shear speed c_S, m/s, with its error (P64, P65).
    pub s_wave_speed: WithError,
    /// 95 % interval of every fitted parameter, physical units, in search-space order.
    pub intervals: Vec<Interval>,
    /// Covariance of the search coordinates (row-major n × n): the quadratic model in the speed
    /// coordinates, widened where the misfit is flatter, mapped back to the search coordinates.
    pub cov: Vec<f64>,
    /// Correlations of the search coordinates, row-major.
    pub correlation: Vec<f64>,
    /// Condition number of the column-scaled Jacobian (unit-free).
    pub condition_number: f64,
    /// The Jacobian could not be evaluated at the optimum: the quadratic model holds only the
    /// weak prior, so the intervals span the search range (the `unstable_root` flag).
    pub curvature_unknown: bool,
    /// The valley points inside the 95 % profile region (Δχ² ≤ 3.84), in search coordinates,
    /// each at its profile minimum: the caller widens what it derives from the soil (the
    /// leak-band speed) to reach them.
    pub valley: Vec<Vec<f64>>,
    /// The data's information about u = (ln c_P, ln c_S) with ξ and every effect profiled out
    /// (the Schur complement of the Gauss–Newton information JᵀJ, eq. P79), as (I_PP, I_PS,
    /// I_SS), in units of the weighted residuals (not yet divided by any variance factor). No
    /// prior is included: a direction the data do not see has (nearly) zero information.
    pub speed_information: [f64; 3],
}

/// The linear map T = ∂u/∂x from the search coordinates x to u = (ln c_P, ln c_S, rest) at x,
/// row-major n × n, and the indices of E_m and ν_m.
fn speed_map(specs: &[ParamSpec], x: &[f64]) -> (Vec<f64>, usize, usize) {
    let n = specs.len();
    let ie = specs.iter().position(|s| s.param == Param::SoilModulus);
    let inu = specs.iter().position(|s| s.param == Param::SoilPoisson);
    let (ie, inu) = (ie.expect("E_m is fitted"), inu.expect("nu_m is fitted"));
    let mut t = vec![0.0; n * n];
    for i in 0..n {
        t[i * n + i] = 1.0;
    }
    let dln_e = match specs[ie].scale {
        Scale::Log10 => std::f64::consts::LN_10,
        Scale::Linear => 1.0 / x[ie],
    };
    let nu = x[inu];
    t[ie * n + ie] = 0.5 * dln_e;
    t[ie * n + inu] = dln_cp_dnu(nu);
    t[inu * n + ie] = 0.5 * dln_e;
    t[inu * n + inu] = dln_cs_dnu(nu);
    (t, ie, inu)
}

fn mat_mul(a: &[f64], b: &[f64], n: usize) -> Vec<f64> {
    let mut c = vec![0.0; n * n];
    for i in 0..n {
        for k in 0..n {
            let aik = a[i * n + k];
            if aik != 0.0 {
                for j in 0..n {
                    c[i * n + j] += aik * b[k * n + j];
                }
            }
        }
    }
    c
}

fn transpose(a: &[f64], n: usize) -> Vec<f64> {
    (0..n * n).map(|k| a[(k % n) * n + k / n]).collect()
}

/// Inverse of the 2 × 2 block structure of [`speed_map`]: T⁻¹ (identity outside the block).
fn invert_speed_map(t: &[f64], n: usize, ie: usize, inu: usize) -> Vec<f64> {
    let mut ti = t.to_vec();
    let (a, b, c, d) = (
        t[ie * n + ie],
        t[ie * n + inu],
        t[inu * n + ie],
        t[inu * n + inu],
    );
    let det = a * d - b * c;
    ti[ie * n + ie] = d / det;
    ti[ie * n + inu] = -b / det;
    ti[inu * n + ie] = -c / det;
    ti[inu * n + inu] = a / det;
    ti
}

/// The search coordinates of a point given in speed coordinates, `None` outside the box or
/// where no soil has those speeds.
pub fn coordinates_from_speeds(
    specs: &[ParamSpec],
    u: &[f64],
    rho: f64,
    bounds: &Bounds,
) -> Option<Vec<f64>> {
    let ie = specs.iter().position(|s| s.param == Param::SoilModulus)?;
    let inu = specs.iter().position(|s| s.param == Param::SoilPoisson)?;
    let (e, nu) = soil_from_speeds(u[ie].exp(), u[inu].exp(), rho)?;
    let mut x = u.to_vec();
    x[ie] = specs[ie].coordinate(e);
    x[inu] = nu;
    let inside = x
        .iter()
        .enumerate()
        .all(|(i, &v)| v.is_finite() && bounds.lower()[i] <= v && v <= bounds.upper()[i]);
    inside.then_some(x)
}

/// What the data determine at the optimum `x` of a least-squares misfit.
///
/// `jac` is the m × n Jacobian of the weighted residuals at `x`, `scale` the residual variance
/// (1 for chi-square, σ̂² otherwise, at least 1 when the model does not explain the data),
/// `cost0` the misfit at `x`, `cost_at` the misfit anywhere (for the curvature check: 2n
/// evaluations) and `profile_at` the misfit minimised over every coordinate but E_m and ν_m,
/// starting from the point given, with the point where it is reached (for the valley scan). A weak prior, one search range wide on every coordinate, keeps the covariance
/// finite where the data say nothing (the interval then spans the search range).
#[allow(clippy::too_many_arguments)]
pub fn determine(
    specs: &[ParamSpec],
    bounds: &Bounds,
    x: &[f64],
    rho: f64,
    jac: &[f64],
    m: usize,
    scale: f64,
    cost0: f64,
    mut cost_at: impl FnMut(&[f64]) -> Option<f64>,
    mut profile_at: impl FnMut(&[f64]) -> Option<(f64, Vec<f64>)>,
) -> Determined {
    let n = specs.len();
    // Information in x, with the weak prior.
    let mut info = crate::optimize::linalg::jtj(jac, m, n);
    for v in info.iter_mut() {
        *v /= scale;
    }
    for (i, s) in specs.iter().enumerate() {
        let w = s.upper - s.lower;
        info[i * n + i] += 1.0 / (w * w);
    }
    let condition_number = scaled_condition(&info, n);
    let cov_x = spd_inverse(&info, n);
    // To speed coordinates.
    let (t, ie, inu) = speed_map(specs, x);
    let speed_information = profiled_speed_information(
        &crate::optimize::linalg::jtj(jac, m, n),
        &invert_speed_map(&t, n, ie, inu),
        n,
        ie,
        inu,
    );
    let tt = transpose(&t, n);
    let cov_u = mat_mul(&mat_mul(&t, &cov_x, n), &tt, n);
    let mut u: Vec<f64> = x.to_vec();
    let (e_opt, nu_opt) = (specs[ie].value(x[ie]), x[inu]);
    let (cp, cs) = soil_speeds(e_opt, nu_opt, rho);
    u[ie] = cp.ln();
    u[inu] = cs.ln();
    // Widen along the principal axes of the speed coordinates where the misfit is flatter.
    let mut lower = bounds.lower().to_vec();
    let mut upper = bounds.upper().to_vec();
    for i in [ie, inu] {
        lower[i] = u[i] - SPEED_PROBE_BOX_LN;
        upper[i] = u[i] + SPEED_PROBE_BOX_LN;
    }
    let mut c = Covariance {
        std_errors: (0..n).map(|i| cov_u[i * n + i].max(0.0).sqrt()).collect(),
        correlation: vec![0.0; n * n],
        cov: cov_u,
        condition_number,
        scaled_condition_number: condition_number,
        rank_deficient: false,
    };
    if let Ok(box_u) = Bounds::new(lower, upper) {
        // The quadratic model includes the weak prior, so the probes do too: otherwise a
        // direction the data do not see at all would look flatter than the model and be
        // widened, and with it every parameter it mixes with.
        let prior = |q: &[f64]| -> f64 {
            specs
                .iter()
                .zip(q.iter().zip(x))
                .map(|(s, (a, b))| ((a - b) / (s.upper - s.lower)).powi(2))
                .sum::<f64>()
        };
        widen_along_flat_directions(&u, cost0, scale, &box_u, &mut c, |p| {
            coordinates_from_speeds(specs, p, rho, bounds)
                .and_then(|q| cost_at(&q).map(|c| c + scale * prior(&q)))
        });
    }
    let cov_u = c.cov;
    let ti = invert_speed_map(&t, n, ie, inu);
    let cov_x = mat_mul(&mat_mul(&ti, &cov_u, n), &transpose(&ti, n), n);

    // The valley beyond the quadratic model: points along it within Δχ² ≤ 3.84.
    let valley = scan_valley(
        specs,
        bounds,
        &u,
        ie,
        inu,
        rho,
        cost0,
        scale,
        &mut profile_at,
    );
    let mut p_wave_speed = WithError {
        value: cp,
        std: cp * cov_u[ie * n + ie].max(0.0).sqrt(),
    };
    let mut s_wave_speed = WithError {
        value: cs,
        std: cs * cov_u[inu * n + inu].max(0.0).sqrt(),
    };
    // Every valley point lies within 1.96 σ of the speeds, the distance taken in m/s as the
    // error is reported. (A floor in ln(speed) carried to m/s at the optimum covers a point a
    // factor e^{1.96 σ} above by only 1.96 σ·c, much less than its distance.)
    for (p, _) in &valley {
        p_wave_speed.reach(p[ie].exp());
        s_wave_speed.reach(p[inu].exp());
    }
    let (mut e_int, mut nu_int) = soil_intervals(specs, bounds, &u, &cov_u, n, ie, inu, rho, x);
    for (p, _) in &valley {
        if let Some((e, nu)) = soil_from_speeds(p[ie].exp(), p[inu].exp(), rho) {
            e_int.lo = e_int.lo.min(e);
            e_int.hi = e_int.hi.max(e);
            nu_int.lo = nu_int.lo.min(nu);
            nu_int.hi = nu_int.hi.max(nu);
        }
    }
    let (e_spec, nu_spec) = (&specs[ie], &specs[inu]);
    e_int.note_bounds_reached(e_spec);
    nu_int.note_bounds_reached(nu_spec);
    let intervals = specs
        .iter()
        .enumerate()
        .map(|(i, s)| {
            if i == ie {
                e_int
            } else if i == inu {
                nu_int
            } else {
                let sd = cov_x[i * n + i].max(0.0).sqrt();
                coordinate_interval(s, x[i] - Z_95 * sd, x[i] + Z_95 * sd)
            }
        })
        .collect();
    let sd: Vec<f64> = (0..n).map(|i| cov_x[i * n + i].max(0.0).sqrt()).collect();
    let correlation = (0..n * n)
        .map(|k| {
            let (i, j) = (k / n, k % n);
            if i == j {
                1.0
            } else if sd[i] > 0.0 && sd[j] > 0.0 {
                cov_x[k] / (sd[i] * sd[j])
            } else {
                0.0
            }
        })
        .collect();
    Determined {
        p_wave_speed,
        s_wave_speed,
        intervals,
        cov: cov_x,
        correlation,
        condition_number,
        curvature_unknown: false,
        valley: valley.into_iter().map(|(_, x)| x).collect(),
        speed_information,
    }
}

/// The information about (ln c_P, ln c_S) of an information matrix `info_x` in the search
/// coordinates, with the other coordinates profiled out (eq. P79): I_u = T⁻ᵀ I_x T⁻¹ carried to
/// the speed coordinates by the inverse `ti` of `speed_map`, then the Schur complement
/// I_aa − I_ab I_bb⁺ I_ba of the speed block a = {E_m, ν_m} against the rest b (pseudo-inverse:
/// a coordinate the data do not see, such as an effect without signal, profiles out as zero).
/// Returns (I_PP, I_PS, I_SS).
pub fn profiled_speed_information(
    info_x: &[f64],
    ti: &[f64],
    n: usize,
    ie: usize,
    inu: usize,
) -> [f64; 3] {
    let iu = mat_mul(&mat_mul(&transpose(ti, n), info_x, n), ti, n);
    let a = [ie, inu];
    let b: Vec<usize> = (0..n).filter(|i| *i != ie && *i != inu).collect();
    let mut out = [iu[ie * n + ie], iu[ie * n + inu], iu[inu * n + inu]];
    if !b.is_empty() {
        let nb = b.len();
        let ibb: Vec<f64> = (0..nb * nb)
            .map(|k| iu[b[k / nb] * n + b[k % nb]])
            .collect();
        let (pinv, _) = crate::optimize::linalg::pseudo_inverse_symmetric(&ibb, nb, 1e-12);
        let mut schur = [[0.0; 2]; 2];
        for (r, &ar) in a.iter().enumerate() {
            for (c, &ac) in a.iter().enumerate() {
                let mut s = 0.0;
                for p in 0..nb {
                    for q in 0..nb {
                        s += iu[ar * n + b[p]] * pinv[p * nb + q] * iu[b[q] * n + ac];
                    }
                }
                schur[r][c] = s;
            }
        }
        out[0] -= schur[0][0];
        out[1] -= 0.5 * (schur[0][1] + schur[1][0]);
        out[2] -= schur[1][1];
    }
    // Round-off of the subtraction may leave a tiny negative eigenvalue: clip to PSD.
    let (pp, ps, ss) = (out[0].max(0.0), out[1], out[2].max(0.0));
    let lim = (pp * ss).sqrt();
    [pp, ps.clamp(-lim, lim), ss]
}

/// Points scanned along each of the two valley lines beyond the quadratic model.
pub const VALLEY_POINTS: usize = 8;

/// Scan the profile misfit along the two lines through the optimum on which the data are least
/// informative (model §7.10): c_P held at its fitted value with c_S varying (the valley of a
/// metal pipe) and c_S held with c_P varying, each across the whole range of ν_m inside the
/// box. Returns the points (in speed coordinates, with the search coordinates of their profile
/// minimum) whose profile misfit (`cost_at`: minimised over the other coordinates) is within
/// Δχ² = 3.84 (in units of `scale`) of the optimum's: they lie inside the profile region P66,
/// whatever the quadratic model says.
#[allow(clippy::too_many_arguments)]
fn scan_valley(
    specs: &[ParamSpec],
    bounds: &Bounds,
    u: &[f64],
    ie: usize,
    inu: usize,
    rho: f64,
    cost0: f64,
    scale: f64,
    cost_at: &mut impl FnMut(&[f64]) -> Option<(f64, Vec<f64>)>,
) -> Vec<(Vec<f64>, Vec<f64>)> {
    let ln_ratio = |nu: f64| {
        let (m, g) = soil_moduli(1.0, nu);
        0.5 * (g / m).ln()
    };
    let nu_spec = &specs[inu];
    let (r_hi, r_lo) = (ln_ratio(nu_spec.lower), ln_ratio(nu_spec.upper));
    let ratio0 = u[inu] - u[ie];
    let mut out = Vec::new();
    // Along each line, ln(c_S/c_P) runs over [r_lo, r_hi] (ν from ν_max to 0).
    for moving in [inu, ie] {
        for i in 0..VALLEY_POINTS {
            let r = r_lo + (r_hi - r_lo) * (i as f64 + 0.5) / VALLEY_POINTS as f64;
            let mut p = u.to_vec();
            // ln c_S − ln c_P = r: move c_S (c_P fixed) or c_P (c_S fixed).
            if moving == inu {
                p[inu] = u[ie] + r;
            } else {
                p[ie] = u[inu] - r;
            }
            if (r - ratio0).abs() < 1e-12 {
                continue;
            }
            let Some(x) = coordinates_from_speeds(specs, &p, rho, bounds) else {
                continue;
            };
            if let Some((c, at)) = cost_at(&x) {
                if c - cost0 <= DCHI2_95 * scale {
                    out.push((p, at));
                }
            }
        }
    }
    out
}

/// Half-width of the box in ln(speed) inside which the curvature probes may step (a factor
/// e³ ≈ 20 either way: beyond that the probes would only leave the search box).
const SPEED_PROBE_BOX_LN: f64 = 3.0;

/// The interval of a coordinate range, clipped to the search box, in physical units.
fn coordinate_interval(s: &ParamSpec, lo: f64, hi: f64) -> Interval {
    let reach = BOUND_REACH_FRACTION * (s.upper - s.lower);
    let (lo, hi) = (lo.max(s.lower), hi.min(s.upper));
    let (a, b) = (s.value(lo), s.value(hi));
    Interval {
        lo: a.min(b),
        hi: a.max(b),
        reaches_lower_bound: lo <= s.lower + reach,
        reaches_upper_bound: hi >= s.upper - reach,
    }
}

/// 95 % intervals of E_m and ν_m: the range of each over the part of the Δχ² ≤ 3.84 ellipse of
/// (ln c_P, ln c_S) inside the search box (see the module documentation).
#[allow(clippy::too_many_arguments)]
fn soil_intervals(
    specs: &[ParamSpec],
    bounds: &Bounds,
    u: &[f64],
    cov_u: &[f64],
    n: usize,
    ie: usize,
    inu: usize,
    rho: f64,
    x: &[f64],
) -> (Interval, Interval) {
    let c2 = [
        cov_u[ie * n + ie],
        cov_u[ie * n + inu],
        cov_u[inu * n + ie],
        cov_u[inu * n + inu],
    ];
    let (p0, s0) = (u[ie], u[inu]);
    let (e_spec, nu_spec) = (&specs[ie], &specs[inu]);
    let nu_max = nu_spec.upper;
    let mut e_range = (e_spec.value(x[ie]), e_spec.value(x[ie]));
    let mut nu_range = (x[inu], x[inu]);
    let mut take = |e: f64, nu: f64| {
        if e.is_finite() && nu.is_finite() && (nu_spec.lower..=nu_max).contains(&nu) {
            e_range = (e_range.0.min(e), e_range.1.max(e));
            nu_range = (nu_range.0.min(nu), nu_range.1.max(nu));
        }
    };
    let r = DCHI2_95.sqrt();
    if let Some(l) = cholesky(&c2, 2) {
        for (e, nu) in ellipse_extremes(p0, s0, [l[0], l[2], l[3]], r, rho) {
            take(e, nu);
        }
        // Chords along ν = const (a line ln c_S = ln c_P + ½ ln(G/M)), at the ν bounds.
        let q = {
            let det = c2[0] * c2[3] - c2[1] * c2[2];
            [c2[3] / det, -c2[1] / det, -c2[2] / det, c2[0] / det]
        };
        for nu in [nu_spec.lower, nu_max] {
            let (mm, gg) = soil_moduli(1.0, nu);
            let c = 0.5 * (gg / mm).ln();
            // d(t) = (t − p0, t + c − s0); dᵀ Q d = r².
            let s1 = s0 - c;
            let a = q[0] + 2.0 * q[1] + q[3];
            let b = -2.0 * (q[0] * p0 + q[1] * (p0 + s1) + q[3] * s1);
            let cc = q[0] * p0 * p0 + 2.0 * q[1] * p0 * s1 + q[3] * s1 * s1 - DCHI2_95;
            let disc = b * b - 4.0 * a * cc;
            if a > 0.0 && disc >= 0.0 {
                for t in [
                    (-b - disc.sqrt()) / (2.0 * a),
                    (-b + disc.sqrt()) / (2.0 * a),
                ] {
                    // E at fixed ν is proportional to M = ρ c_P².
                    let e = rho * (2.0 * t).exp() / mm;
                    take(e, nu);
                }
            }
        }
    }
    let _ = bounds;
    let e_lo = e_range.0.max(e_spec.value(e_spec.lower));
    let e_hi = e_range.1.min(e_spec.value(e_spec.upper));
    let (cl, ch) = (e_spec.coordinate(e_lo), e_spec.coordinate(e_hi));
    let reach_e = BOUND_REACH_FRACTION * (e_spec.upper - e_spec.lower);
    let reach_nu = BOUND_REACH_FRACTION * (nu_spec.upper - nu_spec.lower);
    (
        Interval {
            lo: e_lo,
            hi: e_hi,
            reaches_lower_bound: cl <= e_spec.lower + reach_e,
            reaches_upper_bound: ch >= e_spec.upper - reach_e,
        },
        Interval {
            lo: nu_range.0,
            hi: nu_range.1,
            reaches_lower_bound: nu_range.0 <= nu_spec.lower + reach_nu,
            reaches_upper_bound: nu_range.1 >= nu_spec.upper - reach_nu,
        },
    )
}

/// The soils (E_m, ν_m) on the boundary of the ellipse (ln c_P, ln c_S) = (p0, s0) + L z,
/// |z| = `r` (L lower triangular: `l` = [L₀₀, L₁₀, L₁₁]) at which ν_m or E_m is extreme.
///
/// ν_m depends on d = ln c_S − ln c_P alone (q = c_S²/c_P² = e^{2d}, ν = (1 − 2q)/(2(1 − q)),
/// P63–P64) and falls as d rises; d is linear in z, so its extremes are the two boundary points
/// along the gradient, exactly. ln E_m = ln ρ + 2 ln c_S + h(d), h(d) = ln((3 − 4q)/(1 − q)), is
/// smooth on the boundary away from ν_m = −1 and ½; its local extremes in a scan of
/// [`ELLIPSE_POINTS`] angles are refined to where its derivative along the boundary vanishes,
/// by bisection on the sign of that derivative (analytic: ∂ln E/∂ln c_S = 2 + h′(d),
/// ∂ln E/∂ln c_P = −h′(d), h′(d) = 2q/(1 − q) − 8q/(3 − 4q)). Points that are no soil are
/// left out; where the feasible arc ends, the chords at the ν_m bounds hold the extreme.
fn ellipse_extremes(p0: f64, s0: f64, l: [f64; 3], r: f64, rho: f64) -> Vec<(f64, f64)> {
    let point = |th: f64| {
        let (z0, z1) = (r * th.cos(), r * th.sin());
        (p0 + l[0] * z0, s0 + l[1] * z0 + l[2] * z1)
    };
    let soil = |th: f64| {
        let (p, s) = point(th);
        soil_from_speeds(p.exp(), s.exp(), rho)
    };
    // d ln E/dθ along the boundary.
    let slope = |th: f64| {
        let (p, s) = point(th);
        let q = (2.0 * (s - p)).exp();
        let h1 = 2.0 * q / (1.0 - q) - 8.0 * q / (3.0 - 4.0 * q);
        let (dz0, dz1) = (-r * th.sin(), r * th.cos());
        let (dp, ds) = (l[0] * dz0, l[1] * dz0 + l[2] * dz1);
        -h1 * dp + (2.0 + h1) * ds
    };
    let mut out = Vec::new();
    // ν_m: d − d₀ = (L₁₀ − L₀₀) z₀ + L₁₁ z₁ is extreme at θ = atan2(L₁₁, L₁₀ − L₀₀) and θ + π.
    let th_d = l[2].atan2(l[1] - l[0]);
    out.extend(
        [th_d, th_d + std::f64::consts::PI]
            .into_iter()
            .filter_map(soil),
    );
    let step = std::f64::consts::TAU / ELLIPSE_POINTS as f64;
    let ln_e: Vec<Option<f64>> = (0..ELLIPSE_POINTS)
        .map(|k| soil(k as f64 * step).map(|(e, _)| e.ln()))
        .collect();
    for k in 0..ELLIPSE_POINTS {
        let Some(v) = ln_e[k] else { continue };
        out.extend(soil(k as f64 * step));
        let before = ln_e[(k + ELLIPSE_POINTS - 1) % ELLIPSE_POINTS];
        let after = ln_e[(k + 1) % ELLIPSE_POINTS];
        let (Some(b), Some(a)) = (before, after) else {
            continue;
        };
        // A local maximum (sign +1) or minimum (−1) of the scan, bracketed by the derivative's
        // sign change between its neighbours.
        let sign = if v >= b && v >= a {
            1.0
        } else if v <= b && v <= a {
            -1.0
        } else {
            continue;
        };
        let (lo, hi) = ((k as f64 - 1.0) * step, (k as f64 + 1.0) * step);
        if sign * slope(lo) > 0.0 && sign * slope(hi) < 0.0 {
            let (a, b) =
                crate::optimize::bisect(lo, hi, ELLIPSE_REFINE_STEPS, |th| sign * slope(th) > 0.0);
            out.extend(soil(0.5 * (a + b)));
        }
    }
    out
}

/// 95 % intervals of E_m and ν_m of a soil known through u = (ln c_P, ln c_S) with covariance
/// `cov` (row-major 2 × 2), inside the default search box: the range of each over the
/// Δχ² ≤ 3.84 ellipse, as for a fit (`soil_intervals`). `None` where u is no soil.
pub fn soil_intervals_of_speeds(
    u: [f64; 2],
    cov: [f64; 4],
    rho: f64,
) -> Option<(Interval, Interval)> {
    let specs = super::problem::parameter_space(super::problem::Method::Default, &[]);
    let bounds = Bounds::new(
        specs.iter().map(|s| s.lower).collect(),
        specs.iter().map(|s| s.upper).collect(),
    )
    .ok()?;
    let ie = specs.iter().position(|s| s.param == Param::SoilModulus)?;
    let inu = specs.iter().position(|s| s.param == Param::SoilPoisson)?;
    let n = specs.len();
    let (e, nu) = soil_from_speeds(u[0].exp(), u[1].exp(), rho)?;
    let mut x: Vec<f64> = specs.iter().map(|s| 0.5 * (s.lower + s.upper)).collect();
    x[ie] = specs[ie].coordinate(e);
    x[inu] = nu;
    let mut uu = x.clone();
    uu[ie] = u[0];
    uu[inu] = u[1];
    let mut cov_u = vec![0.0; n * n];
    cov_u[ie * n + ie] = cov[0];
    cov_u[ie * n + inu] = cov[1];
    cov_u[inu * n + ie] = cov[2];
    cov_u[inu * n + inu] = cov[3];
    Some(soil_intervals(
        &specs, &bounds, &uu, &cov_u, n, ie, inu, rho, &x,
    ))
}

/// Inverse of a symmetric positive definite matrix (Cholesky); falls back to the symmetric
/// pseudo-inverse when the factorisation fails.
fn spd_inverse(a: &[f64], n: usize) -> Vec<f64> {
    match cholesky(a, n) {
        Some(l) => {
            let mut inv = vec![0.0; n * n];
            for j in 0..n {
                let mut e = vec![0.0; n];
                e[j] = 1.0;
                let col = cholesky_solve(&l, n, &e);
                for i in 0..n {
                    inv[i * n + j] = col[i];
                }
            }
            inv
        }
        None => crate::optimize::linalg::pseudo_inverse_symmetric(a, n, 1e-14).0,
    }
}

/// Condition number of a symmetric matrix after scaling it to unit diagonal.
fn scaled_condition(a: &[f64], n: usize) -> f64 {
    let d: Vec<f64> = (0..n).map(|i| a[i * n + i].max(0.0).sqrt()).collect();
    let scaled: Vec<f64> = (0..n * n)
        .map(|k| {
            let (i, j) = (k / n, k % n);
            if d[i] > 0.0 && d[j] > 0.0 {
                a[k] / (d[i] * d[j])
            } else {
                0.0
            }
        })
        .collect();
    let e = crate::optimize::linalg::symmetric_eigen(&scaled, n);
    let max = e.values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let min = e.values.iter().copied().fold(f64::INFINITY, f64::min);
    if min > 0.0 {
        (max / min).sqrt()
    } else {
        f64::INFINITY
    }
}

/// One-sigma error of a function f of the search coordinates from its gradient g (P65):
/// σ_f² = g Σ gᵀ.
pub fn propagate(grad: &[f64], cov: &[f64]) -> f64 {
    let n = grad.len();
    let mut s = 0.0;
    for i in 0..n {
        for j in 0..n {
            s += grad[i] * cov[i * n + j] * grad[j];
        }
    }
    s.max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::invert::problem::{parameter_space, Method};

    /// The extremes of E_m and ν_m on the 95 % ellipse's boundary, from the coarse scan refined
    /// at its local extremes, agree with a scan of 200,000 boundary points: never narrower than
    /// it, and wider by at most the scan's own sampling error (its step is 3e-5 rad, so it
    /// misses an extreme by at most about 1e-9 relative). Round, elongated and tilted ellipses,
    /// soft and stiff, including ones crossing ν_m = 0 (arcs that are no soil at ν < 0 are
    /// still in the scan's range here, as `soil_from_speeds` accepts ν > −1).
    #[test]
    fn ellipse_extremes_match_a_dense_scan_of_the_boundary() {
        let r = DCHI2_95.sqrt();
        let cases: [([f64; 2], [f64; 3]); 6] = [
            ([5.0, 3.9], [0.05, 0.0, 0.05]),
            ([5.0, 3.9], [0.3, 0.28, 0.05]),
            ([6.2, 4.1], [0.02, -0.1, 0.4]),
            ([4.4, 3.6], [0.15, 0.1, 0.02]),
            ([7.0, 6.3], [0.2, 0.15, 0.1]),
            ([5.5, 3.0], [0.6, -0.4, 0.3]),
        ];
        for (u, l) in cases {
            let rho = 1900.0;
            let ends = |pts: &[(f64, f64)]| {
                let mut e = (f64::INFINITY, f64::NEG_INFINITY);
                let mut nu = e;
                for &(a, b) in pts {
                    e = (e.0.min(a), e.1.max(a));
                    nu = (nu.0.min(b), nu.1.max(b));
                }
                (e, nu)
            };
            let n = 200_000;
            let dense: Vec<(f64, f64)> = (0..n)
                .filter_map(|k| {
                    let th = std::f64::consts::TAU * k as f64 / n as f64;
                    let (z0, z1) = (r * th.cos(), r * th.sin());
                    soil_from_speeds(
                        (u[0] + l[0] * z0).exp(),
                        (u[1] + l[1] * z0 + l[2] * z1).exp(),
                        rho,
                    )
                })
                .collect();
            let (de, dnu) = ends(&dense);
            let (fe, fnu) = ends(&ellipse_extremes(u[0], u[1], l, r, rho));
            let rel = |a: f64, b: f64| (a - b) / b.abs().max(1e-300);
            for (got, want, lower) in [
                (fe.0, de.0, true),
                (fe.1, de.1, false),
                (fnu.0, dnu.0, true),
                (fnu.1, dnu.1, false),
            ] {
                // Lower ends may only be lower than the scan's, upper only higher.
                let wider = if lower {
                    -rel(got, want)
                } else {
                    rel(got, want)
                };
                assert!(
                    (-1e-12..1e-8).contains(&wider),
                    "{u:?} {l:?}: {got} against the dense scan's {want}"
                );
            }
        }
    }

    /// A misfit that sees only c_P (a metal pipe): χ² = ((ln c_P − ln c_P*)/σ)² + ((ξ − ξ*)/s)².
    /// The E_m interval must then be the exact set {E : ∃ν ∈ [0, ν_max]: c_P(E, ν) in the 95 %
    /// interval of c_P}, and ν_m must span its whole range.
    #[test]
    fn intervals_of_a_cp_only_valley_are_the_exact_profile() {
        let specs = parameter_space(Method::Default, &[]);
        let bounds = Bounds::new(
            specs.iter().map(|s| s.lower).collect(),
            specs.iter().map(|s| s.upper).collect(),
        )
        .unwrap();
        let rho = 1800.0;
        let (sig_lncp, sig_xi) = (0.02, 0.05);
        let (e0, nu0, xi0) = (3e7, 0.3, 0.4);
        let (cp0, _) = soil_speeds(e0, nu0, rho);
        let resid = |x: &[f64]| -> [f64; 2] {
            let (cp, _) = soil_speeds(10f64.powf(x[0]), x[1], rho);
            [(cp.ln() - cp0.ln()) / sig_lncp, (x[2] - xi0) / sig_xi]
        };
        let x = [e0.log10(), nu0, xi0];
        let r0 = resid(&x);
        let mut jac = vec![0.0; 6];
        for q in 0..3 {
            let h = 1e-6;
            let mut xp = x;
            xp[q] += h;
            let r1 = resid(&xp);
            for i in 0..2 {
                jac[i * 3 + q] = (r1[i] - r0[i]) / h;
            }
        }
        let cost = |p: &[f64]| Some(resid(p).iter().map(|v| v * v).sum::<f64>());
        let profile = |q: &[f64]| cost(q).map(|c| (c, q.to_vec()));
        let d = determine(&specs, &bounds, &x, rho, &jac, 2, 1.0, 0.0, cost, profile);
        assert!((d.p_wave_speed.value / cp0 - 1.0).abs() < 1e-12);
        let rel = d.p_wave_speed.relative();
        assert!((rel - sig_lncp).abs() < 1e-2 * sig_lncp, "{rel}");
        // Exact profile: c_P in cp0·exp(±1.96σ); E = M(1+ν)(1−2ν)/(1−ν) is largest at ν = 0
        // (E = M) and smallest at ν = ν_max.
        let m_hi = rho * (cp0 * (Z_95 * sig_lncp).exp()).powi(2);
        let m_lo = rho * (cp0 * (-Z_95 * sig_lncp).exp()).powi(2);
        let nmax = specs[1].upper;
        let e_lo = m_lo * (1.0 + nmax) * (1.0 - 2.0 * nmax) / (1.0 - nmax);
        let e = d.intervals[0];
        assert!((e.hi / m_hi - 1.0).abs() < 2e-3, "{} vs {m_hi}", e.hi);
        assert!((e.lo / e_lo - 1.0).abs() < 2e-3, "{} vs {e_lo}", e.lo);
        let nu = d.intervals[1];
        assert!(nu.reaches_lower_bound && nu.reaches_upper_bound, "{nu:?}");
        let xi = d.intervals[2];
        assert!((xi.hi - (xi0 + Z_95 * sig_xi)).abs() < 1e-3, "{xi:?}");
        assert!(!xi.reaches_lower_bound && !xi.reaches_upper_bound);
    }

    #[test]
    fn propagation_is_the_quadratic_form() {
        let cov = [4.0, 1.0, 1.0, 9.0];
        // g = (1, 2): 4 + 2·2·1 + 4·9 = 44.
        assert!((propagate(&[1.0, 2.0], &cov) - 44f64.sqrt()).abs() < 1e-14);
    }
}
