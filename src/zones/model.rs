//! The hierarchical model of one soil zone (model §7.11, P67–P68), on per-segment models
//! of the misfit in the soil speeds u = (ln c_P, ln c_S) (P63–P64).
//!
//! Each member s brings its single fit's speeds û_s and, along the two principal axes of its
//! information there (ξ and any effect parameters profiled out), the information λ and how it
//! grows with the speeds ([`Axis`]): χ²_s(E_s, ν_s) ≈ χ²_s,min + Σ_axes λ g(t)², t the
//! coordinate of u_s(E_s, ν_s) − û_s along the axis, g(t) = (e^{bt} − 1)/b (a quadratic when
//! b = 0), mapped exactly from (log10 E, ν) with the segment's own ρ_m. The zone's objective
//! Φ(E_z, ν_z) is −2 ln of its marginal likelihood: for each member, the minimum over (E_s, ν_s)
//! of [χ²_s + δ_s²/τ_E² + ε_s²/τ_ν²] (P68) plus the Laplace (Occam) term
//! ln det(JᵀHJ + P) − ln det P at the minimiser, which integrates the member's own (E_s, ν_s)
//! out ([`Member::marginal`]). Φ is evaluated on a coarse grid over the whole search box, then
//! on a grid in the speeds over its 95 % region and one zoomed on that grid's region; the 95 %
//! intervals are {θ : min over the other coordinate of Φ ≤ Φ_min + 3.84} (as P66). A member
//! whose own misfit at the zone, allowing for the scatter (the P68 minimum alone), exceeds the χ²₂ 0.999
//! quantile is an outlier: reported and left out of the zone estimate.

use crate::invert::problem::E_BOUNDS;
use crate::invert::uncertainty::DCHI2_95;
use crate::physics::inputs::MAX_SOIL_POISSON;
use crate::physics::soil::{dln_cp_dnu, dln_cs_dnu, soil_from_speeds, soil_speeds};

/// Typical scatter of log10 E_m between segments of one soil unit, decades (model §7.11:
/// "about 0.04 decade", i.e. about 10 % in E).
pub const TAU_E_DECADES: f64 = 0.04;
/// Typical scatter of ν_m between segments of one soil unit (model §7.11: about 0.01).
pub const TAU_NU: f64 = 0.01;
/// Members with a fit a zone needs before it is estimated.
pub const MIN_MEMBERS: usize = 3;
/// χ²₂ quantile at 0.999: a member whose misfit at the zone (measurement error and scatter
/// allowed for) exceeds it is a `zone_outlier` (false-alarm rate 0.1 % per segment).
pub const OUTLIER_CHI2: f64 = 13.815_510_557_964_274;
/// Largest ν the inner minimisation visits: ν = 0.5 is singular (c_P infinite).
const NU_CAP: f64 = 0.4995;
/// Coarse grid: steps in log10 E (decades) and ν.
const COARSE_STEP_E: f64 = 0.125;
const COARSE_STEP_NU: f64 = 0.025;
/// Fine grid: points per side over the coarse 95 % region.
const FINE_POINTS: usize = 31;
/// Gauss–Newton iterations of the inner (per-member) minimisation.
const INNER_ITERATIONS: usize = 12;
/// The inner minimisation stops when its step is below this fraction of the scatter (τ_E, τ_ν).
const INNER_TOLERANCE: f64 = 1e-4;

/// One principal axis of a member's misfit model in the soil speeds: along the unit direction
/// `dir`, at t = dirᵀ(u − û) from the single fit, the misfit is λ g(t)² with
/// g(t) = (e^{b t} − 1)/b (t when b = 0), so the information there, λ e^{2 b t}, grows at the
/// rate `growth` = b measured at the fit. A plain quadratic (b = 0) evaluated at a noisy
/// optimum weighs the members whose noise pushed them toward the better-seen side (a stiffer
/// soil for a plastic pipe's c_S) more, and biased soft zones stiff.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    /// Information along the axis at the single fit, λ.
    pub lambda: f64,
    /// Unit direction in (ln c_P, ln c_S).
    pub dir: [f64; 2],
    /// Growth rate b of the information, per unit ln speed.
    pub growth: f64,
}

impl Axis {
    /// g(t) and g′(t) = e^{b t}.
    pub fn shape(&self, t: f64) -> (f64, f64) {
        let bt = (self.growth * t).min(MAX_GROWTH_EXPONENT);
        if bt.abs() < 1e-9 {
            (t, 1.0)
        } else {
            (bt.exp_m1() / self.growth, bt.exp())
        }
    }
}

/// Largest exponent b t of an axis's shape (keeps e^{b t} finite far from the fit).
const MAX_GROWTH_EXPONENT: f64 = 50.0;

