//! A prototype global stage in the coordinates the data determine (not the default; selected by
//! [`GlobalStage::SpeedSweep`]): a deterministic grid over (ln c_P, r = c_S/c_P, ξ), dense
//! where the misfit surface falls into pieces, then Levenberg–Marquardt from the grid's best
//! minima, from the best node of each of the best gaps with c_P held, and from both ends of
//! the best's valley.
//!
//! χ² jumps where c_P crosses a model phase speed (the cliffs of P44), so at a fixed c_P the
//! misfit is smooth in (r, ξ) but across c_P it falls into pieces, narrow where the measured
//! phase speeds lie close together. Three stages, each of a cost fixed by the number of
//! measurements, not by conditional retries:
//!
//! 1. [`sweep`]: ln c_P every [`SWEEP_LN_CP_STEP`] within a factor [`SWEEP_NEAR`] of the
//!    measured phase speeds and every [`SWEEP_LN_CP_FAR_STEP`] over the rest of the image of
//!    the search box (P51, [`SpeedBox`]), plus [`SWEEP_GAP_FRACTIONS`] of each gap between
//!    consecutive measured phase speeds, each phase speed times 1 ∓ [`SWEEP_CLIFF_OFFSET`] and
//!    c_P just outside their range ([`SWEEP_OUTSIDE`]); by [`SWEEP_R_POINTS`] values of r and
//!    [`SWEEP_XI`], rated on the search's lower-precision roots. The grid's [`SWEEP_STARTS`]
//!    best local minima (below all of their up to 26 neighbours) are polished in the search
//!    coordinates.
//! 2. [`gaps`]: in each gap between measured phase speeds (and just outside their range) the
//!    best grid node; from the [`SWEEP_GAPS`] best, LM in (r, ξ) with c_P held, then the full
//!    polish. Within a piece the misfit changes little along c_P, while r and ξ set it.
//! 3. [`valley_ends`]: at the c_P of each of the [`SWEEP_VALLEYS`] best optima, LM in (r, ξ)
//!    from the corners (r_max, ξ_min) and (r_min, ξ_max), then the full polish: the two ends
//!    of a valley along which ξ trades off against c_S.

use crate::optimize::{Bounds, LeastSquares, LevenbergMarquardt, Objective};

use super::fit::{polish, Optimum, POLISH_ITERATIONS};
use super::problem::{Param, Problem, Scale};
use super::speed::{soil_of, speeds_of, SpeedBox};

/// Which global stage the default method runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GlobalStage {
    /// The DE restarts, every other one in the speed coordinates ([`InSpeeds`]), the faces of
    /// the best optimum ([`faces`]), then the walking probes: the default search.
    #[default]
    SpeedDe,
    /// The prototype sweep over c_P ([`sweep`]) without DE or probes, where the problem fits
    /// E_m, ν_m and ξ only (otherwise the default search).
    SpeedSweep,
}

/// Spacing of the sweep in ln c_P (22 % in c_P) within [`SWEEP_NEAR`] of the measured phase
/// speeds' range.
pub const SWEEP_LN_CP_STEP: f64 = 0.2;
/// Spacing of the sweep in ln c_P farther out, where no cliff lies (P44) and the misfit
/// changes slowly with c_P.
pub const SWEEP_LN_CP_FAR_STEP: f64 = 0.5;
/// The factor around the measured phase speeds' range within which the sweep takes its finer
/// spacing.
pub const SWEEP_NEAR: f64 = 2.0;
/// Values of r = c_S/c_P at each c_P, evenly from r(ν_m = 0.499) to 1/√2.
pub const SWEEP_R_POINTS: usize = 6;
/// Values of ξ at each c_P.
pub const SWEEP_XI: [f64; 3] = [0.0, 0.5, 1.0];
/// Fractions of each gap between consecutive measured phase speeds the sweep samples.
pub const SWEEP_GAP_FRACTIONS: [f64; 3] = [0.125, 0.5, 0.875];
/// c_P just beside each measured phase speed, both sides (relative): the pieces next to a
/// cliff of P44.
pub const SWEEP_CLIFF_OFFSET: f64 = 0.004;
/// How far outside the range of the measured phase speeds the sweep also samples c_P.
pub const SWEEP_OUTSIDE: [f64; 2] = [0.01, 0.03];
/// Local minima of the grid polished.
pub const SWEEP_STARTS: usize = 6;
/// Gaps between the measured phase speeds whose best grid node starts a polish with c_P held.
pub const SWEEP_GAPS: usize = 9;
/// Optima of distinct c_P whose valleys' ends [`valley_ends`] polishes.
pub const SWEEP_VALLEYS: usize = 2;
/// Relative spacing below which two sampled values of c_P count as one.
pub const SWEEP_MERGE: f64 = 2e-3;
/// Levenberg–Marquardt iterations with c_P held, from the best grid point of each gap.
pub const SWEEP_HELD_ITERATIONS: usize = 20;
/// Relative tolerance of the held polish.
pub const SWEEP_HELD_RTOL: f64 = 1e-4;

