//! The search's coordinates where the data determine the soil: the problem in (ln c_P,
//! r = c_S/c_P, ξ, …) that every other DE run of the default search minimises (`InSpeeds`),
//! and the polishes from the faces of that box at the best optimum (`faces`).
//!
//! χ² jumps where c_P crosses a model phase speed (the cliffs of P44), so in these coordinates
//! the cliffs are (nearly) planes of constant ln c_P, and the misfit is smooth in (r, ξ) between
//! them; the incompressible corner ν_m → ½ is the face r = r_min.

use crate::optimize::{Bounds, Objective};

use super::fit::{polish, Optimum, POLISH_ITERATIONS};
use super::problem::{Param, Problem};
use super::speed::SpeedBox;
use crate::physics::soil::{soil_of, speeds_of};

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
        self.x_within(y, self.region.ln_cp_range_at(y[self.jn])?)
    }

    /// [`Self::x`] of a point of the image only, `None` outside it: the DE's evaluation, which
    /// finds ln c_P's range at r once for both the test and the map.
    fn x_of_image(&self, y: &[f64]) -> Option<Vec<f64>> {
        self.x_within(y, self.region.range_holding(y[self.je], y[self.jn])?)
    }

    /// [`Self::x`] with ln c_P's range at r, (`lo`, `hi`), given.
    fn x_within(&self, y: &[f64], (lo, hi): (f64, f64)) -> Option<Vec<f64>> {
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
        self.x_of_image(y)
            .map_or(f64::INFINITY, |x| self.problem.value(&x))
    }
    fn search_value(&self, y: &[f64]) -> f64 {
        self.x_of_image(y)
            .map_or(f64::INFINITY, |x| self.problem.search_value(&x))
    }
}

/// Step in ln c_P of the line on the face r = r_min past grazing (`faces`): 22 % in c_P.
pub const FACE_LN_CP_STEP: f64 = 0.2;
/// Step in ln c_P of the line's stiffest end, the last [`FACE_STIFF_WIDTH`] below the box's
/// top (0.05 in log10 E_m).
pub const FACE_STIFF_STEP: f64 = 0.0576;
/// An optimum within this fraction of r's or ξ's range of one of its bounds lies on that face.
pub const FACE_ON_BOUND_RTOL: f64 = 1e-9;
/// Width in ln c_P of the line's stiffest end: log10 E_m ≥ 9.7 at ν_m's upper bound.
pub const FACE_STIFF_WIDTH: f64 = 0.345;
/// The line's classes of c_P: past grazing up to this multiple of the mean measured phase
/// speed, and beyond.
pub const FACE_FAR_PAST_GRAZING: f64 = 2.0;
/// The line along the face r = r_max below grazing reaches down to the mean measured phase
/// speed divided by this.
pub const FACE_BELOW_SPAN: f64 = 8.0;
/// Local minima of that line polished at most.
pub const FACE_BELOW_STARTS: usize = 2;
/// Step in ln c_P of the line at constant c_S from the face's minima at the weakest contact
/// (5 % in c_P).
pub const FACE_SHEAR_LINE_STEP: f64 = 0.05;
/// That line's best point is polished only when its misfit is at most this multiple of the
/// best optimum's: a start well above the best seldom polishes below it. The value is the
/// grazing probe's (`probes::GRAZING_PROBE_GATE`), not tuned for this line; without the gate
/// the line costs about 2.5 % more evaluations a fit and mended no more (evidence:
/// docs/search.md, "The faces in speed coordinates").
pub const FACE_SHEAR_LINE_GATE: f64 = 4.0;
/// The best of the stiffest end is polished only when its misfit is at most this multiple of
/// the best optimum's.
pub const FACE_STIFF_GATE: f64 = 2.0;