/// The eigenvalues and unit eigenvectors of a symmetric 2 × 2 matrix (row-major), largest first.
pub fn eigen(h: &[f64; 4]) -> [(f64, [f64; 2]); 2] {
    let (a, b, d) = (h[0], 0.5 * (h[1] + h[2]), h[3]);
    let tr = 0.5 * (a + d);
    let disc = (0.25 * (a - d) * (a - d) + b * b).sqrt();
    let vec = |l: f64| {
        if b.abs() > 1e-300 {
            let (x, y) = (l - d, b);
            let n = (x * x + y * y).sqrt();
            [x / n, y / n]
        } else if (l - a).abs() <= (l - d).abs() {
            [1.0, 0.0]
        } else {
            [0.0, 1.0]
        }
    };
    let (l1, l2) = (tr + disc, tr - disc);
    let v1 = vec(l1);
    // The second axis orthogonal to the first (also when the eigenvalues coincide).
    [(l1, v1), (l2, [-v1[1], v1[0]])]
}

/// What one member segment brings to its zone: the model of its misfit in the soil speeds.
#[derive(Debug, Clone, PartialEq)]
pub struct Member {
    /// Segment.
    pub segment_id: String,
    /// Soil density ρ_m from the inventory, kg/m³.
    pub soil_density: f64,
    /// The single fit's log10 E_m (Pa) and ν_m.
    pub single: (f64, f64),
    /// The single fit's (ln c_P, ln c_S).
    pub u_hat: [f64; 2],
    /// Information of (ln c_P, ln c_S) at the single fit, row-major 2 × 2 (other coordinates
    /// profiled out): Σ λ dir dirᵀ over [`Self::axes`].
    pub info: [f64; 4],
    /// The misfit model's principal axes.
    pub axes: [Axis; 2],
}

impl Member {
    /// A member from its single fit and the axes of its misfit model.
    pub fn new(
        segment_id: &str,
        soil_density: f64,
        single: (f64, f64),
        u_hat: [f64; 2],
        axes: [Axis; 2],
    ) -> Self {
        let mut info = [0.0; 4];
        for a in &axes {
            info[0] += a.lambda * a.dir[0] * a.dir[0];
            info[1] += a.lambda * a.dir[0] * a.dir[1];
            info[2] += a.lambda * a.dir[1] * a.dir[0];
            info[3] += a.lambda * a.dir[1] * a.dir[1];
        }
        Self {
            segment_id: segment_id.to_string(),
            soil_density,
            single,
            u_hat,
            info,
            axes,
        }
    }

    /// A member whose misfit is the quadratic (u − û)ᵀ `info` (u − û) (no growth).
    pub fn quadratic(
        segment_id: &str,
        soil_density: f64,
        single: (f64, f64),
        u_hat: [f64; 2],
        info: [f64; 4],
    ) -> Self {
        let axes = eigen(&info).map(|(l, dir)| Axis {
            lambda: l.max(0.0),
            dir,
            growth: 0.0,
        });
        Self::new(segment_id, soil_density, single, u_hat, axes)
    }

    /// (ln c_P, ln c_S) of this member's soil at (log10 E, ν) (P63–P64).
    fn u(&self, le: f64, nu: f64) -> [f64; 2] {
        let (cp, cs) = soil_speeds(10f64.powf(le), nu, self.soil_density);
        [cp.ln(), cs.ln()]
    }

    /// The misfit model at speeds `u`: (misfit, ½ its gradient in u, its Gauss–Newton
    /// curvature ½ ∇² in u), from the residuals √λ g(t) of the axes.
    fn local(&self, u: [f64; 2]) -> (f64, [f64; 2], [f64; 4]) {
        let d = [u[0] - self.u_hat[0], u[1] - self.u_hat[1]];
        let mut f = 0.0;
        let mut g = [0.0; 2];
        let mut h = [0.0; 4];
        for a in &self.axes {
            let t = a.dir[0] * d[0] + a.dir[1] * d[1];
            let (gt, dg) = a.shape(t);
            let r = a.lambda.sqrt() * gt;
            let j = [
                a.lambda.sqrt() * dg * a.dir[0],
                a.lambda.sqrt() * dg * a.dir[1],
            ];
            f += r * r;
            g[0] += r * j[0];
            g[1] += r * j[1];
            h[0] += j[0] * j[0];
            h[1] += j[0] * j[1];
            h[2] += j[1] * j[0];
            h[3] += j[1] * j[1];
        }
        (f, g, h)
    }

    /// The modelled misfit above the single fit's minimum at (log10 E, ν).
    pub fn misfit(&self, le: f64, nu: f64) -> f64 {
        self.local(self.u(le, nu)).0
    }

    /// ∂u/∂(log10 E, ν) at ν, row-major (P65).
    fn jacobian(nu: f64) -> [f64; 4] {
        let half_ln10 = 0.5 * std::f64::consts::LN_10;
        [half_ln10, dln_cp_dnu(nu), half_ln10, dln_cs_dnu(nu)]
    }

    /// min over (E_s, ν_s) of misfit + δ²/τ_E² + ε²/τ_ν² with the zone at `z` (P68); returns
    /// the minimum and the minimiser (the member's values shrunk toward the zone).
    pub fn profile(&self, z: (f64, f64), tau: (f64, f64)) -> (f64, (f64, f64)) {
        let (f, t, _) = self.inner(z, tau);
        (f, t)
    }