/// Whether the sweep can run on this problem: log10 E_m, ν_m and ξ only.
pub(super) fn applies(problem: &Problem<'_>) -> bool {
    let layout = [Param::SoilModulus, Param::SoilPoisson, Param::Contact];
    problem.specs.len() == 3
        && problem.specs.iter().zip(layout).all(|(s, p)| s.param == p)
        && problem.specs[0].scale == Scale::Log10
}

/// The values of ln c_P the sweep samples, ascending, inside [`l_lo`, `l_hi`]: every
/// [`SWEEP_LN_CP_STEP`] within a factor [`SWEEP_NEAR`] of the range of the sorted measured
/// phase speeds `v`, every [`SWEEP_LN_CP_FAR_STEP`] beyond; the gaps' fractions; each phase
/// speed's two sides; and c_P just outside their range.
fn ln_cp_samples(v: &[f64], l_lo: f64, l_hi: f64) -> Vec<f64> {
    let (near_lo, near_hi) = match (v.first(), v.last()) {
        (Some(lo), Some(hi)) => ((lo / SWEEP_NEAR).ln(), (hi * SWEEP_NEAR).ln()),
        _ => (l_hi, l_hi),
    };
    let mut ln_cp = Vec::new();
    let mut l = l_lo;
    while l <= l_hi {
        ln_cp.push(l);
        let near = (near_lo..near_hi).contains(&l);
        l += if near {
            SWEEP_LN_CP_STEP
        } else {
            SWEEP_LN_CP_FAR_STEP
        };
    }
    for w in v.windows(2) {
        ln_cp.extend(SWEEP_GAP_FRACTIONS.map(|f| (w[0] + f * (w[1] - w[0])).ln()));
    }
    for &c in v {
        ln_cp.extend([
            (c * (1.0 - SWEEP_CLIFF_OFFSET)).ln(),
            (c * (1.0 + SWEEP_CLIFF_OFFSET)).ln(),
        ]);
    }
    if let (Some(lo), Some(hi)) = (v.first(), v.last()) {
        for o in SWEEP_OUTSIDE {
            ln_cp.push((lo * (1.0 - o)).ln());
            ln_cp.push((hi * (1.0 + o)).ln());
        }
    }
    ln_cp.retain(|l| (l_lo..=l_hi).contains(l));
    ln_cp.sort_by(f64::total_cmp);
    ln_cp.dedup_by(|b, a| *b - *a < SWEEP_MERGE);
    ln_cp
}

/// The search coordinates (log10 E_m, ν_m, ξ) of the soil (ln c_P, r) at contact ξ, `None`
/// outside the search box.
fn coordinates(
    problem: &Problem<'_>,
    region: &SpeedBox,
    l: f64,
    r: f64,
    xi: f64,
) -> Option<Vec<f64>> {
    let s = &problem.specs;
    if !region.contains(l, r) {
        return None;
    }
    let (e, nu) = soil_of(l, r, region.rho)?;
    Some(vec![
        s[0].coordinate(e).clamp(s[0].lower, s[0].upper),
        nu.clamp(s[1].lower, s[1].upper),
        xi.clamp(s[2].lower, s[2].upper),
    ])
}

/// The problem with the soil's c_P held at exp(`l`): parameters (r, ξ). Within one piece of
/// the misfit surface (between two cliffs of P44) the misfit changes little along c_P, while
/// r and ξ, which move the model phase speeds, set it.
struct HeldCp<'q, 'a> {
    problem: &'q Problem<'a>,
    region: SpeedBox,
    l: f64,
}

impl HeldCp<'_, '_> {
    fn x(&self, y: &[f64]) -> Option<Vec<f64>> {
        coordinates(self.problem, &self.region, self.l, y[0], y[1])
    }
}

/// The range of r inside the search box at c_P = exp(`l`): E_m = ρ_m c_P² r²(3 − 4r²)/(1 − r²)
/// (P63–P64) grows with r, so the box's E_m range is an interval of r, found by bisection;
/// `None` when no soil of that c_P lies in the box.
fn r_range_at(region: &SpeedBox, l: f64) -> Option<(f64, f64)> {
    let (lo, hi) = region.r_range();
    let e = |r: f64| soil_of(l, r, region.rho).map_or(f64::NAN, |s| s.0);
    let (e_min, e_max) = region.e;
    if e(hi) < e_min || e(lo) > e_max {
        return None;
    }
    let root = |target: f64| crate::optimize::bisect(lo, hi, 60, |m| e(m) < target).1;
    let a = if e(lo) >= e_min { lo } else { root(e_min) };
    let b = if e(hi) <= e_max { hi } else { root(e_max) };
    // Just inside, so that the soil at either end lies in the box.
    let shrink = 1e-9 * (b - a);
    (b > a).then_some((a + shrink, b - shrink))
}

