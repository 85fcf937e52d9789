//! The search's probes near grazing (P44): where the DE runs, their polishes and the faces of
//! the box in the speed coordinates (`super::speed_search::faces`) leave a deeper basin
//! unvisited, candidates across the grazing cliffs and in their gaps, built from the best
//! optimum so far, polished and walked from (the grazing probe); and the step off a grazing
//! cliff that lets the reference path confirm an optimum on its edge.

use std::cell::RefCell;

use num_complex::Complex64;

use super::fit::{polish, Optimum, POLISH_ITERATIONS};
use super::problem::{Param, Problem};
use crate::optimize::{Bounds, LeastSquares, LevenbergMarquardt, NelderMead, Objective};
use crate::physics::soil::{shear_to_compressional, soil_from_speeds, soil_speeds};

/// Which measured frequencies radiate compressional waves into the soil at a point: those whose
/// model phase speed lies above the soil's c_P (§7.8 item 3). χ² jumps where one of them
/// crosses c_P (P44), so the landscape falls into pieces, each with its own pattern. Also the
/// soil's axes among the parameters, which every probe works along.
pub(super) struct Pieces<'p, 'a> {
    problem: &'p Problem<'a>,
    /// Index of log10 E_m among the parameters.
    je: usize,
    /// Index of ν_m.
    jn: usize,
    /// Index of ξ, when it is fitted.
    jx: Option<usize>,
    /// The probes' polishes so far, by start.
    polishes: Trodden<Option<(Optimum, bool)>>,
    /// The probes' walks so far, by start.
    walks: Trodden<Option<Optimum>>,
}

/// What the probes of one search found from each start they polished or walked from. A polish
/// and a walk are deterministic functions of their start and box (the problem being the
/// search's), and the probes often start them from the same point again: a later round of the
/// grazing probe, or its scan again near grazing, from a best that did not move starts its own
/// polishes and walks where the round before did. Answered from here, each fit's result is
/// the same to the bit, with fewer evaluations; the saving is largest near grazing (P44),
/// where the root's continuation halves its steps (see `physics::solver::NEWTON_MAX_ITER`) and
/// an evaluation costs many times one of the DE runs' (evidence: docs/search.md, "The probes'
/// memory of their fits (Trodden)").
struct Trodden<T> {
    seen: RefCell<Vec<(Vec<u64>, Bounds, T)>>,
}

impl<T: Clone> Trodden<T> {
    fn new() -> Self {
        Self {
            seen: RefCell::new(Vec::new()),
        }
    }

    /// The answer from `x` in `bounds`: remembered, or `run()` and remembered. Starts are the
    /// same when their coordinates are the same to the bit.
    fn from(&self, x: &[f64], bounds: &Bounds, run: impl FnOnce() -> T) -> T {
        let key: Vec<u64> = x.iter().map(|v| v.to_bits()).collect();
        let found = self
            .seen
            .borrow()
            .iter()
            .find(|(k, b, _)| *k == key && b == bounds)
            .map(|(_, _, t)| t.clone());
        found.unwrap_or_else(|| {
            let t = run();
            self.seen
                .borrow_mut()
                .push((key, bounds.clone(), t.clone()));
            t
        })
    }
}

impl<'p, 'a> Pieces<'p, 'a> {
    /// `None` when the problem does not fit the soil's E_m and ν_m.
    pub(super) fn new(problem: &'p Problem<'a>) -> Option<Self> {
        let position = |p: Param| problem.specs.iter().position(|s| s.param == p);
        Some(Self {
            problem,
            je: position(Param::SoilModulus)?,
            jn: position(Param::SoilPoisson)?,
            jx: position(Param::Contact),
            polishes: Trodden::new(),
            walks: Trodden::new(),
        })
    }

    /// The candidate polish from `x` ([`polish`]), once per start.
    fn polish(&self, bounds: &Bounds, x: &[f64]) -> Option<(Optimum, bool)> {
        self.polishes.from(x, bounds, || {
            polish(self.problem, x, bounds, POLISH_ITERATIONS)
        })
    }

    /// The walk from `x` ([`walk`]), once per start.
    fn walk(&self, bounds: &Bounds, x: &[f64]) -> Option<Optimum> {
        self.walks.from(x, bounds, || walk(self.problem, bounds, x))
    }

    /// The soil's (c_P, c_S) at x, m/s.
    fn speeds(&self, x: &[f64]) -> (f64, f64) {
        let e = self.problem.specs[self.je].value(x[self.je]);
        soil_speeds(e, x[self.jn], self.problem.data.soil_density)
    }

    /// Whether the model's phase speed (P2) at some frequency lies in the near-grazing band of
    /// the soil's c_P or c_S at x, eq. P44 ([`crate::physics::solver::near_grazing`]), on the
    /// search path.
    pub(super) fn near_grazing(&self, x: &[f64]) -> bool {
        let (c_p, c_s) = self.speeds(x);
        self.problem.predict(x).is_some_and(|k| {
            self.model_phase_speeds(&k)
                .any(|c| crate::physics::solver::near_grazing(c, c_p, c_s))
        })
    }

    /// x with the soil moved to speeds (c_P, c_S), everything else kept; `None` outside the
    /// search box or where no soil has those speeds.
    fn with_speeds(&self, x: &[f64], c_p: f64, c_s: f64) -> Option<Vec<f64>> {
        let (e, nu) = soil_from_speeds(c_p, c_s, self.problem.data.soil_density)?;
        let (e_spec, n_spec) = (&self.problem.specs[self.je], &self.problem.specs[self.jn]);
        let log_e = e_spec.coordinate(e);
        let inside = (e_spec.lower..=e_spec.upper).contains(&log_e)
            && (n_spec.lower..=n_spec.upper).contains(&nu);
        inside.then(|| {
            let mut y = x.to_vec();
            y[self.je] = log_e;
            y[self.jn] = nu;
            y
        })
    }