    /// [`Self::profile`] and the Gauss–Newton curvature JᵀHJ + P at the minimiser.
    fn inner(&self, z: (f64, f64), tau: (f64, f64)) -> (f64, (f64, f64), [f64; 4]) {
        let p = [1.0 / (tau.0 * tau.0), 1.0 / (tau.1 * tau.1)];
        // The objective at t and the misfit model's local values there.
        let at = |t: (f64, f64)| {
            let loc = self.local(self.u(t.0, t.1));
            (
                loc.0 + p[0] * (t.0 - z.0).powi(2) + p[1] * (t.1 - z.1).powi(2),
                loc,
            )
        };
        let curvature = |t: (f64, f64), h: &[f64; 4]| {
            let j = Self::jacobian(t.1);
            let hj = mat2_mul(h, &j);
            let jt = [j[0], j[2], j[1], j[3]];
            let mut a = mat2_mul(&jt, &hj);
            a[0] += p[0];
            a[3] += p[1];
            a
        };
        let mut t = (z.0, z.1.min(NU_CAP));
        let (mut f, mut loc) = at(t);
        for _ in 0..INNER_ITERATIONS {
            let hd = loc.1;
            let j = Self::jacobian(t.1);
            // Gauss–Newton: (JᵀHJ + P) Δ = −(Jᵀ ½∇misfit + P (t − z)).
            let a = curvature(t, &loc.2);
            let g = [
                j[0] * hd[0] + j[2] * hd[1] + p[0] * (t.0 - z.0),
                j[1] * hd[0] + j[3] * hd[1] + p[1] * (t.1 - z.1),
            ];
            let det = a[0] * a[3] - a[1] * a[2];
            if !(det.is_finite() && det > 0.0) {
                break;
            }
            let step = [
                -(a[3] * g[0] - a[1] * g[1]) / det,
                -(-a[2] * g[0] + a[0] * g[1]) / det,
            ];
            // Converged: the step is a negligible fraction of the scatter.
            if step[0].abs() / tau.0 + step[1].abs() / tau.1 < INNER_TOLERANCE {
                break;
            }
            // Halve the step until the objective does not rise (the map is nonlinear).
            let mut lambda = 1.0;
            let mut accepted = false;
            for _ in 0..6 {
                let cand = (
                    t.0 + lambda * step[0],
                    (t.1 + lambda * step[1]).clamp(0.0, NU_CAP),
                );
                let (fc, lc) = at(cand);
                if fc.is_finite() && fc <= f {
                    let moved = (cand.0 - t.0).abs() + (cand.1 - t.1).abs();
                    t = cand;
                    f = fc;
                    loc = lc;
                    accepted = moved > 1e-10;
                    break;
                }
                lambda *= 0.5;
            }
            if !accepted {
                break;
            }
        }
        (f, t, curvature(t, &loc.2))
    }

    /// The member's term of the zone's marginal objective at `z`: −2 ln of
    /// ∫ exp(−χ²_s/2) N(θ_s; z, diag(τ²)) dθ_s by Laplace's method, i.e. the profile minimum
    /// of P68 plus the Occam term ln det(JᵀHJ + P) − ln det P at the minimiser (up to a
    /// constant). Without it the joint minimum of P68 over the zone and its members is drawn to
    /// where the scatter maps to large changes of the speeds (ν_z toward 0.5, where
    /// ∂ln c_P/∂ν is large): there every member can fit its own c_P at no cost, and soft
    /// zones came out with ν_m too high and E_m too low. Returns (term, profile minimum,
    /// minimiser).
    pub fn marginal(&self, z: (f64, f64), tau: (f64, f64)) -> (f64, f64, (f64, f64)) {
        let (f, t, a) = self.inner(z, tau);
        let p = [1.0 / (tau.0 * tau.0), 1.0 / (tau.1 * tau.1)];
        let det = a[0] * a[3] - a[1] * a[2];
        let occam = if det.is_finite() && det > 0.0 {
            (det / (p[0] * p[1])).ln()
        } else {
            f64::INFINITY
        };
        (f + occam, f, t)
    }
}

fn mat2_mul(a: &[f64; 4], b: &[f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] + a[1] * b[2],
        a[0] * b[1] + a[1] * b[3],
        a[2] * b[0] + a[3] * b[2],
        a[2] * b[1] + a[3] * b[3],
    ]
}

/// How the zone's scatter was chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScatterSource {
    /// Fixed at the typical values of one soil unit ([`TAU_E_DECADES`], [`TAU_NU`]).
    Fixed,
}

impl ScatterSource {
    /// Text stored in `zone_fits.scatter_source`.
    pub fn as_str(self) -> &'static str {
        match self {
            ScatterSource::Fixed => "fixed",
        }
    }
}

/// A 95 % profile interval of a zone coordinate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZoneInterval {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
    /// The interval reaches the lower end of the search range.
    pub reaches_lower_bound: bool,
    /// The interval reaches the upper end of the search range.
    pub reaches_upper_bound: bool,
}

