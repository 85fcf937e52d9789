//! A member segment's misfit model in the soil speeds, from its single fit and the real misfit
//! (`invert::Problem`): the Gauss–Newton information JᵀJ of the weighted residuals at the fit's
//! optimum (central differences, 2n forward evaluations), ξ and any effect parameters profiled
//! out (Schur complement, with the single fit's weak prior one search range wide on them),
//! carried to (ln c_P, ln c_S) by the exact Jacobian of P63–P64 (P65); along each principal
//! axis, the growth of that information measured at probes on both sides of the fit and the
//! model checked against the real misfit there.

use crate::invert::problem::{Param, Problem, Weighting};
use crate::invert::uncertainty::coordinates_from_speeds;
use crate::invert::{Method, SegmentData};
use crate::optimize::lm::{jacobian_fd, FiniteDifference};
use crate::physics::effects::Effect;
use crate::physics::soil::{dln_cp_dnu, dln_cs_dnu, soil_speeds};
use crate::physics::{ContactMode, Model};

use super::model::{eigen, Axis, Member};

/// The settings a member's fit was made with (from its `fits` row).
#[derive(Debug, Clone, PartialEq)]
pub struct FitSetup {
    /// Model variant.
    pub model: Model,
    /// Contact reading.
    pub contact_mode: ContactMode,
    /// Effects switched on.
    pub effects: Vec<Effect>,
}

impl FitSetup {
    /// The default method's problem for `data` with this setup.
    pub fn problem<'a>(&self, data: &'a SegmentData) -> Problem<'a> {
        Problem::new(
            data,
            Method::Default,
            self.model,
            self.contact_mode,
            &self.effects,
        )
    }
}

/// Indices of E_m and ν_m among the search coordinates, `None` if either is not fitted.
fn soil_indices(problem: &Problem<'_>) -> Option<(usize, usize)> {
    let at = |p: Param| problem.specs.iter().position(|s| s.param == p);
    Some((at(Param::SoilModulus)?, at(Param::SoilPoisson)?))
}