    /// The contact coefficients the probes try a soil at: x's own ξ, then each face of ξ's
    /// range that is not x's (an optimum often lies on one, and the same point twice would be
    /// solved twice); `[None]` when ξ is not fitted.
    fn contacts(&self, x: &[f64]) -> Vec<Option<f64>> {
        let Some(j) = self.jx else {
            return vec![None];
        };
        let spec = &self.problem.specs[j];
        let mut xis = vec![Some(x[j])];
        for face in [spec.lower, spec.upper] {
            if face != x[j] {
                xis.push(Some(face));
            }
        }
        xis
    }

    /// The model's phase speeds c = ω/Re k (P2), given its wavenumbers k at the measured
    /// frequencies.
    fn model_phase_speeds<'k>(&self, k: &'k [Complex64]) -> impl Iterator<Item = f64> + 'k
    where
        'p: 'k,
    {
        k.iter()
            .zip(&self.problem.data.measurements)
            .map(|(k, m)| m.omega / k.re)
    }

    /// Which frequencies radiate at x, given the model's wavenumbers k there: phase speed (P2)
    /// above c_P (P63).
    fn pattern_of(&self, x: &[f64], k: &[Complex64]) -> Vec<bool> {
        let (c_p, _) = self.speeds(x);
        self.model_phase_speeds(k).map(|c| c > c_p).collect()
    }

    /// The misfit and the pattern at x (one evaluation).
    fn at(&self, x: &[f64]) -> Option<(f64, Vec<bool>)> {
        let k = self.problem.predict(x)?;
        Some((self.problem.objective_of(&k), self.pattern_of(x, &k)))
    }
}

/// The grazing probe: whether a deeper basin lies across a grazing cliff from the best
/// optimum. Where the soil's c_P lies among the measured phase speeds (plastic pipes in stiff
/// soil) the pieces (see [`Pieces`]) are narrow, in c_P and in ξ (which moves the phase
/// speeds), and the DE runs settle in one of them while the piece across a cliff, or the same
/// soil at another ξ, lies deeper (evidence: docs/search.md, "The grazing probe").
///
/// Candidates: the best optimum's soil with c_P at the middle of each gap between the sorted
/// measured phase speeds and just outside their range ([`GRAZING_PROBE_MARGIN`]), c_S kept, at
/// ξ ∈ {the best's, 0, 1}; and the best soil at ξ ∈ [`GRAZING_PROBE_CONTACTS`]. A candidate
/// counts if its misfit is within [`GRAZING_PROBE_GATE`] times the best's and its pattern
/// differs from the best's, or if it is better than the best (then a cliff of another kind,
/// e.g. a change of root, lies between them). The best candidate of
/// each pattern is a start, and the [`GRAZING_PROBE_POLISHES`] best starts are polished, and
/// walked from by the downhill simplex ([`walk`]; the walk's optimum
/// polished in turn). A polish from inside a narrow piece often leaves it downhill, into the
/// basin it came from, where the simplex stays in the piece and follows its edges. (Holding a
/// polish within its start's piece does not mend this: a piece is not always connected, and
/// its walls stop the polish short.)
///
/// Also the best candidate (by the same rule) at the middle in ln c_P of each outer piece, c_S
/// kept: below the measured phase speeds down to c_P = √2 c_S (ν_m = 0), and above them up to
/// c_S/r(ν_max). Where the data fix c_S and leave c_P nearly free, a piece's basin can lie far
/// from its edge, and the polish from just outside the measured speeds stops at the cliff. As
/// a start of its own it does not displace the gaps'; it is polished and walked from in the
/// same way (evidence: docs/search.md, "The grazing probe").
///
/// With `scan`, also the best of the gap scan's starts ([`gap_scan`]), polished and walked
/// from in the same way (the search scans in the probe's first round).
pub(super) fn grazing_probe(
    pieces: &Pieces<'_, '_>,
    bounds: &Bounds,
    best: &Optimum,
    scan: bool,
) -> Vec<(Optimum, bool)> {
    let problem = pieces.problem;
    let Some(k) = problem.predict(&best.x) else {
        return Vec::new();
    };
    let own = pieces.pattern_of(&best.x, &k);
    let jx = pieces.jx;
    let (_, c_s) = pieces.speeds(&best.x);
    let mut v: Vec<f64> = problem
        .data
        .measurements
        .iter()
        .map(|m| m.phase_speed())
        .collect();
    v.sort_by(f64::total_cmp);
    // c_P just outside the range of the measured phase speeds.
    let outside: Vec<f64> = match (v.first(), v.last()) {
        (Some(lo), Some(hi)) => vec![
            lo * (1.0 - GRAZING_PROBE_MARGIN),
            hi * (1.0 + GRAZING_PROBE_MARGIN),
        ],
        _ => Vec::new(),
    };
    let mut targets: Vec<f64> = v.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
    targets.extend(&outside);
    // The middle in ln c_P of each outer piece (every frequency radiates below the measured
    // phase speeds, none above, P63), c_S kept: the piece below reaches down to c_S/r(0) =
    // √2 c_S, the one above up to c_S/r(ν_max), r(ν) = c_S/c_P of P63–P64.
    let nu = (
        problem.specs[pieces.jn].lower,
        problem.specs[pieces.jn].upper,
    );
    let ends = [
        c_s / shear_to_compressional(nu.0),
        c_s / shear_to_compressional(nu.1),
    ];
    let middles: Vec<f64> = outside
        .iter()
        .zip(ends)
        .zip([true, false])
        .filter(|&((&edge, end), below)| end.is_finite() && end > 0.0 && (end < edge) == below)
        .map(|((&edge, end), _)| (edge * end).sqrt())
        .collect();
    let xis = pieces.contacts(&best.x);
    let soil_starts = |targets: &[f64]| -> Vec<Vec<f64>> {
        let mut starts = Vec::new();
        for &c_p in targets {
            let Some(x) = pieces.with_speeds(&best.x, c_p, c_s) else {
                continue;
            };
            for &xi in &xis {
                let mut x = x.clone();
                if let (Some(j), Some(xi)) = (jx, xi) {
                    x[j] = xi;
                }
                starts.push(x);
            }
        }
        starts
    };
    let mut starts = soil_starts(&targets);
    if let Some(j) = jx {
        let (lo, hi) = (problem.specs[j].lower, problem.specs[j].upper);
        for &t in &GRAZING_PROBE_CONTACTS {
            let mut x = best.x.clone();
            x[j] = lo + t * (hi - lo);
            starts.push(x);
        }
    }
    // The best candidate of each pattern.
    let by_pattern = |starts: Vec<Vec<f64>>| {
        let mut by: Vec<(f64, Vec<f64>, Vec<bool>)> = Vec::new();
        for x in starts {
            let Some((f, pattern)) = pieces.at(&x) else {
                continue;
            };
            if !(f <= GRAZING_PROBE_GATE * best.cost && (pattern != own || f < best.cost)) {
                continue;
            }
            match by.iter_mut().find(|(_, _, p)| *p == pattern) {
                Some(c) if f < c.0 => *c = (f, x, pattern),
                Some(_) => {}
                None => by.push((f, x, pattern)),
            }
        }
        by.sort_by(|a, b| a.0.total_cmp(&b.0));
        by
    };
    let mut chosen = by_pattern(starts);
    chosen.truncate(GRAZING_PROBE_POLISHES);
    // The outer pieces' middles compete among themselves, as another start.
    chosen.extend(by_pattern(soil_starts(&middles)).into_iter().take(1));
    if scan {
        // The gap scan's starts compete among themselves, not with the others: a start of the
        // same pattern with the piece's own c_S and ξ is another start.
        // The best's highest model phase speed: its first grazing cliff (P44) as c_P falls.
        let highest = pieces
            .model_phase_speeds(&k)
            .fold(f64::NEG_INFINITY, f64::max);
        let targets = with_distinct(
            gap_scan_targets(&v, &outside, highest),
            above_grazing_targets(pieces, best, &k, c_s),
            GAP_SCAN_OFFSET,
        );
        chosen.extend(
            by_pattern(gap_scan(pieces, &targets, best))
                .into_iter()
                .take(GAP_SCAN_POLISHES),
        );
    }
    chosen
        .into_iter()
        .flat_map(|(f, x, _)| {
            let polished = pieces.polish(bounds, &x);
            let walked = pieces
                .walk(bounds, &x)
                .filter(|o| o.cost < f)
                .map(|o| pieces.polish(bounds, &o.x).unwrap_or((o, false)));
            [polished, walked]
        })
        .flatten()
        .collect()
}