impl ZoneInterval {
    /// True if `v` lies inside.
    pub fn contains(&self, v: f64) -> bool {
        self.lo <= v && v <= self.hi
    }
}

/// A member's place in its zone's estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct MemberResult {
    /// Segment.
    pub segment_id: String,
    /// E_m (Pa) shrunk toward the zone (the minimiser of P68 at the zone estimate).
    pub shrunk_modulus: f64,
    /// ν_m shrunk toward the zone.
    pub shrunk_poisson: f64,
    /// The member's misfit at the zone estimate with the scatter allowed for (the inner
    /// minimum of P68); compared with [`OUTLIER_CHI2`].
    pub statistic: f64,
    /// Its quadratic misfit at the zone's own values, above its single fit's minimum.
    pub misfit_at_zone: f64,
    /// Left out of the zone estimate as inconsistent with it.
    pub outlier: bool,
    /// Its single fit's log10 E_m (Pa) and ν_m ([`Member::single`]).
    pub single: (f64, f64),
    /// Its soil density ρ_m, kg/m³.
    pub soil_density: f64,
}

/// The estimate of one zone.
#[derive(Debug, Clone, PartialEq)]
pub struct ZoneEstimate {
    /// log10 E_z (Pa) at the minimum of the profile misfit.
    pub log10_modulus: f64,
    /// ν_z.
    pub poisson: f64,
    /// 95 % interval of E_z, Pa.
    pub modulus_interval: ZoneInterval,
    /// 95 % interval of ν_z.
    pub poisson_interval: ZoneInterval,
    /// The soil density the zone's speeds are given at (the members' mean ρ_m), kg/m³.
    pub soil_density: f64,
    /// 95 % interval of the zone's c_P at that density, m/s (over the same region, P63).
    pub p_wave_speed_interval: (f64, f64),
    /// 95 % interval of the zone's c_S, m/s (P64).
    pub s_wave_speed_interval: (f64, f64),
    /// Covariance (pp, ps, ss) of the zone's (ln c_P, ln c_S) at [`Self::soil_density`] under
    /// its marginal likelihood (P68), where the grid allows it: the error of the zone's soil as
    /// the field's class mean (model §7.12).
    pub speed_cov: Option<[f64; 3]>,
    /// Scatter used: (τ_E decades, τ_ν).
    pub scatter: (f64, f64),
    /// How it was chosen.
    pub scatter_source: ScatterSource,
    /// The members' profile minima of P68 at the estimate, summed over the members kept, / (2 n − 2)
    /// parameters).
    pub chi2_per_dof: f64,
    /// Every member, in input order.
    pub members: Vec<MemberResult>,
}

impl ZoneEstimate {
    /// The zone's (c_P, c_S) at its estimate and [`Self::soil_density`], m/s (P63–P64).
    pub fn speeds(&self) -> (f64, f64) {
        soil_speeds(self.modulus(), self.poisson, self.soil_density)
    }
    /// E_z, Pa.
    pub fn modulus(&self) -> f64 {
        10f64.powf(self.log10_modulus)
    }
    /// Members kept in the estimate.
    pub fn n_kept(&self) -> usize {
        self.members.iter().filter(|m| !m.outlier).count()
    }
}

/// Φ(z) over the members in `keep`: the zone's marginal objective (−2 ln of its marginal
/// likelihood up to a constant; [`Member::marginal`]).
fn phi(members: &[Member], keep: &[bool], z: (f64, f64), tau: (f64, f64)) -> f64 {
    members
        .iter()
        .zip(keep)
        .filter(|(_, &k)| k)
        .map(|(m, _)| m.marginal(z, tau).0)
        .sum()
}

/// A grid evaluation of Φ: points (log10 E, ν, Φ).
fn grid(
    members: &[Member],
    keep: &[bool],
    tau: (f64, f64),
    e_range: (f64, f64),
    nu_range: (f64, f64),
    ne: usize,
    nn: usize,
) -> Vec<(f64, f64, f64)> {
    let mut out = Vec::with_capacity(ne * nn);
    for i in 0..ne {
        let le = e_range.0 + (e_range.1 - e_range.0) * i as f64 / (ne - 1).max(1) as f64;
        for j in 0..nn {
            let nu = nu_range.0 + (nu_range.1 - nu_range.0) * j as f64 / (nn - 1).max(1) as f64;
            out.push((le, nu, phi(members, keep, (le, nu), tau)));
        }
    }
    out
}

fn minimum(points: &[(f64, f64, f64)]) -> (f64, f64, f64) {
    points.iter().copied().filter(|p| p.2.is_finite()).fold(
        (f64::NAN, f64::NAN, f64::INFINITY),
        |a, p| {
            if p.2 < a.2 {
                p
            } else {
                a
            }
        },
    )
}

/// Search box of the zone coordinates: the single-segment fit's (model §7.1).
fn search_box() -> ((f64, f64), (f64, f64)) {
    (
        (E_BOUNDS.0.log10(), E_BOUNDS.1.log10()),
        (0.0, MAX_SOIL_POISSON),
    )
}