/// The member of a zone from its data and its single fit's optimum `x` in the default
/// method's coordinates (log10 E_m, ν_m, ξ, effect coordinates…) and the single fit's own
/// relative one-sigma errors of c_P and c_S (`speed_rstd`, P65; `None` where not known). `None`
/// if the model cannot be evaluated there or the model's information is not positive definite.
/// A speed the single fit knows only loosely gives the member no information along it
/// ([`MEMBER_SPEED_RSTD_MAX`]), so a member may inform its zone along one axis of
/// (ln c_P, ln c_S) or, with both speeds loosely known, along none (its axes have λ = 0).
pub fn member_from_fit(
    segment_id: &str,
    data: &SegmentData,
    setup: &FitSetup,
    x: &[f64],
    speed_rstd: [Option<f64>; 2],
) -> Option<Member> {
    let problem = setup.problem(data);
    let n = problem.specs.len();
    if x.len() != n {
        return None;
    }
    let (ie, inu) = soil_indices(&problem)?;
    let bounds = problem.bounds().ok()?;
    let k = problem.predict(x)?;
    let ss = problem.sum_of_squares(&k);
    if !ss.is_finite() {
        return None;
    }
    // Residual variance as in the single fit: at least 1 when the model does not explain the
    // data (chi-square), σ̂² for relative residuals.
    let dof = problem.n_residuals().saturating_sub(n).max(1) as f64;
    let scale = match problem.weighting {
        Weighting::ChiSquare => (ss / dof).max(1.0),
        Weighting::Relative => ss / dof,
    };
    let h = soil_information(&problem, x, &k, scale)?;
    let (le, nu) = (x[ie], x[inu]);
    let hu = to_speeds(&h, nu)?;
    if !(hu[0] >= 0.0 && hu[3] >= 0.0) {
        return None;
    }
    let (cp, cs) = soil_speeds(10f64.powf(le), nu, data.soil_density);
    let u_hat = [cp.ln(), cs.ln()];
    // The point of the search space at speeds u_hat + du (the other coordinates at the fit).
    let at = |du: [f64; 2]| {
        let mut u = x.to_vec();
        u[ie] = u_hat[0] + du[0];
        u[inu] = u_hat[1] + du[1];
        coordinates_from_speeds(&problem.specs, &u, data.soil_density, &bounds)
    };
    let hu_fit = no_tighter_than(hu, speed_rstd);
    let mut axes = Vec::with_capacity(2);
    for (lambda, dir) in eigen(&hu_fit) {
        let mut axis = Axis {
            lambda: lambda.max(0.0),
            dir,
            growth: 0.0,
        };
        if axis.lambda > 0.0 {
            let step = (PROBE_SIGMAS / axis.lambda.sqrt()).min(PROBE_MAX_LN);
            // How the information along the axis grows with the speeds (a soft soil's c_S is
            // seen less well the softer it is): the slope of ln λ over the fit and a probe on
            // each side, λ(t) = λ₀ e^{2 b t}.
            let mut pts = vec![(0.0, quad(&hu, dir))];
            for sgn in [1.0, -1.0] {
                let t = sgn * step;
                let lam = at([t * dir[0], t * dir[1]]).and_then(|q| {
                    let k = problem.predict(&q)?;
                    let hq = soil_information(&problem, &q, &k, scale)?;
                    to_speeds(&hq, q[inu]).map(|hq| quad(&hq, dir))
                });
                if let Some(l) = lam.filter(|l| l.is_finite() && *l > 0.0) {
                    pts.push((t, l));
                }
            }
            if pts[0].1 > 0.0 && pts.len() > 1 {
                let n = pts.len() as f64;
                let mt = pts.iter().map(|p| p.0).sum::<f64>() / n;
                let ml = pts.iter().map(|p| p.1.ln()).sum::<f64>() / n;
                let sxy: f64 = pts.iter().map(|p| (p.0 - mt) * (p.1.ln() - ml)).sum();
                let sxx: f64 = pts.iter().map(|p| (p.0 - mt).powi(2)).sum();
                axis.growth = (0.5 * sxy / sxx).clamp(-MAX_GROWTH, MAX_GROWTH);
            }
            // Widen where the real misfit rises less than the model says (the valley flattens,
            // e.g. toward a soft soil's small c_S), as the single fit's uncertainty does
            // (model §7.10): probe on both sides.
            let real = [1.0, -1.0]
                .iter()
                .filter_map(|sgn| {
                    let t = sgn * step;
                    let q = at([t * dir[0], t * dir[1]])?;
                    let k = problem.predict(&q)?;
                    let rise = (problem.sum_of_squares(&k) - ss) / scale;
                    let modelled = axis.lambda * axis.shape(t).0.powi(2);
                    (rise.is_finite() && modelled > 0.0).then_some(rise / modelled)
                })
                .fold(f64::INFINITY, f64::min);
            if real.is_finite() && real < 1.0 {
                axis.lambda *= real.max(MIN_WIDENING);
            }
        }
        axes.push(axis);
    }
    Some(Member::new(
        segment_id,
        data.soil_density,
        (le, nu),
        u_hat,
        [axes[0], axes[1]],
    ))
}

/// The information `h` of (log10 E_m, ν_m) carried to (ln c_P, ln c_S): u = T x locally,
/// H_u = T⁻ᵀ H_x T⁻¹ (P65), symmetrised; `None` if not finite.
fn to_speeds(h: &[f64; 4], nu: f64) -> Option<[f64; 4]> {
    let half_ln10 = 0.5 * std::f64::consts::LN_10;
    let t = [half_ln10, dln_cp_dnu(nu), half_ln10, dln_cs_dnu(nu)];
    let det = t[0] * t[3] - t[1] * t[2];
    let ti = [t[3] / det, -t[1] / det, -t[2] / det, t[0] / det];
    let tit = [ti[0], ti[2], ti[1], ti[3]];
    let hu = mul(&mul(&tit, h), &ti);
    let off = 0.5 * (hu[1] + hu[2]);
    let hu = [hu[0], off, off, hu[3]];
    hu.iter().all(|v| v.is_finite()).then_some(hu)
}

/// vᵀ H v.
fn quad(h: &[f64; 4], v: [f64; 2]) -> f64 {
    v[0] * (h[0] * v[0] + h[1] * v[1]) + v[1] * (h[2] * v[0] + h[3] * v[1])
}