impl LeastSquares for HeldCp<'_, '_> {
    fn n_params(&self) -> usize {
        2
    }
    fn n_residuals(&self) -> usize {
        self.problem.n_residuals()
    }
    fn residuals(&self, y: &[f64], out: &mut [f64]) -> bool {
        self.x(y)
            .is_some_and(|x| LeastSquares::residuals(self.problem, &x, out))
    }
    fn residuals_near(&self, base: &[f64], y: &[f64], out: &mut [f64]) -> bool {
        match (self.x(base), self.x(y)) {
            (Some(b), Some(x)) => self.problem.residuals_near(&b, &x, out),
            _ => false,
        }
    }
    fn near_at(&self, base: &[f64]) -> bool {
        self.x(base).is_some_and(|b| self.problem.near_at(&b))
    }
}

/// The region of the search box in (ln c_P, r) for this problem.
fn region_of(problem: &Problem<'_>) -> SpeedBox {
    let s = &problem.specs;
    SpeedBox::new(
        (s[0].value(s[0].lower), s[0].value(s[0].upper)),
        (s[1].lower, s[1].upper),
        problem.data.soil_density,
    )
}

/// The sweep's grid in (ln c_P, r, ξ) and its misfits (+∞ outside the box or without a root).
pub(super) struct Grid {
    region: SpeedBox,
    /// The sorted distinct measured phase speeds, m/s.
    v: Vec<f64>,
    ln_cp: Vec<f64>,
    rs: Vec<f64>,
    f: Vec<f64>,
}

impl Grid {
    fn index(&self, c: usize, i: usize, k: usize) -> usize {
        (c * self.rs.len() + i) * SWEEP_XI.len() + k
    }

    fn value(&self, (c, i, k): (usize, usize, usize)) -> f64 {
        self.f[self.index(c, i, k)]
    }

    /// Every grid node, as (ln c_P index, r index, ξ index).
    fn nodes(&self) -> impl Iterator<Item = (usize, usize, usize)> + '_ {
        let (nr, nx) = (self.rs.len(), SWEEP_XI.len());
        (0..self.ln_cp.len() * nr * nx).map(move |n| (n / (nr * nx), (n / nx) % nr, n % nx))
    }

    /// The search coordinates of a node, inside `bounds`.
    fn point(
        &self,
        problem: &Problem<'_>,
        bounds: &Bounds,
        (c, i, k): (usize, usize, usize),
    ) -> Option<Vec<f64>> {
        coordinates(
            problem,
            &self.region,
            self.ln_cp[c],
            self.rs[i],
            SWEEP_XI[k],
        )
        .map(|mut x| {
            bounds.clamp(&mut x);
            x
        })
    }

    /// The local minima of the grid (no lower value among the up to 26 neighbours), best
    /// first.
    fn minima(&self) -> Vec<(usize, usize, usize)> {
        let dims = [self.ln_cp.len(), self.rs.len(), SWEEP_XI.len()];
        let mut minima: Vec<(usize, usize, usize)> = self
            .nodes()
            .filter(|&(c, i, k)| {
                let f = self.value((c, i, k));
                f.is_finite()
                    && !(0..27).any(|d: i64| {
                        let n = [
                            c as i64 + d / 9 - 1,
                            i as i64 + (d / 3) % 3 - 1,
                            k as i64 + d % 3 - 1,
                        ];
                        n.iter().zip(dims).all(|(&a, d)| a >= 0 && a < d as i64)
                            && self.value((n[0] as usize, n[1] as usize, n[2] as usize)) < f
                    })
            })
            .collect();
        minima.sort_by(|&a, &b| self.value(a).total_cmp(&self.value(b)));
        minima
    }
}