/// The minimum of Φ, the 95 % intervals of E_z and ν_z, the 95 % region's points, and the
/// covariance of the zone's (ln c_P, ln c_S) ([`speed_covariance`]).
type Solution = (
    (f64, f64, f64),
    ZoneInterval,
    ZoneInterval,
    Vec<(f64, f64)>,
    Option<[f64; 3]>,
);

/// The covariance (pp, ps, ss) of the zone's speeds u = (ln c_P, ln c_S) under its marginal
/// likelihood e^(−Φ/2) (P68, members' soils integrated out) with a flat prior in u: the
/// weighted second moments over a regular grid in u (`points` as [`speed_grid`] gives them),
/// weights e^(−(Φ − Φ_min)/2). The grid spans the 95 % region and a step beyond, so the tails
/// it leaves out carry a few per cent of the weight. `None` with fewer than three finite
/// points or a degenerate result.
fn speed_covariance(points: &[[f64; 5]]) -> Option<[f64; 3]> {
    let finite: Vec<&[f64; 5]> = points.iter().filter(|p| p[4].is_finite()).collect();
    let f0 = finite.iter().map(|p| p[4]).fold(f64::INFINITY, f64::min);
    if finite.len() < 3 || !f0.is_finite() {
        return None;
    }
    let w: Vec<f64> = finite.iter().map(|p| (-0.5 * (p[4] - f0)).exp()).collect();
    let total: f64 = w.iter().sum();
    let mean = |k: usize| finite.iter().zip(&w).map(|(p, w)| w * p[k]).sum::<f64>() / total;
    let (mp, ms) = (mean(0), mean(1));
    let moment = |f: &dyn Fn(&[f64; 5]) -> f64| {
        finite.iter().zip(&w).map(|(p, w)| w * f(p)).sum::<f64>() / total
    };
    let pp = moment(&|p| (p[0] - mp) * (p[0] - mp));
    let ps = moment(&|p| (p[0] - mp) * (p[1] - ms));
    let ss = moment(&|p| (p[1] - ms) * (p[1] - ms));
    (pp > 0.0 && ss > 0.0 && pp * ss - ps * ps > 0.0).then_some([pp, ps, ss])
}

/// A grid of Φ in the speeds (ln c_P, ln c_S) at density `rho`, `n` × `n` points over the
/// box: points (ln c_P, ln c_S, log10 E, ν, Φ), Φ infinite where the speeds give no soil in the
/// search box.
#[allow(clippy::too_many_arguments)]
fn speed_grid(
    members: &[Member],
    keep: &[bool],
    tau: (f64, f64),
    rho: f64,
    p_range: (f64, f64),
    s_range: (f64, f64),
    n: usize,
) -> Vec<[f64; 5]> {
    let (eb, nb) = search_box();
    let mut out = Vec::with_capacity(n * n);
    for i in 0..n {
        let lp = p_range.0 + (p_range.1 - p_range.0) * i as f64 / (n - 1).max(1) as f64;
        for j in 0..n {
            let ls = s_range.0 + (s_range.1 - s_range.0) * j as f64 / (n - 1).max(1) as f64;
            let soil = soil_from_speeds(lp.exp(), ls.exp(), rho)
                .map(|(e, nu)| (e.log10(), nu))
                .filter(|&(le, nu)| {
                    (eb.0..=eb.1).contains(&le) && (nb.0..=nb.1).contains(&nu) && nu <= NU_CAP
                });
            let (le, nu, f) = match soil {
                Some((le, nu)) => (le, nu, phi(members, keep, (le, nu), tau)),
                None => (f64::NAN, f64::NAN, f64::INFINITY),
            };
            out.push([lp, ls, le, nu, f]);
        }
    }
    out
}

/// The bounding box in the speeds of the points with Φ ≤ `level`, padded by `pad` on each
/// side.
fn speed_box(points: &[[f64; 5]], level: f64, pad: (f64, f64)) -> ((f64, f64), (f64, f64)) {
    let inside: Vec<&[f64; 5]> = points.iter().filter(|p| p[4] <= level).collect();
    let range = |k: usize, pad: f64| {
        let lo = inside.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
        let hi = inside
            .iter()
            .map(|p| p[k])
            .fold(f64::NEG_INFINITY, f64::max);
        (lo - pad, hi + pad)
    };
    (range(0, pad.0), range(1, pad.1))
}