/// The faces of the box in the speed coordinates at the best optimum: bounded
/// Levenberg–Marquardt polishes
///
/// * from its soil at the same c_P moved to r = r_min (ν_m → ½, the incompressible face: the
///   fluid-like end of a valley of constant c_P, c_S → 0), and, when it lies on that face, to
///   r = r_max (ν_m = 0: the valley's other end; the data of a metal pipe fix c_P and barely
///   c_S, so χ² changes little along the valley, and a polish from one end does not cross it;
///   evidence: docs/search.md, "The faces in speed coordinates");
/// * when it lies on a face of ξ, from its soil at the opposite face (ξ enters the soil's
///   stiffness as a weight, §4.10, so a misfit falling towards one face can have a deeper
///   basin at the other);
/// * from the best point of each class of a line along the face r = r_min past grazing (c_P
///   above the mean measured phase speed v̄, where compressional radiation switches off, model
///   §7.8 item 3, P44), at ξ ∈ {its own, 0, 1}: c_P up to [`FACE_FAR_PAST_GRAZING`] v̄, above
///   it, and the stiffest end of the box (gated by [`FACE_STIFF_GATE`]). Those basins are
///   narrow in r (c_P² ∝ 1/(1 − 2ν_m)) and in c_P, and a population seldom lands in them;
/// * from the best [`FACE_BELOW_STARTS`] local minima of a line along the face r = r_max
///   below grazing (c_P from v̄/[`FACE_BELOW_SPAN`] to v̄, where every soil wave radiates),
///   each point the best over the same values of ξ. Towards ξ = 0 the shear coupling fades,
///   and where the data fix c_P (metal pipes) the misfit depends on c_P nearly alone; its
///   basins along c_P lie far from the best optimum's c_P, where no other start reaches them;
/// * at the weakest contact (ξ at its lower bound), from the best point of a line at constant
///   c_S that starts at each of the best [`FACE_BELOW_STARTS`] local minima of that ξ's own line
///   along the face r = r_max and rises in c_P (r falling) every [`FACE_SHEAR_LINE_STEP`] up
///   to v̄, where that point is below its start (gated by [`FACE_SHEAR_LINE_GATE`]). Where the
///   data fix c_S (plastic pipes, P47) and the contact is weak, the valley runs along constant
///   c_S, below the measured phase speeds and narrow in ξ, and the face r = r_max meets it only
///   at its soft end, far up its walls (evidence: docs/search.md, "The faces in speed
///   coordinates"). The line starts from ξ's own minima, not the best over ξ: at another ξ the
///   valley lies at another c_S.
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
    let (r_min, r_max) = speeds.region.r_range();
    let y_best = speeds.y(&best.x);
    let mut starts: Vec<Vec<f64>> = Vec::new();
    let mut y = y_best.clone();
    y[jn] = r_min;
    starts.extend(speeds.x(&y));
    if let (true, Some((lo, hi))) = (
        y_best[jn] <= r_min + FACE_ON_BOUND_RTOL * (r_max - r_min),
        speeds.region.ln_cp_range_at(r_max),
    ) {
        // On the face r = r_min: the valley's other end, c_P kept as far as the box allows.
        let mut y = y_best.clone();
        (y[je], y[jn]) = (y_best[je].clamp(lo, hi), r_max);
        starts.extend(speeds.x(&y));
    }
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
    // The soil with ln c_P = l, c_S/c_P = r and ξ (the best's where `None`), with its misfit;
    // `None` where it has none.
    let at = |l: f64, r: f64, xi: Option<f64>| -> Option<(f64, Vec<f64>)> {
        let mut y = y_best.clone();
        (y[je], y[jn]) = (l, r);
        if let (Some(j), Some(xi)) = (jx, xi) {
            y[j] = xi;
        }
        let x = speeds.x(&y)?;
        let f = problem.value(&x);
        f.is_finite().then_some((f, x))
    };
    let over_xi = |l: f64, r: f64| -> Vec<_> { xis.iter().map(|&xi| at(l, r, xi)).collect() };
    // The lowest of some soils (the first of equals).
    let lowest = |p: &[Option<(f64, Vec<f64>)>]| {
        p.iter()
            .flatten()
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .cloned()
    };
    let best_over_xi = |l: f64, r: f64| lowest(&over_xi(l, r));
    if let (true, Some((_, top))) = (v > 0.0, speeds.region.ln_cp_range_at(r_min)) {
        // The best point of each class: [up to FACE_FAR_PAST_GRAZING v̄, beyond, stiffest].
        let mut best_of: [Option<(f64, Vec<f64>)>; 3] = [None, None, None];
        let mut rate = |l: f64, class: usize| {
            if let Some((f, x)) = best_over_xi(l, r_min) {
                if best_of[class].as_ref().is_none_or(|(g, _)| f < *g) {
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
    if let (true, Some((bottom, top))) = (v > 0.0, speeds.region.ln_cp_range_at(r_max)) {
        // The line along the face r = r_max below grazing, every FACE_LN_CP_STEP from just
        // below v̄ down to v̄/FACE_BELOW_SPAN; its local minima, best first.
        let (mut ls, mut grid) = (Vec::new(), Vec::new());
        let mut l = (v.ln() - 0.5 * FACE_LN_CP_STEP).min(top);
        while l >= (v / FACE_BELOW_SPAN).ln().max(bottom) {
            grid.push(over_xi(l, r_max));
            ls.push(l);
            l -= FACE_LN_CP_STEP;
        }
        let line: Vec<_> = grid.iter().map(|at| lowest(at)).collect();
        let minima_of = |f: &dyn Fn(usize) -> f64| {
            let mut minima: Vec<usize> = (0..ls.len())
                .filter(|&i| f(i).is_finite() && f(i) <= f(i + 1) && (i == 0 || f(i) <= f(i - 1)))
                .collect();
            minima.sort_by(|&a, &b| f(a).total_cmp(&f(b)));
            minima.truncate(FACE_BELOW_STARTS);
            minima
        };
        let f = |i: usize| {
            line.get(i)
                .and_then(Option::as_ref)
                .map_or(f64::INFINITY, |p| p.0)
        };
        starts.extend(
            minima_of(&f)
                .into_iter()
                .filter_map(|i| line[i].as_ref().map(|(_, x)| x.clone())),
        );
        // At the weakest contact (ξ at its lower bound), from the local minima of that ξ's own
        // line, the line of their c_S up to just below v̄ (r falls as c_P rises); its lowest
        // point where it is below its start and within FACE_SHEAR_LINE_GATE of the best.
        let weak = jx.and_then(|j| {
            xis.iter()
                .position(|xi| xi.unwrap_or(best.x[j]) == bounds.lower()[j])
        });
        if let Some(k) = weak {
            let fk = |i: usize| {
                grid.get(i)
                    .and_then(|p| p[k].as_ref())
                    .map_or(f64::INFINITY, |p| p.0)
            };
            for i in minima_of(&fk) {
                let ln_cs = ls[i] + r_max.ln();
                let (mut on, mut l) = (Vec::new(), ls[i] + FACE_SHEAR_LINE_STEP);
                while l < v.ln() && (ln_cs - l).exp() >= r_min {
                    on.push(at(l, (ln_cs - l).exp(), xis[k]));
                    l += FACE_SHEAR_LINE_STEP;
                }
                let worth = |g: f64| g < fk(i) && g <= FACE_SHEAR_LINE_GATE * best.cost;
                starts.extend(lowest(&on).filter(|(g, _)| worth(*g)).map(|(_, x)| x));
            }
        }
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