/// The grid of the sweep: ln c_P from [`ln_cp_samples`], r evenly ([`SWEEP_R_POINTS`]), ξ at
/// [`SWEEP_XI`], each rated on the search's lower-precision roots; and the polish of its best
/// [`SWEEP_STARTS`] local minima. `None` when the measurements give no phase speed.
pub(super) fn sweep(problem: &Problem<'_>, bounds: &Bounds) -> (Grid, Vec<(Optimum, bool)>) {
    let region = region_of(problem);
    let (l_lo, l_hi) = region.ln_cp_range();
    let (r_lo, r_hi) = region.r_range();
    let mut v: Vec<f64> = problem
        .data
        .measurements
        .iter()
        .map(|m| m.phase_speed())
        .filter(|c| c.is_finite() && *c > 0.0)
        .collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    let ln_cp = ln_cp_samples(&v, l_lo, l_hi);
    let rs: Vec<f64> = (0..SWEEP_R_POINTS)
        .map(|i| r_lo + (r_hi - r_lo) * i as f64 / (SWEEP_R_POINTS - 1) as f64)
        .collect();
    let mut grid = Grid {
        region,
        v,
        f: vec![f64::INFINITY; ln_cp.len() * rs.len() * SWEEP_XI.len()],
        ln_cp,
        rs,
    };
    let nodes: Vec<_> = grid.nodes().collect();
    for node in nodes {
        if let Some(x) = grid.point(problem, bounds, node) {
            let f = problem.search_value(&x);
            if f.is_finite() {
                let n = grid.index(node.0, node.1, node.2);
                grid.f[n] = f;
            }
        }
    }
    let mut minima = grid.minima();
    minima.truncate(SWEEP_STARTS);
    let out = minima
        .into_iter()
        .filter_map(|n| {
            polish(
                problem,
                &grid.point(problem, bounds, n)?,
                bounds,
                POLISH_ITERATIONS,
            )
        })
        .collect();
    (grid, out)
}

/// Levenberg–Marquardt with c_P held at exp(`l`) from (r, ξ) = `y0`, then the full polish;
/// `None` where the box holds no soil of that c_P or the fit gives no finite misfit.
fn held_then_polished(
    problem: &Problem<'_>,
    bounds: &Bounds,
    region: SpeedBox,
    l: f64,
    y0: [f64; 2],
) -> Option<(Optimum, bool)> {
    let s = &problem.specs;
    let held = HeldCp { problem, region, l };
    let (a, b) = r_range_at(&region, l)?;
    let yb = Bounds::new(vec![a, s[2].lower], vec![b, s[2].upper]).ok()?;
    let lm = LevenbergMarquardt::new()
        .max_iterations(SWEEP_HELD_ITERATIONS)
        .and_then(|l| l.ftol(SWEEP_HELD_RTOL))
        .and_then(|l| l.xtol(SWEEP_HELD_RTOL))
        .map(|l| l.final_jacobian(false))
        .ok()?;
    let mut y = y0.to_vec();
    yb.clamp(&mut y);
    let r = lm.minimize(&held, &y, Some(&yb)).ok()?;
    let mut x = held.x(&r.x).filter(|_| r.cost.is_finite())?;
    bounds.clamp(&mut x);
    Some(
        polish(problem, &x, bounds, POLISH_ITERATIONS)
            .unwrap_or((Optimum { x, cost: r.cost }, false)),
    )
}

/// The pieces between the cliffs (P44): in each gap between consecutive measured phase speeds
/// and just outside their range, the grid's best node; at the [`SWEEP_GAPS`] best of these,
/// r and ξ moved to the bottom of that piece's valley with c_P held, then polished. A polish
/// from the grid node itself often leaves a narrow piece downhill.
pub(super) fn gaps(problem: &Problem<'_>, bounds: &Bounds, grid: &Grid) -> Vec<(Optimum, bool)> {
    let (Some(&lo), Some(&hi)) = (grid.v.first(), grid.v.last()) else {
        return Vec::new();
    };
    let widest = SWEEP_OUTSIDE.iter().fold(0.0f64, |a, &b| a.max(b));
    let (near_lo, near_hi) = ((lo * (1.0 - widest)).ln(), (hi * (1.0 + widest)).ln());
    let mut best_in: Vec<Option<(usize, usize, usize)>> = vec![None; grid.v.len() + 1];
    for node in grid.nodes() {
        let l = grid.ln_cp[node.0];
        let f = grid.value(node);
        if l < near_lo - 1e-12 || l > near_hi + 1e-12 || !f.is_finite() {
            continue;
        }
        let gap = grid.v.partition_point(|&p| p.ln() < l);
        if best_in[gap].is_none_or(|b| f < grid.value(b)) {
            best_in[gap] = Some(node);
        }
    }
    let mut starts: Vec<(usize, usize, usize)> = best_in.into_iter().flatten().collect();
    starts.sort_by(|&a, &b| grid.value(a).total_cmp(&grid.value(b)));
    starts.truncate(SWEEP_GAPS);
    starts
        .into_iter()
        .filter_map(|(c, i, k)| {
            held_then_polished(
                problem,
                bounds,
                grid.region,
                grid.ln_cp[c],
                [grid.rs[i], SWEEP_XI[k]],
            )
        })
        .collect()
}