/// Minimum and 95 % region of Φ: a coarse grid in (log10 E, ν) over the search box, then two
/// grids in the speeds (ln c_P, ln c_S), where a zone's valley is nearly straight and along
/// the axes: one over the coarse region, one zoomed on its region. (A grid in (log10 E, ν)
/// steps across a narrow c_P valley, and its minimum then lies where the lattice happens to
/// meet the valley, not where the data put it.)
fn solve(members: &[Member], keep: &[bool], tau: (f64, f64)) -> Option<Solution> {
    let (eb, nb) = search_box();
    let ne = ((eb.1 - eb.0) / COARSE_STEP_E).round() as usize + 1;
    let nn = ((nb.1 - nb.0) / COARSE_STEP_NU).round() as usize + 1;
    let coarse = grid(members, keep, tau, eb, nb, ne, nn);
    let best = minimum(&coarse);
    if !best.2.is_finite() {
        return None;
    }
    let kept: Vec<&Member> = members
        .iter()
        .zip(keep)
        .filter(|(_, &k)| k)
        .map(|(m, _)| m)
        .collect();
    let rho = kept.iter().map(|m| m.soil_density).sum::<f64>() / kept.len().max(1) as f64;
    let speeds = |le: f64, nu: f64| {
        let (cp, cs) = soil_speeds(10f64.powf(le), nu, rho);
        [cp.ln(), cs.ln()]
    };
    // The coarse region in the speeds, padded by the speeds' change over one coarse step there
    // (the region's edge lies within a step of its outermost point).
    let (de, dn) = (
        (eb.1 - eb.0) / (ne - 1) as f64,
        (nb.1 - nb.0) / (nn - 1) as f64,
    );
    let c0 = speeds(best.0, best.1);
    let mut pad = (0.0f64, 0.0f64);
    for (dle, dnu) in [(de, 0.0), (-de, 0.0), (0.0, dn), (0.0, -dn)] {
        let nu = (best.1 + dnu).clamp(nb.0, NU_CAP);
        let c = speeds(best.0 + dle, nu);
        pad.0 = pad.0.max((c[0] - c0[0]).abs());
        pad.1 = pad.1.max((c[1] - c0[1]).abs());
    }
    let coarse_speeds: Vec<[f64; 5]> = coarse
        .iter()
        .map(|p| {
            let c = speeds(p.0, p.1);
            [c[0], c[1], p.0, p.1, p.2]
        })
        .collect();
    let (pr, sr) = speed_box(&coarse_speeds, best.2 + 2.0 * DCHI2_95, pad);
    let fine = speed_grid(members, keep, tau, rho, pr, sr, FINE_POINTS);
    let fbest = fine
        .iter()
        .map(|p| p[4])
        .fold(f64::INFINITY, f64::min)
        .min(best.2);
    // Zoom on the fine grid's region, one fine step wider each side.
    let step = |r: (f64, f64)| (r.1 - r.0) / (FINE_POINTS - 1) as f64;
    let (pr2, sr2) = speed_box(&fine, fbest + DCHI2_95, (step(pr), step(sr)));
    let zoom = if pr2.0.is_finite() && sr2.0.is_finite() {
        speed_grid(members, keep, tau, rho, pr2, sr2, FINE_POINTS)
    } else {
        Vec::new()
    };
    let all: Vec<[f64; 5]> = fine.iter().chain(&zoom).copied().collect();
    let zbest = all
        .iter()
        .copied()
        .filter(|p| p[4].is_finite())
        .min_by(|a, b| a[4].total_cmp(&b[4]));
    let best = match zbest.filter(|z| z[4] <= best.2) {
        Some(zbest) => (zbest[2], zbest[3], zbest[4]),
        None => best,
    };
    // The region: the zoomed grid's points inside (the fine grid's where there is no zoom),
    // each standing for its cell (half a step each side in the speeds).
    let (grid_pts, hp, hs) = if zoom.is_empty() {
        (&fine, 0.5 * step(pr), 0.5 * step(sr))
    } else {
        (&zoom, 0.5 * step(pr2), 0.5 * step(sr2))
    };
    let region: Vec<&[f64; 5]> = grid_pts
        .iter()
        .filter(|p| p[4] <= best.2 + DCHI2_95)
        .collect();
    let mut le_range = (best.0, best.0);
    let mut nu_range = (best.1, best.1);
    for p in &region {
        for (a, b) in [(-hp, -hs), (-hp, hs), (hp, -hs), (hp, hs), (0.0, 0.0)] {
            if let Some((e, nu)) = soil_from_speeds((p[0] + a).exp(), (p[1] + b).exp(), rho) {
                let (le, nu) = (e.log10().clamp(eb.0, eb.1), nu.clamp(nb.0, nb.1));
                le_range = (le_range.0.min(le), le_range.1.max(le));
                nu_range = (nu_range.0.min(nu), nu_range.1.max(nu));
            }
        }
    }
    let interval = |r: (f64, f64), b: (f64, f64)| {
        let reach = 1e-3 * (b.1 - b.0);
        ZoneInterval {
            lo: r.0,
            hi: r.1,
            reaches_lower_bound: r.0 <= b.0 + reach,
            reaches_upper_bound: r.1 >= b.1 - reach,
        }
    };
    let mut e_int = interval(le_range, eb);
    e_int.lo = 10f64.powf(e_int.lo);
    e_int.hi = 10f64.powf(e_int.hi);
    let nu_int = interval(nu_range, nb);
    let mut points: Vec<(f64, f64)> = region.iter().map(|p| (p[2], p[3])).collect();
    points.push((best.0, best.1));
    Some((best, e_int, nu_int, points, speed_covariance(grid_pts)))
}