/// The gap scan's targets of c_P, given the sorted measured phase speeds `v`, the grazing
/// probe's two c_P outside their range, and the best's highest model phase speed: each phase
/// speed times 1 ∓ [`GAP_SCAN_OFFSET`], the middle of each gap narrower than twice the offset
/// (which has no such target inside it), the two outside, and `highest` times 1 −
/// [`GAP_SCAN_BELOW_GRAZING`] (when finite).
fn gap_scan_targets(v: &[f64], outside: &[f64], highest: f64) -> Vec<f64> {
    let mut targets: Vec<f64> = v
        .iter()
        .flat_map(|&c| [c * (1.0 - GAP_SCAN_OFFSET), c * (1.0 + GAP_SCAN_OFFSET)])
        .collect();
    targets.extend(
        v.windows(2)
            .filter(|w| w[1] * (1.0 - GAP_SCAN_OFFSET) < w[0] * (1.0 + GAP_SCAN_OFFSET))
            .map(|w| 0.5 * (w[0] + w[1])),
    );
    targets.extend(outside);
    if highest.is_finite() {
        targets.push(highest * (1.0 - GAP_SCAN_BELOW_GRAZING));
    }
    targets
}

/// The gap scan's targets just above each of the best's model phase speeds:
/// c_P = c_i·(1 + [`GAP_SCAN_ABOVE_GRAZING`]) for each frequency i, c_i = ω_i/Re k_i its
/// model phase speed (P2), where that frequency's compressional wave has just stopped radiating
/// (q_P turns evanescent as c_P passes c_i, the grazing cliff of P44). Moving c_P moves c_i
/// too, and a target from the best's c_i alone can fall below the moved c_i, on the side where
/// the frequency still radiates; so the target is found from the best's c_i and then once more
/// from c_i at the moved soil (c_S and the rest of the best kept): one evaluation a frequency.
/// Soils outside the search box give no target (evidence: docs/search.md, "The gap scan's
/// targets (GAP_SCAN_OFFSET, GAP_SCAN_BELOW_GRAZING, GAP_SCAN_ABOVE_GRAZING)").
fn above_grazing_targets(
    pieces: &Pieces<'_, '_>,
    best: &Optimum,
    k: &[Complex64],
    c_s: f64,
) -> Vec<f64> {
    let above = 1.0 + GAP_SCAN_ABOVE_GRAZING;
    pieces
        .model_phase_speeds(k)
        .enumerate()
        .filter_map(|(i, c)| {
            let x = pieces.with_speeds(&best.x, c * above, c_s)?;
            let moved = pieces.problem.predict(&x)?;
            let c = pieces.model_phase_speeds(&moved).nth(i)? * above;
            pieces.with_speeds(&best.x, c, c_s).map(|_| c)
        })
        .collect()
}

/// `targets` and those of `extra` farther than `rtol` (relative) from every one of `targets`.
fn with_distinct(mut targets: Vec<f64>, extra: Vec<f64>, rtol: f64) -> Vec<f64> {
    let n = targets.len();
    for c in extra {
        if targets[..n].iter().all(|t| (t - c).abs() > rtol * c) {
            targets.push(c);
        }
    }
    targets
}

/// The problem with the soil's c_P held: parameters (ln c_S, then ξ when it is fitted), the
/// rest of the best optimum's coordinates kept. Within one piece (see [`Pieces`]) the misfit
/// changes little along c_P, while c_S and ξ, which trade off against each other, set it.
struct HeldCp<'q, 'p, 'a> {
    pieces: &'q Pieces<'p, 'a>,
    base: Vec<f64>,
    c_p: f64,
}