/// The information of (log10 E_m, ν_m) of `problem` at `x` (whose prediction is `k`): the
/// Gauss–Newton information JᵀJ / `scale` of the weighted residuals (central differences,
/// 2n forward evaluations), ξ and any effect parameters profiled out (Schur complement) with a
/// weak prior one search range wide on each (as the single fit's). Row-major 2 × 2; `None` if
/// the Jacobian cannot be evaluated or the nuisance block is not positive definite. At the true
/// parameters with `scale` = 1 this is the Fisher information whose inverse is the Cramér–Rao
/// bound of the member's soil ([`super::bound`]).
pub fn soil_information(
    problem: &Problem<'_>,
    x: &[f64],
    k: &[num_complex::Complex64],
    scale: f64,
) -> Option<[f64; 4]> {
    let n = problem.specs.len();
    let (ie, inu) = soil_indices(problem)?;
    let bounds = problem.bounds().ok()?;
    let m = problem.n_residuals();
    let mut r0 = vec![0.0; m];
    problem.residuals_of(k, &mut r0);
    let mut jac = vec![0.0; m * n];
    jacobian_fd(
        problem,
        x,
        &r0,
        Some(&bounds),
        FiniteDifference::Central,
        FiniteDifference::Central.default_rel_step(),
        &mut jac,
    )
    .ok()?;
    let mut info = crate::optimize::linalg::jtj(&jac, m, n);
    for v in info.iter_mut() {
        *v /= scale;
    }
    let rest: Vec<usize> = (0..n).filter(|&i| i != ie && i != inu).collect();
    for &i in &rest {
        let w = problem.specs[i].upper - problem.specs[i].lower;
        info[i * n + i] += 1.0 / (w * w);
    }
    // Schur complement: information of (log10 E, ν) with the rest profiled out.
    let soil = [ie, inu];
    let mut h = [0.0; 4];
    for (a, &i) in soil.iter().enumerate() {
        for (b, &j) in soil.iter().enumerate() {
            h[2 * a + b] = info[i * n + j];
        }
    }
    if !rest.is_empty() {
        let r = rest.len();
        let mut d = vec![0.0; r * r];
        for (a, &i) in rest.iter().enumerate() {
            for (b, &j) in rest.iter().enumerate() {
                d[a * r + b] = info[i * n + j];
            }
        }
        let l = crate::optimize::linalg::cholesky(&d, r)?;
        for (a, &i) in soil.iter().enumerate() {
            let bi: Vec<f64> = rest.iter().map(|&q| info[i * n + q]).collect();
            let di_bi = crate::optimize::linalg::cholesky_solve(&l, r, &bi);
            for (b, &j) in soil.iter().enumerate() {
                let bj: f64 = rest
                    .iter()
                    .zip(&di_bi)
                    .map(|(&q, v)| info[j * n + q] * v)
                    .sum();
                h[2 * a + b] -= bj;
            }
        }
    }
    h.iter().all(|v| v.is_finite()).then_some(h)
}

/// The information `h` of (ln c_P, ln c_S) with each coordinate's marginal variance raised to
/// at least the single fit's own (`rstd`, relative one-sigma errors of c_P and c_S), the
/// correlation kept: H′ = D⁻¹ H D⁻¹ with D = diag(max(1, σ_fit / σ_model)). The quadratic model is
/// local; where the misfit has a cusp (a root near grazing, model §7.10) it can claim c_P or
/// c_S to a fraction of a per cent while the single fit's own analysis finds it undetermined,
/// and such a member would pull its whole zone.
///
/// A speed the single fit knows only loosely (relative one-sigma error above
/// [`MEMBER_SPEED_RSTD_MAX`]) gives no information at all: only the other speed's marginal
/// information is kept. The misfit of such a segment can have a second basin as good as its
/// optimum's (a nearly incompressible soil with c_P past grazing, on the face r = c_S/c_P →
/// its lower bound of the fit's search), which no quadratic model about the optimum
/// represents; a metal
/// pipe whose single fit lies in that basin would otherwise pull its zone's c_P there
/// (`tests/zones.rs`, metal-only zones: coverage 0.81 and 0.75 of E_m and ν_m).
fn no_tighter_than(h: [f64; 4], rstd: [Option<f64>; 2]) -> [f64; 4] {
    let det = h[0] * h[3] - h[1] * h[2];
    if !(det.is_finite() && det > 0.0) {
        return h;
    }
    let undetermined = rstd.map(|s| s.is_some_and(|s| s.is_nan() || s > MEMBER_SPEED_RSTD_MAX));
    let h = match undetermined {
        [true, true] => return [0.0; 4],
        // The other speed's marginal information, 1/var.
        [true, false] => [0.0, 0.0, 0.0, det / h[0]],
        [false, true] => [det / h[3], 0.0, 0.0, 0.0],
        [false, false] => h,
    };
    // Marginal variances (a dropped coordinate's is infinite and is not raised).
    let var = match undetermined {
        [false, false] => [h[3] / det, h[0] / det],
        _ => [1.0 / h[0], 1.0 / h[3]],
    };
    let mut k = [1.0; 2];
    for i in 0..2 {
        if let Some(s) = rstd[i].filter(|s| s.is_finite() && *s > 0.0 && var[i].is_finite()) {
            k[i] = (s / var[i].sqrt()).max(1.0);
        }
    }
    [
        h[0] / (k[0] * k[0]),
        h[1] / (k[0] * k[1]),
        h[2] / (k[1] * k[0]),
        h[3] / (k[1] * k[1]),
    ]
}