/// The ends of the valleys in (r, ξ) of the [`SWEEP_VALLEYS`] best optima of distinct c_P:
/// where the data fix c_P and nearly only a product of ξ and c_S (a stiff pipe), the valley
/// runs from small r at large ξ to large r at small ξ, and a polish creeps along it and stops
/// short of the end that holds the optimum. With c_P held at each optimum's, Levenberg–Marquardt
/// from both corners, (r_max, ξ_min) and (r_min, ξ_max), then the full polish.
pub(super) fn valley_ends(
    problem: &Problem<'_>,
    bounds: &Bounds,
    optima: &[Optimum],
) -> Vec<(Optimum, bool)> {
    let s = &problem.specs;
    let region = region_of(problem);
    let (r_lo, r_hi) = region.r_range();
    let mut order: Vec<&Optimum> = optima.iter().filter(|o| o.cost.is_finite()).collect();
    order.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    let mut held: Vec<f64> = Vec::new();
    for o in order {
        let (l, _) = super::speed::speeds_of(s[0].value(o.x[0]), o.x[1], region.rho);
        if held.len() < SWEEP_VALLEYS && held.iter().all(|h| (h - l).abs() > SWEEP_MERGE) {
            held.push(l);
        }
    }
    held.into_iter()
        .flat_map(|l| {
            [[r_hi, s[2].lower], [r_lo, s[2].upper]]
                .into_iter()
                .filter_map(move |y0| held_then_polished(problem, bounds, region, l, y0))
        })
        .collect()
}

/// The problem in the speed coordinates: the soil's (E_m, ν_m) replaced by (ln c_P, r =
/// c_S/c_P) through the exact map of P63–P64 ([`super::speed`]), every other parameter (ξ, the
/// effects) as it is. Its box is the bounding box of the image of the search box (P51) in
/// (ln c_P, r) and the search box's own ranges of the rest; a point of it outside the image
/// (a soft soil at large r, a stiff one at small r; about 24 % of the box) has no misfit and
/// costs no forward evaluation, so that every rated soil is one of the search box (a point
/// rated at its projection onto the image would weigh the image's edge with the whole band
/// beyond it; docs/performance.md measures both). In these coordinates the cliffs of P44 are
/// (nearly) planes of constant ln c_P, and the incompressible corner ν_m → ½ is the face
/// r = r_min: r uniform over its range puts 39 % of a population at ν_m ≥ 0.45, where the
/// misfit's basins are narrow in (log10 E_m, ν_m).
pub(super) struct InSpeeds<'q, 'a> {
    problem: &'q Problem<'a>,
    /// The search box, in the search coordinates.
    bounds: &'q Bounds,
    /// Its image in (ln c_P, r).
    region: SpeedBox,
    /// Index of E_m (ln c_P in these coordinates) among the parameters.
    je: usize,
    /// Index of ν_m (r).
    jn: usize,
}

impl<'q, 'a> InSpeeds<'q, 'a> {
    /// `None` unless the problem fits E_m and ν_m.
    pub(super) fn new(problem: &'q Problem<'a>, bounds: &'q Bounds) -> Option<Self> {
        let position = |p: Param| problem.specs.iter().position(|s| s.param == p);
        let (je, jn) = (position(Param::SoilModulus)?, position(Param::SoilPoisson)?);
        let e = &problem.specs[je];
        let region = SpeedBox::new(
            (e.value(bounds.lower()[je]), e.value(bounds.upper()[je])),
            (bounds.lower()[jn], bounds.upper()[jn]),
            problem.data.soil_density,
        );
        Some(Self {
            problem,
            bounds,
            region,
            je,
            jn,
        })
    }

    /// The box of the speed coordinates.
    pub(super) fn speed_bounds(&self) -> Option<Bounds> {
        let (mut lo, mut hi) = (self.bounds.lower().to_vec(), self.bounds.upper().to_vec());
        let (l, r) = (self.region.ln_cp_range(), self.region.r_range());
        (lo[self.je], hi[self.je]) = l;
        (lo[self.jn], hi[self.jn]) = r;
        Bounds::new(lo, hi).ok()
    }

    /// The search coordinates of the point `y` of the speed coordinates, its ln c_P moved into
    /// the image of the search box at its r; `None` where r gives no soil.
    pub(super) fn x(&self, y: &[f64]) -> Option<Vec<f64>> {
        let (lo, hi) = self.region.ln_cp_range_at(y[self.jn])?;
        let (e, nu) = soil_of(y[self.je].clamp(lo, hi), y[self.jn], self.region.rho)?;
        let mut x = y.to_vec();
        x[self.je] = self.problem.specs[self.je].coordinate(e);
        x[self.jn] = nu;
        self.bounds.clamp(&mut x);
        Some(x)
    }

    /// The speed coordinates of the point `x` of the search coordinates.
    pub(super) fn y(&self, x: &[f64]) -> Vec<f64> {
        let e = self.problem.specs[self.je].value(x[self.je]);
        let (l, r) = speeds_of(e, x[self.jn], self.region.rho);
        let mut y = x.to_vec();
        y[self.je] = l;
        y[self.jn] = r;
        y
    }
}