impl HeldCp<'_, '_, '_> {
    fn x(&self, y: &[f64]) -> Option<Vec<f64>> {
        let mut x = self.pieces.with_speeds(&self.base, self.c_p, y[0].exp())?;
        if let (Some(j), Some(&xi)) = (self.pieces.jx, y.get(1)) {
            x[j] = xi;
        }
        Some(x)
    }
}

impl LeastSquares for HeldCp<'_, '_, '_> {
    fn n_params(&self) -> usize {
        1 + usize::from(self.pieces.jx.is_some())
    }
    fn n_residuals(&self) -> usize {
        self.pieces.problem.n_residuals()
    }
    fn residuals(&self, y: &[f64], out: &mut [f64]) -> bool {
        self.x(y)
            .is_some_and(|x| LeastSquares::residuals(self.pieces.problem, &x, out))
    }
    fn residuals_near(&self, base: &[f64], y: &[f64], out: &mut [f64]) -> bool {
        match (self.x(base), self.x(y)) {
            (Some(b), Some(x)) => self.pieces.problem.residuals_near(&b, &x, out),
            _ => false,
        }
    }
    fn near_at(&self, base: &[f64]) -> bool {
        self.x(base)
            .is_some_and(|b| self.pieces.problem.near_at(&b))
    }
}

/// The gap scan: at each c_P of `targets` (taken in ascending order), the best soil's c_S and
/// ξ moved to the bottom of that piece's valley, by Levenberg–Marquardt with c_P held (at most
/// [`GAP_SCAN_ITERATIONS`] iterations, loose tolerances) and c_S kept within ν_m's range at
/// that c_P. For a plastic pipe the data fix c_S to a few per cent and ξ with it, and the
/// valley moves from piece to piece, so the best's own c_S and ξ, moved to another piece, can
/// lie far up its walls.
///
/// Each target starts from the previous one's answer or from the best's own c_S and ξ,
/// whichever fits better there (one evaluation each): the previous answer follows the valley
/// from piece to piece, and the best's own restarts the scan after a piece that fits badly,
/// whose c_S and ξ would otherwise be carried on (evidence: docs/search.md, "The gap scan
/// (gap_scan)").
fn gap_scan(pieces: &Pieces<'_, '_>, targets: &[f64], best: &Optimum) -> Vec<Vec<f64>> {
    let problem = pieces.problem;
    let (_, c_s) = pieces.speeds(&best.x);
    let mut sorted = targets.to_vec();
    sorted.sort_by(f64::total_cmp);
    let mut lower = vec![(c_s / GAP_SCAN_CS_RANGE).ln()];
    let mut upper = vec![(c_s * GAP_SCAN_CS_RANGE).ln()];
    let mut own = vec![c_s.ln()];
    if let Some(j) = pieces.jx {
        lower.push(problem.specs[j].lower);
        upper.push(problem.specs[j].upper);
        own.push(best.x[j]);
    }
    // The previous target's answer.
    let mut last: Option<Vec<f64>> = None;
    let Ok(lm) = LevenbergMarquardt::new()
        .max_iterations(GAP_SCAN_ITERATIONS)
        .and_then(|l| l.ftol(GAP_SCAN_RTOL))
        .and_then(|l| l.xtol(GAP_SCAN_RTOL))
        .map(|l| l.final_jacobian(false))
    else {
        return Vec::new();
    };
    let (nu_lo, nu_hi) = (
        problem.specs[pieces.jn].lower,
        problem.specs[pieces.jn].upper,
    );
    let mut out = Vec::new();
    for c_p in sorted {
        // c_S within ν_m's range at this c_P (P63–P64), where the box projects each start: a
        // start off it would give no soil.
        let (mut l, mut u) = (lower.clone(), upper.clone());
        l[0] = l[0].max((c_p * shear_to_compressional(nu_hi) * (1.0 + 1e-6)).ln());
        u[0] = u[0].min((c_p * shear_to_compressional(nu_lo) * (1.0 - 1e-6)).ln());
        if u[0] <= l[0] {
            continue;
        }
        let Ok(b) = Bounds::new(l, u) else {
            continue;
        };
        let held = HeldCp {
            pieces,
            base: best.x.clone(),
            c_p,
        };
        // From the previous target's answer or the best's own c_S and ξ, whichever fits
        // better here (LM projects a start onto the box).
        let start = match &last {
            None => own.clone(),
            Some(y) => {
                let at = |z: &[f64]| {
                    let mut z = z.to_vec();
                    b.clamp(&mut z);
                    let f = held.x(&z).map_or(f64::INFINITY, |x| problem.value(&x));
                    (f, z)
                };
                let (from_own, from_last) = (at(&own), at(y));
                if from_own.0 < from_last.0 {
                    from_own.1
                } else {
                    from_last.1
                }
            }
        };
        let Ok(r) = lm.minimize(&held, &start, Some(&b)) else {
            continue;
        };
        if !r.cost.is_finite() {
            continue;
        }
        if let Some(x) = held.x(&r.x) {
            out.push(x);
            last = Some(r.x);
        }
    }
    out
}

/// A walk by the downhill simplex from `x`, for the grazing probe's starts:
/// initial steps of [`WALK_STEP`] times each parameter's range, at most
/// [`WALK_EVALUATIONS`], stopping when χ² fell by less than [`WALK_STALL`]`.1` over the last
/// [`WALK_STALL`]`.0` evaluations.
fn walk(problem: &Problem<'_>, bounds: &Bounds, x: &[f64]) -> Option<Optimum> {
    let steps: Vec<f64> = (0..x.len()).map(|j| WALK_STEP * bounds.width(j)).collect();
    let r = NelderMead::new()
        .max_evaluations(WALK_EVALUATIONS)
        .and_then(|s| s.stall(WALK_STALL.0, WALK_STALL.1))
        .and_then(|s| s.minimize(problem, bounds, x, &steps))
        .ok()?;
    Some(Optimum { x: r.x, cost: r.f })
}