/// Relative one-sigma error of a member's single-fit c_P or c_S above which that speed gives
/// the zone no information (`no_tighter_than`): a speed known that loosely lies on the
/// misfit valley's far, curved part, where the member's Gaussian information misstates it.
/// Chosen on three zoned networks by the mixed zones' E_m error p90 against the efficient
/// estimator's bound, and by the metal-only zones' coverage (the figures, per limit and
/// network, are in docs/validation.md, "Soil zones").
pub const MEMBER_SPEED_RSTD_MAX: f64 = 0.3;

/// Model sigmas at which the misfit model is checked against the real misfit (and its
/// information's growth measured).
const PROBE_SIGMAS: f64 = 2.0;
/// Largest probe step in ln c_P or ln c_S (a factor e): beyond it the model is not checked.
const PROBE_MAX_LN: f64 = 1.0;
/// Smallest factor an eigenvalue is reduced by (keeps the information positive).
const MIN_WIDENING: f64 = 0.02;
/// Largest growth rate b of an axis's information, λ ∝ e^{2 b t} per unit ln speed (the
/// information of a plastic pipe's c_S grows about as c_S^3.3 in soft soils, b ≈ 1.7).
const MAX_GROWTH: f64 = 5.0;

fn mul(a: &[f64; 4], b: &[f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] + a[1] * b[2],
        a[0] * b[1] + a[1] * b[3],
        a[2] * b[0] + a[3] * b[2],
        a[2] * b[1] + a[3] * b[3],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Information of (ln c_P, ln c_S) with marginal sigmas 0.02 and 0.05, correlation 0.6.
    fn info() -> [f64; 4] {
        let (sp, ss, r) = (0.02_f64, 0.05_f64, 0.6_f64);
        let c = [sp * sp, r * sp * ss, r * sp * ss, ss * ss];
        let det = c[0] * c[3] - c[1] * c[2];
        [c[3] / det, -c[1] / det, -c[2] / det, c[0] / det]
    }

    #[test]
    fn a_loosely_known_speed_gives_no_information_and_the_other_keeps_its_marginal() {
        let h = info();
        // c_P stated to 50 %: only c_S's marginal information, 1/0.05², remains.
        let g = no_tighter_than(h, [Some(0.5), Some(0.01)]);
        assert_eq!([g[0], g[1], g[2]], [0.0; 3]);
        assert!((g[3] - 1.0 / 0.05_f64.powi(2)).abs() < 1e-9 * g[3], "{g:?}");
        // The kept speed is still no tighter than the fit states: c_S to 10 % gives 1/0.1².
        let g = no_tighter_than(h, [Some(0.5), Some(0.1)]);
        assert!((g[3] - 100.0).abs() < 1e-9, "{g:?}");
        // Both loosely known: nothing.
        assert_eq!(no_tighter_than(h, [Some(0.4), Some(f64::NAN)]), [0.0; 4]);
        // Both known better than the model claims: unchanged.
        assert_eq!(no_tighter_than(h, [Some(0.01), Some(0.02)]), h);
    }
}