impl Objective for InSpeeds<'_, '_> {
    fn dim(&self) -> usize {
        self.problem.specs.len()
    }
    fn value(&self, y: &[f64]) -> f64 {
        if !self.region.contains(y[self.je], y[self.jn]) {
            return f64::INFINITY;
        }
        self.x(y).map_or(f64::INFINITY, |x| self.problem.value(&x))
    }
    fn search_value(&self, y: &[f64]) -> f64 {
        if !self.region.contains(y[self.je], y[self.jn]) {
            return f64::INFINITY;
        }
        self.x(y)
            .map_or(f64::INFINITY, |x| self.problem.search_value(&x))
    }
}

/// Step in ln c_P of the line on the face r = r_min past grazing ([`faces`]): 22 % in c_P.
pub const FACE_LN_CP_STEP: f64 = 0.2;
/// Step in ln c_P of the line's stiffest end, the last [`FACE_STIFF_WIDTH`] below the box's
/// top (0.05 in log10 E_m).
pub const FACE_STIFF_STEP: f64 = 0.0576;
/// An optimum within this fraction of ξ's range of one of its bounds lies on that face.
pub const FACE_ON_BOUND_RTOL: f64 = 1e-9;
/// Width in ln c_P of the line's stiffest end: log10 E_m ≥ 9.7 at ν_m's upper bound.
pub const FACE_STIFF_WIDTH: f64 = 0.345;
/// The line's classes of c_P: past grazing up to this multiple of the mean measured phase
/// speed, and beyond.
pub const FACE_FAR_PAST_GRAZING: f64 = 2.0;
/// The best of the stiffest end is polished only when its misfit is at most this multiple of
/// the best optimum's.
pub const FACE_STIFF_GATE: f64 = 2.0;