/// A walk's initial simplex: steps of this fraction of each parameter's range, for a simplex
/// that follows a grazing cliff's edge (P44) where a polish stopped (evidence: docs/search.md,
/// "The walk (WALK_STEP, WALK_EVALUATIONS, WALK_STALL)").
pub const WALK_STEP: f64 = 1e-2;
/// A walk's budget of evaluations.
pub const WALK_EVALUATIONS: usize = 400;
/// A walk stops when χ² fell by less than `.1` over the last `.0` evaluations: most walks
/// start where a valley ends, and gain nothing, while one along a cliff's edge gains slowly and
/// needs the longer window (evidence: docs/search.md, "The walk (WALK_STEP, WALK_EVALUATIONS,
/// WALK_STALL)").
pub const WALK_STALL: (usize, f64) = (80, 1e-4);

/// The grazing probe's c_P just outside the range of the measured phase speeds, relative.
pub const GRAZING_PROBE_MARGIN: f64 = 0.02;
/// The gap scan's targets of c_P: each measured phase speed times 1 ∓ this (and the
/// grazing probe's two c_P outside their range). A narrow piece often lies right next to a
/// measured phase speed, where one frequency's wave is just grazing (P44), not midway between
/// two. A gap narrower than twice this has no such target inside it, so its middle is a target
/// too: the phase speeds of a metal pipe often lie within 1 % of each other. The middles of
/// wider gaps are not targets (evidence: docs/search.md, "The gap scan's targets
/// (GAP_SCAN_OFFSET, GAP_SCAN_BELOW_GRAZING, GAP_SCAN_ABOVE_GRAZING)").
pub const GAP_SCAN_OFFSET: f64 = 0.004;
/// The gap scan's target just below the best optimum's highest model phase speed, relative.
/// As c_P falls from above every phase speed, that frequency is the first to radiate
/// compressional waves, and just past its grazing point (P44) the misfit can dip in a piece
/// too narrow for the targets next to the measured phase speeds, which the model's may miss by
/// a per cent. The grazing points below it are not targets (evidence: docs/search.md, "The gap
/// scan's targets (GAP_SCAN_OFFSET, GAP_SCAN_BELOW_GRAZING, GAP_SCAN_ABOVE_GRAZING)").
pub const GAP_SCAN_BELOW_GRAZING: f64 = 1e-3;
/// The gap scan's targets just above each of the best's model phase speeds, relative
/// (`above_grazing_targets`); a target within [`GAP_SCAN_OFFSET`] of one of the
/// other targets is dropped. Just past a grazing point (P44) on the side where the frequency's
/// compressional wave no longer radiates, the misfit can dip in a piece 0.2 % wide, which
/// neither the targets next to the measured phase speeds nor the one below the highest model
/// phase speed reach (evidence: docs/search.md, "The gap scan's targets (GAP_SCAN_OFFSET,
/// GAP_SCAN_BELOW_GRAZING, GAP_SCAN_ABOVE_GRAZING)").
pub const GAP_SCAN_ABOVE_GRAZING: f64 = 1e-3;
/// The gap scan's starts polished and walked from, best first, besides the grazing probe's
/// own [`GRAZING_PROBE_POLISHES`].
pub const GAP_SCAN_POLISHES: usize = 1;
/// The gap scan's range of c_S: the best's c_S divided and multiplied by this.
pub const GAP_SCAN_CS_RANGE: f64 = 3.0;
/// Levenberg–Marquardt iterations of the gap scan at each c_P.
pub const GAP_SCAN_ITERATIONS: usize = 20;
/// The gap scan's relative tolerances (LM's ftol and xtol): it only places starts.
pub const GAP_SCAN_RTOL: f64 = 1e-4;

/// The grazing probe's contact coefficients at the best soil, as fractions of ξ's range.
pub const GRAZING_PROBE_CONTACTS: [f64; 11] =
    [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0];
/// Starts of the grazing probe polished and walked from, best first.
pub const GRAZING_PROBE_POLISHES: usize = 2;
/// The grazing probe polishes only starts whose misfit is at most this multiple of the
/// best's: a start further up the landscape seldom leads below the best, and the limit skips
/// most polishes (evidence: docs/search.md, "The grazing probe's gate (GRAZING_PROBE_GATE)").
pub const GRAZING_PROBE_GATE: f64 = 4.0;

/// Relative moves of c_P (c_S and ξ kept) that take an optimum off a grazing cliff.
pub const OFF_CLIFF_STEPS: [f64; 2] = [1e-4, 1e-3];
/// Further moves of c_P, tried after [`OFF_CLIFF_STEPS`] where the reference path has roots at
/// the optimum but not the search path's: near a grazing cliff (P44) the reference path can
/// take another root at a frequency over a wider band of c_P than those moves cross. Where the
/// reference path has no root at the optimum, the fast path's ranking is not trusted and the
/// fit searches again on the safe path (see `fit::run`) unless a move of [`OFF_CLIFF_STEPS`] is
/// confirmed: a longer move there would stand in for that search, and end further from the
/// global optimum (evidence: docs/search.md, "Stepping off a cliff (OFF_CLIFF_STEPS,
/// FURTHER_OFF_CLIFF_STEPS)").
pub const FURTHER_OFF_CLIFF_STEPS: [f64; 2] = [3e-3, 1e-2];