/// Estimate one zone from its members (at least [`MIN_MEMBERS`]); `None` if too few or the
/// misfit is nowhere finite. Outliers are removed one at a time, worst first, while at least
/// [`MIN_MEMBERS`] remain.
pub fn estimate_zone(members: &[Member]) -> Option<ZoneEstimate> {
    if members.len() < MIN_MEMBERS {
        return None;
    }
    let tau = (TAU_E_DECADES, TAU_NU);
    let mut keep = vec![true; members.len()];
    loop {
        let (best, e_int, nu_int, region, speed_cov) = solve(members, &keep, tau)?;
        let z = (best.0, best.1);
        let results: Vec<MemberResult> = members
            .iter()
            .zip(&keep)
            .map(|(m, &k)| {
                let (stat, t) = m.profile(z, tau);
                MemberResult {
                    segment_id: m.segment_id.clone(),
                    shrunk_modulus: 10f64.powf(t.0),
                    shrunk_poisson: t.1,
                    statistic: stat,
                    misfit_at_zone: m.misfit(z.0, z.1),
                    outlier: !k,
                    single: m.single,
                    soil_density: m.soil_density,
                }
            })
            .collect();
        let worst = results
            .iter()
            .enumerate()
            .filter(|(i, r)| keep[*i] && r.statistic > OUTLIER_CHI2)
            .max_by(|a, b| a.1.statistic.total_cmp(&b.1.statistic))
            .map(|(i, _)| i);
        let n_kept = keep.iter().filter(|&&k| k).count();
        match worst {
            Some(i) if n_kept > MIN_MEMBERS => keep[i] = false,
            _ => {
                let dof = (2 * n_kept).saturating_sub(2).max(1) as f64;
                let rho = members
                    .iter()
                    .zip(&keep)
                    .filter(|(_, &k)| k)
                    .map(|(m, _)| m.soil_density)
                    .sum::<f64>()
                    / n_kept as f64;
                let speeds: Vec<(f64, f64)> = region
                    .iter()
                    .map(|&(le, nu)| soil_speeds(10f64.powf(le), nu, rho))
                    .collect();
                let range = |f: fn(&(f64, f64)) -> f64| {
                    speeds
                        .iter()
                        .map(f)
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, v| {
                            (a.0.min(v), a.1.max(v))
                        })
                };
                return Some(ZoneEstimate {
                    log10_modulus: z.0,
                    poisson: z.1,
                    modulus_interval: e_int,
                    poisson_interval: nu_int,
                    soil_density: rho,
                    p_wave_speed_interval: range(|s| s.0),
                    s_wave_speed_interval: range(|s| s.1),
                    speed_cov,
                    scatter: tau,
                    scatter_source: ScatterSource::Fixed,
                    chi2_per_dof: results
                        .iter()
                        .filter(|r| !r.outlier)
                        .map(|r| r.statistic)
                        .sum::<f64>()
                        / dof,
                    members: results,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A member whose single fit sees its soil's speeds with relative errors (σ_P, σ_S).
    fn member(id: &str, le: f64, nu: f64, rho: f64, sp: f64, ss: f64) -> Member {
        let (cp, cs) = soil_speeds(10f64.powf(le), nu, rho);
        Member::quadratic(
            id,
            rho,
            (le, nu),
            [cp.ln(), cs.ln()],
            [1.0 / (sp * sp), 0.0, 0.0, 1.0 / (ss * ss)],
        )
    }

    #[test]
    fn metal_and_plastic_members_determine_the_zone_and_metal_alone_does_not() {
        // Metal pipes see c_P to 2 %, c_S hardly (100 %); plastic pipes c_S to 2 %.
        let (le, nu) = (7.7, 0.33);
        let mixed: Vec<Member> = (0..6)
            .map(|i| {
                let (sp, ss) = if i % 2 == 0 { (0.02, 1.0) } else { (1.0, 0.02) };
                member(&format!("S{i}"), le, nu, 1900.0, sp, ss)
            })
            .collect();
        let z = estimate_zone(&mixed).unwrap();
        assert!((z.log10_modulus - le).abs() < 0.02, "{z:?}");
        assert!((z.poisson - nu).abs() < 0.01, "{z:?}");
        assert!(z.modulus_interval.contains(10f64.powf(le)));
        assert!(z.poisson_interval.contains(nu));
        assert!(z.modulus_interval.hi / z.modulus_interval.lo < 1.3, "{z:?}");
        assert!(z.members.iter().all(|m| !m.outlier));

        let metal: Vec<Member> = (0..6)
            .map(|i| member(&format!("M{i}"), le, nu, 1900.0, 0.02, 1.0))
            .collect();
        let zm = estimate_zone(&metal).unwrap();
        // c_P alone: E and ν trade along c_P = const, so both intervals are wide.
        assert!(
            zm.poisson_interval.hi - zm.poisson_interval.lo > 0.15,
            "{zm:?}"
        );
        assert!(
            zm.modulus_interval.hi / zm.modulus_interval.lo > 2.0,
            "{zm:?}"
        );
        assert!(zm.modulus_interval.contains(10f64.powf(le)));
        assert!(zm.poisson_interval.contains(nu));
    }

    #[test]
    fn a_member_in_another_soil_is_an_outlier_and_left_out() {
        let (le, nu) = (7.7, 0.33);
        let mut ms: Vec<Member> = (0..6)
            .map(|i| {
                let (sp, ss) = if i % 2 == 0 { (0.02, 1.0) } else { (1.0, 0.02) };
                member(&format!("S{i}"), le, nu, 1900.0, sp, ss)
            })
            .collect();
        ms.push(member("BAD", 8.5, 0.25, 1900.0, 0.02, 0.02));
        let z = estimate_zone(&ms).unwrap();
        let bad = z.members.iter().find(|m| m.segment_id == "BAD").unwrap();
        assert!(bad.outlier && bad.statistic > OUTLIER_CHI2, "{bad:?}");
        assert_eq!(z.n_kept(), 6);
        assert!((z.log10_modulus - le).abs() < 0.02, "{z:?}");
    }

    #[test]
    fn shrinkage_pulls_an_undetermined_coordinate_to_the_zone() {
        let (le, nu) = (7.7, 0.33);
        let mut ms: Vec<Member> = (0..5)
            .map(|i| {
                let (sp, ss) = if i % 2 == 0 { (0.02, 1.0) } else { (1.0, 0.02) };
                member(&format!("S{i}"), le, nu, 1900.0, sp, ss)
            })
            .collect();
        // A metal pipe whose single fit went far along its c_P valley (ν = 0.05).
        let (cp, _) = soil_speeds(10f64.powf(le), nu, 1900.0);
        let mut far = member("FAR", le, nu, 1900.0, 0.02, 1.0);
        // Same c_P, different (E, ν): move along c_P = const to ν = 0.05.
        let m_mod = 1900.0 * cp * cp;
        let nu_far: f64 = 0.05;
        let e_far = crate::physics::soil::youngs_from_p_wave_modulus(m_mod, nu_far);
        far.single = (e_far.log10(), nu_far);
        let (_, cs_far) = soil_speeds(e_far, nu_far, 1900.0);
        far.u_hat[1] = cs_far.ln();
        ms.push(far);
        let z = estimate_zone(&ms).unwrap();
        let f = z.members.iter().find(|m| m.segment_id == "FAR").unwrap();
        assert!(!f.outlier, "{f:?}");
        assert!((f.shrunk_poisson - nu).abs() < 0.03, "{f:?}");
    }

    /// Plastic-like members whose c_S misfit is κ (e^{b u} − e^{b û})² / b² exactly (the
    /// information grows as e^{2 b u}, as a plastic pipe's in soft soil) and whose single fits
    /// lie symmetrically about the truth in e^{b u}: the growth model recovers the zone's c_S,
    /// a quadratic at each fit (b = 0) is drawn toward the stiffer fits.
    #[test]
    fn growing_information_does_not_bias_the_zone_toward_the_better_seen_side() {
        let (le, nu, rho) = (7.0, 0.25, 1800.0);
        let (cp, cs) = soil_speeds(10f64.powf(le), nu, rho);
        let (b, kappa, eps): (f64, f64, f64) = (1.7, 25.0, 0.3);
        let members = |growth: bool| -> Vec<Member> {
            [1.0, -1.0, 1.0, -1.0]
                .iter()
                .enumerate()
                .map(|(i, sgn)| {
                    let t = (1.0 + sgn * eps).ln() / b;
                    let lambda = kappa * (2.0 * b * t).exp();
                    Member::new(
                        &format!("P{i}"),
                        rho,
                        (le, nu),
                        [cp.ln(), cs.ln() + t],
                        [
                            Axis {
                                lambda: 1.0 / (0.03 * 0.03),
                                dir: [1.0, 0.0],
                                growth: 0.0,
                            },
                            Axis {
                                lambda,
                                dir: [0.0, 1.0],
                                growth: if growth { b } else { 0.0 },
                            },
                        ],
                    )
                })
                .collect()
        };
        let bias = |ms: &[Member]| {
            let z = estimate_zone(ms).unwrap();
            (z.speeds().1 / cs).ln()
        };
        let with = bias(&members(true));
        let without = bias(&members(false));
        assert!(with.abs() < 0.01, "with growth: ln c_S bias {with}");
        assert!(without > 0.04, "quadratic: ln c_S bias {without}");
    }

    #[test]
    fn an_axis_shape_is_the_integral_of_its_growing_information() {
        let a = Axis {
            lambda: 4.0,
            dir: [0.6, 0.8],
            growth: 1.5,
        };
        for t in [-0.7, -0.1, 0.0, 0.2, 0.9] {
            let (g, dg) = a.shape(t);
            assert!((g - ((1.5 * t).exp() - 1.0) / 1.5).abs() < 1e-12);
            assert!((dg - (1.5 * t).exp()).abs() < 1e-12);
        }
        let flat = Axis { growth: 0.0, ..a };
        assert_eq!(flat.shape(0.3), (0.3, 1.0));
    }
}