/// The faces of the box in the speed coordinates at the best optimum: bounded
/// Levenberg–Marquardt polishes
///
/// * from its soil at the same c_P moved to r = r_min (ν_m → ½, the incompressible face: the
///   fluid-like end of a valley of constant c_P, c_S → 0);
/// * when it lies on a face of ξ, from its soil at the opposite face (ξ enters the soil's
///   stiffness as a weight, §4.10, so a misfit falling towards one face can have a deeper
///   basin at the other);
/// * from the best point of each class of a line along the face r = r_min past grazing (c_P
///   above the mean measured phase speed v̄, where compressional radiation switches off, model
///   §7.8 item 3, P44), at ξ ∈ {its own, 0, 1}: c_P up to [`FACE_FAR_PAST_GRAZING`] v̄, above
///   it, and the stiffest end of the box (gated by [`FACE_STIFF_GATE`]). Those basins are
///   narrow in r (c_P² ∝ 1/(1 − 2ν_m)) and in c_P, and a population seldom lands in them.
pub(super) fn faces(
    problem: &Problem<'_>,
    bounds: &Bounds,
    best: &Optimum,
) -> Vec<(Optimum, bool)> {
    let Some(speeds) = InSpeeds::new(problem, bounds) else {
        return Vec::new();
    };
    let (je, jn) = (speeds.je, speeds.jn);
    let jx = problem.specs.iter().position(|s| s.param == Param::Contact);
    let r_min = speeds.region.r_range().0;
    let y_best = speeds.y(&best.x);
    let mut starts: Vec<Vec<f64>> = Vec::new();
    let mut y = y_best.clone();
    y[jn] = r_min;
    starts.extend(speeds.x(&y));
    let mut xis = vec![None];
    if let Some(j) = jx {
        let (lo, hi) = (bounds.lower()[j], bounds.upper()[j]);
        for face in [lo, hi] {
            if face != best.x[j] {
                xis.push(Some(face));
            }
        }
        // An optimum on a face of ξ: the polish from the opposite face.
        let on_face = FACE_ON_BOUND_RTOL * (hi - lo);
        let opposite = if best.x[j] <= lo + on_face {
            Some(hi)
        } else if best.x[j] >= hi - on_face {
            Some(lo)
        } else {
            None
        };
        if let Some(face) = opposite {
            let mut x = best.x.clone();
            x[j] = face;
            starts.push(x);
        }
    }
    let n = problem.data.measurements.len().max(1) as f64;
    let v = problem
        .data
        .measurements
        .iter()
        .map(|m| m.phase_speed())
        .sum::<f64>()
        / n;
    if let (true, Some((_, top))) = (v > 0.0, speeds.region.ln_cp_range_at(r_min)) {
        // The best point of each class: [up to FACE_FAR_PAST_GRAZING v̄, beyond, stiffest].
        let mut best_of: [Option<(f64, Vec<f64>)>; 3] = [None, None, None];
        let mut rate = |l: f64, class: usize| {
            for &xi in &xis {
                let mut y = y_best.clone();
                (y[je], y[jn]) = (l, r_min);
                if let (Some(j), Some(xi)) = (jx, xi) {
                    y[j] = xi;
                }
                let Some(x) = speeds.x(&y) else { continue };
                let f = problem.value(&x);
                if f.is_finite() && best_of[class].as_ref().is_none_or(|(g, _)| f < *g) {
                    best_of[class] = Some((f, x));
                }
            }
        };
        let (far, stiff) = ((FACE_FAR_PAST_GRAZING * v).ln(), top - FACE_STIFF_WIDTH);
        let mut l = v.ln() + FACE_LN_CP_STEP;
        while l < stiff {
            rate(l, usize::from(l > far));
            l += FACE_LN_CP_STEP;
        }
        let mut l = top;
        while l >= stiff {
            rate(l, 2);
            l -= FACE_STIFF_STEP;
        }
        if best_of[2]
            .as_ref()
            .is_some_and(|(f, _)| *f > FACE_STIFF_GATE * best.cost)
        {
            best_of[2] = None;
        }
        starts.extend(best_of.into_iter().flatten().map(|(_, x)| x));
    }
    starts
        .iter()
        .filter_map(|x| polish(problem, x, bounds, POLISH_ITERATIONS))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::invert::problem::E_BOUNDS;
    use crate::invert::{FitSettings, SegmentData};
    use crate::physics::inputs::MAX_SOIL_POISSON;

    /// The default fit's problem for `data`.
    fn default_problem(data: &SegmentData) -> Problem<'_> {
        let st = FitSettings::default();
        Problem::new(data, st.method, st.model, st.contact_mode, &st.effects)
    }

    /// The samples hold both sides of each measured phase speed, the gaps' fractions and the
    /// soils just outside the range; none lie closer than [`SWEEP_MERGE`]; the fine spacing
    /// holds near the range and the coarse one far from it.
    #[test]
    fn the_samples_are_dense_at_the_cliffs_and_sparse_far_from_them() {
        let v = [400.0, 500.0, 502.0];
        let (l_lo, l_hi) = (-0.32, 10.3);
        let s = ln_cp_samples(&v, l_lo, l_hi);
        assert!(s.windows(2).all(|w| w[1] - w[0] >= SWEEP_MERGE), "{s:?}");
        let has = |c: f64| s.iter().any(|l| (l - c.ln()).abs() < SWEEP_MERGE);
        for c in v {
            assert!(has(c * (1.0 - SWEEP_CLIFF_OFFSET)) && has(c * (1.0 + SWEEP_CLIFF_OFFSET)));
        }
        assert!(has(450.0) && has(412.5) && has(487.5));
        assert!(has(400.0 * 0.97) && has(502.0 * 1.03) && has(502.0 * 1.01));
        // 200 to 1,004 m/s is near; 10 m/s and 20,000 m/s are far.
        let spacing = |c: f64| {
            let l = c.ln();
            let above = s.iter().copied().find(|&x| x > l).unwrap();
            let below = s.iter().copied().rev().find(|&x| x <= l).unwrap();
            above - below
        };
        assert!(spacing(300.0) <= SWEEP_LN_CP_STEP + 1e-12);
        assert!(spacing(10.0) > SWEEP_LN_CP_STEP + 1e-12);
        assert!(spacing(20_000.0) > SWEEP_LN_CP_STEP + 1e-12);
        assert!(s[0] >= l_lo && *s.last().unwrap() <= l_hi);
    }

    /// At a held c_P the range of r gives soils inside the box at both ends, and the box's
    /// E_m limits where it cuts r's range; a c_P no soil of the box has gives none.
    #[test]
    fn the_range_of_r_at_a_held_c_p_is_the_box_s() {
        let rho = 1_900.0;
        let b = SpeedBox::new(E_BOUNDS, (0.0, MAX_SOIL_POISSON), rho);
        let (r_lo, r_hi) = b.r_range();
        // c_P 5 m/s: E_m at ν_m = 0 is 4.75e4 Pa, in the box; at r_lo it is 284 Pa, below
        // E_min.
        let l = 5f64.ln();
        let (a, c) = r_range_at(&b, l).expect("a range");
        assert!(a > r_lo && (c - r_hi).abs() < 1e-6, "{a} {c}");
        let (e_a, _) = soil_of(l, a, rho).unwrap();
        assert!((e_a / E_BOUNDS.0 - 1.0).abs() < 1e-6, "{e_a}");
        assert!(b.contains(l, a) && b.contains(l, c));
        // c_P 20,000 m/s: E_m at ν_m = 0 is 7.6e11 Pa, above E_max; at r_lo 4.6e9 Pa, inside.
        let l = 20_000f64.ln();
        let (a, c) = r_range_at(&b, l).expect("a range");
        assert!((a - r_lo).abs() < 1e-6 && c < r_hi, "{a} {c}");
        let (e_c, _) = soil_of(l, c, rho).unwrap();
        assert!((e_c / E_BOUNDS.1 - 1.0).abs() < 1e-6, "{e_c}");
        assert!(r_range_at(&b, 0.1f64.ln()).is_none());
        assert!(r_range_at(&b, 50_000f64.ln()).is_none());
    }

    /// The speed DE's coordinates: the box is the image's bounding box (ln c_P −0.32 to 10.30
    /// at ρ_m 1,900 kg/m³, r from r(0.499) to 1/√2, ξ's own range); a point of the search box
    /// returns to itself through (ln c_P, r); a point of the bounding box outside the image has
    /// no misfit, and one inside is rated as its soil.
    #[test]
    fn the_speed_de_rates_the_image_of_the_search_box_only() {
        use crate::synth::bench::{bench_network, MaterialMix};
        let data = bench_network(5, 848484, MaterialMix::Default)
            .into_iter()
            .next()
            .expect("a segment")
            .data;
        let problem = default_problem(&data);
        let bounds = problem.bounds().expect("bounds");
        let speeds = InSpeeds::new(&problem, &bounds).expect("E_m and ν_m are fitted");
        let yb = speeds.speed_bounds().expect("a box");
        let rho = data.soil_density;
        let (l_lo, l_hi) = (0.5 * (E_BOUNDS.0 / rho).ln(), {
            let nu = MAX_SOIL_POISSON;
            0.5 * (E_BOUNDS.1 * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu)) / rho).ln()
        });
        assert!((yb.lower()[0] - l_lo).abs() < 1e-9 && (yb.upper()[0] - l_hi).abs() < 1e-9);
        assert!((yb.lower()[1] - 0.044_68).abs() < 1e-5, "{}", yb.lower()[1]);
        assert!((yb.upper()[1] - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
        assert_eq!(
            (yb.lower()[2], yb.upper()[2]),
            (bounds.lower()[2], bounds.upper()[2])
        );
        for x in [
            vec![7.3, 0.21, 0.4],
            vec![3.5, 0.0, 1.0],
            vec![9.9, 0.499, 0.0],
        ] {
            let back = speeds.x(&speeds.y(&x)).expect("a soil");
            for (a, b) in x.iter().zip(&back) {
                assert!((a - b).abs() < 1e-9, "{x:?} -> {back:?}");
            }
        }
        // ln c_P 9 (8,100 m/s) at r = 1/√2 needs E_m = 1.2e11 Pa, above the box: no misfit.
        let outside = [9.0, std::f64::consts::FRAC_1_SQRT_2, 0.5];
        assert!(!speeds.region.contains(outside[0], outside[1]));
        assert_eq!(speeds.value(&outside), f64::INFINITY);
        assert_eq!(speeds.search_value(&outside), f64::INFINITY);
        let inside = speeds.y(&[7.3, 0.21, 0.4]);
        let x = speeds.x(&inside).expect("a soil");
        assert_eq!(speeds.value(&inside), problem.value(&x));
        assert!(speeds.value(&inside).is_finite());
    }

    /// A ductile-iron pipe whose global optimum lies past grazing on the face r = r_min (c_P
    /// 2,538 m/s, r 0.056, χ² 1.14), while a basin at c_P 166 m/s (χ² 2.08) holds the best
    /// optimum of a search: the faces stage reaches the first from the second, by the line
    /// along the face (the polish from r_min at the best's own c_P stays below grazing).
    #[test]
    fn the_faces_reach_an_optimum_past_grazing_on_the_incompressible_face() {
        use crate::synth::bench::{bench_network, MaterialMix};
        let data = bench_network(200, 848484, MaterialMix::Default)
            .into_iter()
            .find(|s| s.id == "WM10101")
            .expect("segment")
            .data;
        let problem = default_problem(&data);
        let bounds = problem.bounds().expect("bounds");
        let speeds = InSpeeds::new(&problem, &bounds).expect("E_m and ν_m are fitted");
        let x = speeds.x(&[166.15f64.ln(), 0.4307, 1.0]).expect("a soil");
        let (best, _) = polish(&problem, &x, &bounds, POLISH_ITERATIONS).expect("polished");
        assert!((best.cost - 2.08).abs() < 0.01, "{}", best.cost);
        let found = faces(&problem, &bounds, &best);
        let lowest = found
            .iter()
            .map(|(o, _)| o)
            .min_by(|a, b| a.cost.total_cmp(&b.cost));
        let lowest = lowest.expect("optima");
        assert!(lowest.cost < 1.2, "{}", lowest.cost);
        let y = speeds.y(&lowest.x);
        assert!(y[0].exp() > 2_000.0 && y[1] < 0.07, "{y:?}");
    }
}