/// Points just off a grazing cliff next to `x`, to be tried in turn. Where χ² falls towards a
/// cliff (see [`Pieces`]) the search's optimum sits on its edge, and there the search path and
/// the reference path can take roots on either side of it. Just off the edge, on the side the
/// search path rates lower, they agree (evidence: docs/search.md, "Stepping off a cliff
/// (OFF_CLIFF_STEPS, FURTHER_OFF_CLIFF_STEPS)"). For each step of [`OFF_CLIFF_STEPS`], and of
/// [`FURTHER_OFF_CLIFF_STEPS`] when `rooted` (the reference path has roots at `x`), the side
/// the search path rates lower.
pub(super) fn off_cliff(pieces: &Pieces<'_, '_>, x: &[f64], rooted: bool) -> Vec<Vec<f64>> {
    let (c_p, c_s) = pieces.speeds(x);
    let further: &[f64] = if rooted {
        &FURTHER_OFF_CLIFF_STEPS
    } else {
        &[]
    };
    OFF_CLIFF_STEPS
        .iter()
        .chain(further)
        .filter_map(|&step| {
            [-step, step]
                .into_iter()
                .filter_map(|s| pieces.with_speeds(x, c_p * (1.0 + s), c_s))
                .map(|y| (pieces.problem.value(&y), y))
                .filter(|(f, _)| f.is_finite())
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, y)| y)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::invert::FitSettings;
    use crate::synth::bench::{bench_network, MaterialMix};

    /// The problem of the default fit.
    fn default_fit_problem(data: &crate::invert::SegmentData) -> Problem<'_> {
        let s = FitSettings::default();
        Problem::new(data, s.method, s.model, s.contact_mode, &s.effects)
    }

    /// The data of segment `id` of the 200-segment bench network of `seed`.
    fn bench_segment(seed: u64, mix: MaterialMix, id: &str) -> crate::invert::SegmentData {
        bench_network(200, seed, mix)
            .into_iter()
            .find(|s| s.id == id)
            .expect("segment")
            .data
    }

    /// The lowest misfit a probe found (∞ when it found nothing).
    fn lowest(found: &[(Optimum, bool)]) -> f64 {
        found
            .iter()
            .map(|(o, _)| o.cost)
            .fold(f64::INFINITY, f64::min)
    }

    /// The candidate polish from the soil with speeds (c_P, c_S) at contact ξ.
    fn polished_from(
        pieces: &Pieces<'_, '_>,
        bounds: &Bounds,
        c_p: f64,
        c_s: f64,
        xi: f64,
    ) -> Optimum {
        let x = pieces
            .with_speeds(&[8.0, 0.3, xi], c_p, c_s)
            .expect("inside");
        polish(pieces.problem, &x, bounds, POLISH_ITERATIONS)
            .expect("polish")
            .0
    }

    /// The optimum a test starts from: `x` with its misfit on the search path, which must be
    /// `expected` (to 1e-3), so that a changed model or dataset shows here and not as a
    /// probe's failure.
    fn optimum_at(p: &Problem<'_>, x: Vec<f64>, expected: f64) -> Optimum {
        let cost = p.value(&x);
        assert!((cost - expected).abs() < 1e-3, "{cost} against {expected}");
        Optimum { x, cost }
    }

    /// A soil moved to given speeds has those speeds (P63–P64 inverted), keeps ξ, and is
    /// refused outside the search box or where no soil has them (c_P ≤ c_S √(4/3)).
    #[test]
    fn a_soil_moved_to_given_speeds_has_them_and_stays_in_the_box() {
        let data = crate::bench::paper_case_data();
        let p = default_fit_problem(&data);
        let pieces = Pieces::new(&p).expect("soil parameters");
        let x = vec![8.0, 0.3, 0.4];
        let (c_p, c_s) = pieces.speeds(&x);
        let y = pieces.with_speeds(&x, 1.5 * c_p, c_s).expect("inside");
        let (c_p2, c_s2) = pieces.speeds(&y);
        assert!(
            (c_p2 / (1.5 * c_p) - 1.0).abs() < 1e-12,
            "{c_p2} vs {}",
            1.5 * c_p
        );
        assert!((c_s2 / c_s - 1.0).abs() < 1e-12, "{c_s2} vs {c_s}");
        assert_eq!(y[2], x[2]);
        assert!(y[1] > x[1], "a higher c_P at the same c_S is a higher ν_m");
        assert!(pieces.with_speeds(&x, 1.1 * c_s, c_s).is_none());
        assert!(pieces.with_speeds(&x, 1e3 * c_p, 1e3 * c_s).is_none());
    }

    /// The points off a cliff keep c_S and ξ and move c_P by each step of
    /// [`OFF_CLIFF_STEPS`], on one side or the other, and by the
    /// [`FURTHER_OFF_CLIFF_STEPS`] too only where the reference path has roots.
    #[test]
    fn points_off_a_cliff_move_only_c_p_by_the_steps() {
        let data = crate::bench::paper_case_data();
        let p = default_fit_problem(&data);
        let pieces = Pieces::new(&p).expect("soil parameters");
        let x = vec![8.0, 0.3, 0.4];
        let (c_p, c_s) = pieces.speeds(&x);
        for rooted in [false, true] {
            let points = off_cliff(&pieces, &x, rooted);
            let steps: Vec<f64> = if rooted {
                OFF_CLIFF_STEPS
                    .iter()
                    .chain(&FURTHER_OFF_CLIFF_STEPS)
                    .copied()
                    .collect()
            } else {
                OFF_CLIFF_STEPS.to_vec()
            };
            assert_eq!(points.len(), steps.len());
            for (y, step) in points.iter().zip(steps) {
                let (c_p2, c_s2) = pieces.speeds(y);
                assert!(((c_p2 / c_p - 1.0).abs() / step - 1.0).abs() < 1e-6);
                assert!((c_s2 / c_s - 1.0).abs() < 1e-12);
                assert_eq!(y[2], x[2]);
            }
        }
    }

    /// An MDPE pipe of a plastic-heavy bench network, where a search without the gap scan
    /// ended (χ² 15.80, c_P 3,676 m/s, c_S 164 m/s, ξ 0.65): the
    /// exhaustive search's piece lies between the measured phase speeds 490 and 494 m/s at
    /// c_S 161 m/s and ξ 0.87 (χ² 14.68). The grazing probe's own starts keep the best's c_S
    /// and try three ξ, and reach no lower than 15.5; the gap scan's start there reaches
    /// within 0.1 of it. Each of the scan's starts has c_P at its target and fits at least as
    /// well as the best's own c_S and ξ moved there.
    #[test]
    fn the_gap_scan_finds_a_narrow_piece_at_its_own_shear_speed_and_contact() {
        let data = bench_segment(848857, MaterialMix::PlasticHeavy, "WM10084");
        let p = default_fit_problem(&data);
        let bounds = p.bounds().expect("bounds");
        let pieces = Pieces::new(&p).expect("soil parameters");
        let polished = polished_from(&pieces, &bounds, 3676.5, 164.3, 0.651);
        assert!((polished.cost - 15.795).abs() < 0.01, "{}", polished.cost);
        let plain = lowest(&grazing_probe(&pieces, &bounds, &polished, false));
        assert!(plain > 15.5, "without the scan: {plain}");
        let scanning = lowest(&grazing_probe(&pieces, &bounds, &polished, true));
        assert!(scanning < 14.677 + 0.1, "with the scan: {scanning}");

        let targets = [480.0, 492.3, 530.0];
        let starts = gap_scan(&pieces, &targets, &polished);
        assert_eq!(starts.len(), targets.len());
        let (_, c_s) = pieces.speeds(&polished.x);
        for (y, &c_p) in starts.iter().zip(&targets) {
            assert!((pieces.speeds(y).0 / c_p - 1.0).abs() < 1e-9);
            let moved = pieces.with_speeds(&polished.x, c_p, c_s).expect("inside");
            assert!(p.value(y) <= p.value(&moved), "at c_P {c_p}");
        }
        let at_piece = p.value(&starts[1]);
        assert!(at_piece < 14.8, "the piece's valley: {at_piece}");
    }

    /// A ductile-iron pipe of a bench network, where a search without the gap scan
    /// ended: χ² 5.32 on ν_m's upper bound (c_P 1,370 m/s, c_S 61.2 m/s, ξ 0.36).
    /// The exhaustive search's 3.63 is on the bound too, at c_P 1,342 m/s (just below the
    /// highest measured phase speed, 1,343.5 m/s), c_S 59.95 m/s, ξ 0.34. At a c_P below the
    /// best's its c_S would need ν_m above the bound, so the scan starts each target within ν_m's
    /// range; a start outside it gives no soil, and every target after the first failed.
    #[test]
    fn the_gap_scan_keeps_the_soil_in_the_box_on_the_incompressible_bound() {
        let data = bench_segment(848854, MaterialMix::Default, "WM10027");
        let p = default_fit_problem(&data);
        let bounds = p.bounds().expect("bounds");
        let pieces = Pieces::new(&p).expect("soil parameters");
        let best = polished_from(&pieces, &bounds, 1370.5, 1370.5 / 22.38, 0.363);
        assert!((best.cost - 5.315).abs() < 0.01, "{}", best.cost);
        assert!(
            best.x[1] >= p.specs[1].upper - 1e-9,
            "on the bound: {}",
            best.x[1]
        );
        let mut v: Vec<f64> = data.measurements.iter().map(|m| m.phase_speed()).collect();
        v.sort_by(f64::total_cmp);
        let targets = gap_scan_targets(&v, &[], f64::NAN);
        let starts = gap_scan(&pieces, &targets, &best);
        assert_eq!(starts.len(), targets.len(), "every target gives a start");
        let best_start = starts
            .iter()
            .map(|y| p.value(y))
            .fold(f64::INFINITY, f64::min);
        assert!(best_start < 3.632 + 0.1, "{best_start}");
        let reached = lowest(&grazing_probe(&pieces, &bounds, &best, true));
        assert!(reached < 3.632 + 0.01, "{reached}");
    }

    /// The scan's targets: 0.4 % either side of each measured phase speed, the middle of the
    /// one gap narrower than 0.8 % (none in the wide one), the two outside, and 0.1 % below the
    /// highest model phase speed.
    #[test]
    fn the_gap_scan_targets_a_narrow_gap_and_just_below_the_first_grazing_point() {
        let mut t = gap_scan_targets(&[100.0, 100.5, 110.0], &[98.0, 112.2], 105.0);
        t.sort_by(f64::total_cmp);
        let expected = [
            98.0, 99.6, 100.098, 100.25, 100.4, 100.902, 104.895, 109.56, 110.44, 112.2,
        ];
        assert_eq!(t.len(), expected.len(), "{t:?}");
        for (a, b) in t.iter().zip(expected) {
            assert!((a - b).abs() < 1e-9, "{t:?}");
        }
        assert_eq!(gap_scan_targets(&[100.0], &[], f64::NAN).len(), 2);
    }

    /// A soil is tried at its own ξ and at each face of ξ's range, a face it lies on only once.
    #[test]
    fn the_contacts_tried_hold_no_point_twice() {
        let data = bench_segment(848920, MaterialMix::PlasticHeavy, "WM10332");
        let p = default_fit_problem(&data);
        let pieces = Pieces::new(&p).expect("soil parameters");
        let j = pieces.jx.expect("ξ is fitted");
        let (lo, hi) = (p.specs[j].lower, p.specs[j].upper);
        let at = |xi: f64| {
            let mut x = vec![7.8, 0.3, 0.0];
            x[j] = xi;
            pieces.contacts(&x)
        };
        assert_eq!(at(0.4), [Some(0.4), Some(lo), Some(hi)]);
        assert_eq!(at(lo), [Some(lo), Some(hi)]);
        assert_eq!(at(hi), [Some(hi), Some(lo)]);
    }

    /// Targets from elsewhere join the scan's only where none of its own lies within the
    /// tolerance; they are not compared among themselves.
    #[test]
    fn only_distinct_targets_join_the_scan() {
        let t = with_distinct(vec![100.0, 200.0], vec![100.3, 100.5, 100.5, 150.0], 4e-3);
        assert_eq!(t, [100.0, 200.0, 100.5, 100.5, 150.0]);
        assert_eq!(with_distinct(vec![], vec![1.0], 4e-3), [1.0]);
    }

    /// An MDPE pipe of a plastic-heavy bench network and the soil where a search without the
    /// targets above grazing ended there (χ² 14.38, c_P 366.4 m/s).
    fn wm10332_search_optimum() -> (crate::invert::SegmentData, Vec<f64>) {
        let data = bench_segment(848920, MaterialMix::PlasticHeavy, "WM10332");
        let x = vec![
            58807004.54709561_f64.log10(),
            0.4545205189982146,
            0.2365922164449546,
        ];
        (data, x)
    }

    /// On that MDPE pipe, from the soil where the search ended (χ² 14.38, c_P 366.4 m/s), the fourth
    /// frequency's target lands in the dip just above its model phase speed, 0.2 % wide, where
    /// the best's own c_S and ξ already fit at 11.25; the targets next to the measured phase
    /// speeds 442.5 and 458.9 m/s lie outside it.
    #[test]
    fn a_target_lands_just_above_a_model_phase_speed() {
        let (data, x) = wm10332_search_optimum();
        let p = default_fit_problem(&data);
        let pieces = Pieces::new(&p).expect("soil parameters");
        let best = Optimum {
            cost: p.value(&x),
            x,
        };
        assert!((best.cost - 14.377).abs() < 0.01, "{}", best.cost);
        let k = p.predict(&best.x).expect("roots");
        let (_, c_s) = pieces.speeds(&best.x);
        let targets = above_grazing_targets(&pieces, &best, &k, c_s);
        assert_eq!(targets.len(), data.measurements.len());
        let fit_at = |c_p: f64| p.value(&pieces.with_speeds(&best.x, c_p, c_s).expect("soil"));
        let lowest = targets
            .iter()
            .map(|&c| fit_at(c))
            .fold(f64::INFINITY, f64::min);
        assert!(lowest < 11.5, "{lowest}: {targets:?}");
        for c in [
            442.5 * (1.0 + GAP_SCAN_OFFSET),
            458.86 * (1.0 - GAP_SCAN_OFFSET),
        ] {
            assert!(fit_at(c) > 14.0, "{c}: {}", fit_at(c));
        }
    }

    /// `near_grazing` is the root flag of P44 at the search path's roots: on that MDPE pipe's
    /// search optimum above (c_P 366.4 m/s, its highest model phase speed more than 10 % above c_P and
    /// c_S) no frequency is within 2 % of c_P or c_S; with c_P moved to 1 % above the highest
    /// model phase speed one is, and at 5 % above none is.
    #[test]
    fn near_grazing_is_a_model_phase_speed_within_two_percent_of_a_soil_speed() {
        let (data, x) = wm10332_search_optimum();
        let p = default_fit_problem(&data);
        let pieces = Pieces::new(&p).expect("soil parameters");
        assert!(!pieces.near_grazing(&x));
        let (c_p, c_s) = pieces.speeds(&x);
        let k = p.predict(&x).expect("roots");
        let highest = pieces
            .model_phase_speeds(&k)
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(
            highest > 1.1 * c_p && highest > 1.1 * c_s,
            "{highest} {c_p} {c_s}"
        );
        let moved = |r: f64| pieces.with_speeds(&x, highest * r, c_s).expect("soil");
        assert!(pieces.near_grazing(&moved(1.01)));
        assert!(!pieces.near_grazing(&moved(1.05)));
    }

    /// A start is the same to the bit in the same box: once per start the work runs, and
    /// another box or another bit pattern (−0 against +0) runs it again.
    #[test]
    fn a_start_is_polished_or_walked_once_per_box() {
        let trodden: Trodden<usize> = Trodden::new();
        let unit = Bounds::new(vec![0.0, 0.0], vec![1.0, 1.0]).expect("box");
        let wide = Bounds::new(vec![0.0, 0.0], vec![2.0, 1.0]).expect("box");
        let runs = std::cell::Cell::new(0);
        let run = || {
            runs.set(runs.get() + 1);
            runs.get()
        };
        assert_eq!(trodden.from(&[0.5, 0.0], &unit, run), 1);
        assert_eq!(trodden.from(&[0.5, 0.0], &unit, run), 1);
        assert_eq!(trodden.from(&[0.5, -0.0], &unit, run), 2);
        assert_eq!(trodden.from(&[0.5, 0.0], &wide, run), 3);
        assert_eq!(trodden.from(&[0.5, 0.0], &unit, run), 1);
        assert_eq!(runs.get(), 3);
    }

    /// The grazing probe from a best that did not move (a later round, or the scan again near
    /// grazing) finds what it found before without polishing or walking again: on an MDPE pipe
    /// of a plastic-heavy bench network, from the best its first round leaves, the probe
    /// polishes and walks from two starts near grazing (573 evaluations), and the second time
    /// costs only the ranking of its starts (39, one evaluation each).
    #[test]
    fn the_grazing_probe_again_from_the_same_best_polishes_and_walks_nothing_again() {
        let data = bench_segment(849902, MaterialMix::PlasticHeavy, "WM10350");
        let p = default_fit_problem(&data);
        let bounds = p.bounds().expect("bounds");
        let best = optimum_at(
            &p,
            vec![8.0229967150674, 0.45142105277041444, 0.11865398556284132],
            9.4915,
        );
        let pieces = Pieces::new(&p).expect("soil parameters");
        // Every optimum the probe returns, to the bit, and whether its polish was capped.
        let found = |found: &[(Optimum, bool)]| -> Vec<(Vec<u64>, u64, bool)> {
            found
                .iter()
                .map(|(o, c)| {
                    let x = o.x.iter().map(|v| v.to_bits()).collect();
                    (x, o.cost.to_bits(), *c)
                })
                .collect()
        };
        let e0 = p.evaluations();
        let first = grazing_probe(&pieces, &bounds, &best, false);
        let e1 = p.evaluations();
        let second = grazing_probe(&pieces, &bounds, &best, false);
        let e2 = p.evaluations();
        assert!(!first.is_empty());
        assert_eq!(found(&first), found(&second));
        assert!(
            e1 - e0 > 500,
            "the first probe polished and walked: {}",
            e1 - e0
        );
        assert!(
            e2 - e1 < 60,
            "the second only ranked its starts: {}",
            e2 - e1
        );
    }
}
