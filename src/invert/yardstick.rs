//! An independent yardstick of the segment search: a dense grid over the soil in the
//! coordinates the data determine, (ln c_P, r = c_S/c_P) ([`super::speed`]), by the contact
//! coefficient ξ, its best local minima polished by Levenberg–Marquardt and rated on the
//! reference path. It shares no code with the search (no differential evolution, no probe, not
//! the search's polish): only the objective ([`Problem`]) and the generic Levenberg–Marquardt
//! solver. `pipewave bench --verify` judges the default fit against it.
//!
//! The grid, over the image of the search box (P51) only:
//!
//! * ln c_P every [`LN_CP_STEP`] from the lower end of the box's ln c_P range, plus the points at
//!   ⅛, ½ and ⅞ of each gap between consecutive measured phase speeds ([`GAP_FRACTIONS`]).
//!   χ² jumps where c_P crosses a model phase speed (the cliffs of P44), and near an optimum the
//!   model phase speeds lie near the measured ones, so each gap holds its own piece of the
//!   misfit surface, often narrower than the regular spacing;
//! * [`R_POINTS`] values of r, evenly spaced from r(ν_m = 0.499) to 1/√2 (both faces included);
//! * ξ at [`XI_POINTS`] evenly spaced values from 0 to 1 (both faces included).
//!
//! Inside the gaps the pieces are also narrow in r and ξ (both move the model phase speeds
//! across c_P), so the gap points get a finer grid of their own: [`GAP_R_POINTS`] values of r
//! by [`GAP_XI_POINTS`] of ξ. On a 4–8-frequency segment and ρ_m near 1,900 kg/m³ that is about
//! 58,000 points of the regular grid (201 values of ln c_P lie inside the box at each r) and
//! 3,200 fine points per gap.
//!
//! A grid minimum is a point whose misfit is below that of each of its up to 26 neighbours in
//! the grid (ties broken by position). The [`POLISHED`] best minima of both grids are polished
//! by Levenberg–Marquardt in the search coordinates (so the polish stays in the search box, up
//! to its faces), with central differences and up to [`POLISH_ITERATIONS`] iterations, and each
//! polished point and its grid point are rated on the reference path (model §5.3–5.4). An
//! optimum on a cliff's edge (P44) stops the polish short, its finite differences crossing the
//! cliff; so the [`ZOOMED`] best rated points are also zoomed into by a derivative-free pattern
//! search in (ln c_P, r, ξ) (`zoom`) and rated. The yardstick is the lowest of those misfits.

use crate::optimize::{Bounds, FiniteDifference, LevenbergMarquardt, Objective};

use super::problem::{Method, Param, Problem, Scale, SegmentData};
use super::speed::SpeedBox;
use super::FitSettings;
use crate::physics::soil::soil_of;

/// Spacing of the regular grid in ln c_P (4 % in c_P).
pub const LN_CP_STEP: f64 = 0.04;
/// Where in each gap between consecutive measured phase speeds the grid has a value of c_P,
/// as fractions of the gap.
pub const GAP_FRACTIONS: [f64; 3] = [0.125, 0.5, 0.875];
/// Values of r = c_S/c_P of the regular grid.
pub const R_POINTS: usize = 48;
/// Values of ξ of the regular grid (0, 0.2, …, 1).
pub const XI_POINTS: usize = 6;
/// Values of r at the gap points.
pub const GAP_R_POINTS: usize = 96;
/// Values of ξ at the gap points (0, 0.1, …, 1).
pub const GAP_XI_POINTS: usize = 11;
/// Grid minima polished.
pub const POLISHED: usize = 12;
/// Levenberg–Marquardt iterations of each polish at most.
pub const POLISH_ITERATIONS: usize = 150;
/// Best rated points zoomed into (`zoom`).
pub const ZOOMED: usize = 4;
/// Levels of the zoom.
pub const ZOOM_LEVELS: usize = 8;
/// The zoom's first steps in (ln c_P, r, ξ).
pub const ZOOM_STEPS: [f64; 3] = [0.01, 0.01, 0.05];

/// Why the yardstick cannot rate a segment.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum YardstickError {
    /// The yardstick grids the soil and the contact only.
    #[error(
        "the yardstick covers the default method without effects (E_m, nu_m and the contact only)"
    )]
    Unsupported,
    /// The segment has no measurements.
    #[error("no measurements for this segment")]
    NoMeasurements,
    /// No grid point gave a finite misfit.
    #[error("the forward model solves at no point of the grid")]
    NoFiniteGridPoint,
    /// The reference path solves at no candidate.
    #[error("the reference path solves at none of the {0} candidates")]
    NoReferenceRoot(usize),
}

/// What the yardstick found for one segment.
#[derive(Debug, Clone, PartialEq)]
pub struct Yardstick {
    /// The lowest misfit on the reference path (χ², or the relative squares without stds).
    pub misfit: f64,
    /// Where, in the search coordinates (log10 E_m, ν_m, ξ).
    pub x: Vec<f64>,
    /// Grid points evaluated (both grids).
    pub grid_points: usize,
    /// Forward evaluations on the search path (grid and polishes).
    pub evaluations: usize,
    /// Grid minima polished.
    pub polished: usize,
}

/// One grid: its axes and the misfit at each point (NaN outside the search box).
struct Grid {
    ln_cp: Vec<f64>,
    r: Vec<f64>,
    xi: Vec<f64>,
    value: Vec<f64>,
}

impl Grid {
    fn index(&self, i: usize, j: usize, k: usize) -> usize {
        (i * self.r.len() + j) * self.xi.len() + k
    }

    /// Evaluate the misfit at every point of the axes inside the box.
    fn evaluate(
        problem: &Problem<'_>,
        region: &SpeedBox,
        ln_cp: Vec<f64>,
        r: Vec<f64>,
        xi: Vec<f64>,
    ) -> Grid {
        let mut value = vec![f64::NAN; ln_cp.len() * r.len() * xi.len()];
        let mut g = Grid {
            ln_cp,
            r,
            xi,
            value: Vec::new(),
        };
        for (i, &l) in g.ln_cp.iter().enumerate() {
            for (j, &r) in g.r.iter().enumerate() {
                if !region.contains(l, r) {
                    continue;
                }
                let Some(x0) = coordinates(region, l, r, 0.0) else {
                    continue;
                };
                for (k, &xi) in g.xi.iter().enumerate() {
                    let mut x = x0.clone();
                    x[2] = xi;
                    let idx = (i * g.r.len() + j) * g.xi.len() + k;
                    value[idx] = problem.value(&x);
                }
            }
        }
        g.value = value;
        g
    }

    /// Points evaluated.
    fn evaluated(&self) -> usize {
        self.value.iter().filter(|v| !v.is_nan()).count()
    }

    /// The local minima: (misfit, ln c_P, r, ξ) of every finite point below each evaluated
    /// neighbour (ties broken by position in the grid).
    fn minima(&self) -> Vec<(f64, f64, f64, f64)> {
        let (ni, nj, nk) = (self.ln_cp.len(), self.r.len(), self.xi.len());
        let near = |a: usize, n: usize| a.saturating_sub(1)..(a + 2).min(n);
        let mut out = Vec::new();
        for i in 0..ni {
            for j in 0..nj {
                for k in 0..nk {
                    let p = self.index(i, j, k);
                    let v = self.value[p];
                    if !v.is_finite() {
                        continue;
                    }
                    let mut lowest = true;
                    'n: for a in near(i, ni) {
                        for b in near(j, nj) {
                            for c in near(k, nk) {
                                let q = self.index(a, b, c);
                                let w = self.value[q];
                                if q != p && (w < v || (w == v && q < p)) {
                                    lowest = false;
                                    break 'n;
                                }
                            }
                        }
                    }
                    if lowest {
                        out.push((v, self.ln_cp[i], self.r[j], self.xi[k]));
                    }
                }
            }
        }
        out
    }
}

/// The search coordinates (log10 E_m, ν_m, ξ) of the soil (ln c_P, r) at contact ξ; `None`
/// where r gives no Poisson's ratio.
fn coordinates(region: &SpeedBox, ln_cp: f64, r: f64, xi: f64) -> Option<Vec<f64>> {
    let (e, nu) = soil_of(ln_cp, r, region.rho)?;
    Some(vec![
        e.log10().clamp(region.e.0.log10(), region.e.1.log10()),
        nu.clamp(region.nu.0, region.nu.1),
        xi,
    ])
}

/// `n` evenly spaced values from `lo` to `hi`, both included.
fn even(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| lo + (hi - lo) * i as f64 / (n - 1).max(1) as f64)
        .collect()
}

/// The values of ln c_P at [`GAP_FRACTIONS`] of each gap between consecutive distinct measured
/// phase speeds, inside `range`.
fn gap_points(data: &SegmentData, range: (f64, f64)) -> Vec<f64> {
    let mut c: Vec<f64> = data.measurements.iter().map(|m| m.phase_speed()).collect();
    c.sort_by(f64::total_cmp);
    c.dedup();
    c.windows(2)
        .flat_map(|w| GAP_FRACTIONS.map(|f| (w[0] + f * (w[1] - w[0])).ln()))
        .filter(|l| (range.0..=range.1).contains(l))
        .collect()
}

/// The yardstick of one segment fitted with `settings` (default method, no effects).
pub fn yardstick(data: &SegmentData, settings: &FitSettings) -> Result<Yardstick, YardstickError> {
    if settings.method != Method::Default || !settings.effects.is_empty() {
        return Err(YardstickError::Unsupported);
    }
    if data.measurements.is_empty() {
        return Err(YardstickError::NoMeasurements);
    }
    let problem = Problem::new(
        data,
        Method::Default,
        settings.model,
        settings.contact_mode,
        &[],
    );
    let layout = [Param::SoilModulus, Param::SoilPoisson, Param::Contact];
    let as_expected = problem.specs.len() == 3
        && problem.specs.iter().zip(layout).all(|(s, p)| s.param == p)
        && problem.specs[0].scale == Scale::Log10;
    let bounds = problem.bounds().map_err(|_| YardstickError::Unsupported)?;
    if !as_expected {
        return Err(YardstickError::Unsupported);
    }
    let spec = &problem.specs;
    let region = SpeedBox::new(
        (spec[0].value(spec[0].lower), spec[0].value(spec[0].upper)),
        (spec[1].lower, spec[1].upper),
        data.soil_density,
    );
    let (l_lo, l_hi) = region.ln_cp_range();
    let (r_lo, r_hi) = region.r_range();
    let (x_lo, x_hi) = (spec[2].lower, spec[2].upper);
    let gaps = gap_points(data, (l_lo, l_hi));
    let steps = ((l_hi - l_lo) / LN_CP_STEP).floor() as usize;
    let mut ln_cp: Vec<f64> = (0..=steps)
        .map(|i| l_lo + LN_CP_STEP * i as f64)
        .chain(gaps.iter().copied())
        .collect();
    ln_cp.sort_by(f64::total_cmp);
    ln_cp.dedup();
    let coarse = Grid::evaluate(
        &problem,
        &region,
        ln_cp,
        even(r_lo, r_hi, R_POINTS),
        even(x_lo, x_hi, XI_POINTS),
    );
    let fine = Grid::evaluate(
        &problem,
        &region,
        gaps,
        even(r_lo, r_hi, GAP_R_POINTS),
        even(x_lo, x_hi, GAP_XI_POINTS),
    );
    let grid_points = coarse.evaluated() + fine.evaluated();
    let mut minima = coarse.minima();
    minima.extend(fine.minima());
    minima.sort_by(|a, b| a.0.total_cmp(&b.0));
    minima.dedup_by(|a, b| (a.1, a.2, a.3) == (b.1, b.2, b.3));
    minima.truncate(POLISHED);
    if minima.is_empty() {
        return Err(YardstickError::NoFiniteGridPoint);
    }
    let lm = LevenbergMarquardt::new()
        .max_iterations(POLISH_ITERATIONS)
        .map(|lm| lm.finite_difference(FiniteDifference::Central))
        .map(|lm| lm.final_jacobian(false))
        .map_err(|_| YardstickError::Unsupported)?;
    // Every rated point: (misfit on the reference path, search coordinates).
    let mut rated: Vec<(f64, Vec<f64>)> = Vec::new();
    for &(_, l, r, xi) in &minima {
        let Some(x0) = coordinates(&region, l, r, xi) else {
            continue;
        };
        let polished = lm
            .minimize(&problem, &x0, Some(&bounds))
            .ok()
            .filter(|p| p.cost.is_finite())
            .map(|p| p.x);
        for x in polished.into_iter().chain(std::iter::once(x0)) {
            if let Some(f) = rate(&problem, &bounds, &x) {
                rated.push((f, x));
            }
        }
    }
    // A derivative-free zoom from the best rated points: an optimum on a cliff's edge (P44)
    // stops the polish, whose finite differences cross the cliff, short of it.
    rated.sort_by(|a, b| a.0.total_cmp(&b.0));
    rated.dedup_by(|a, b| a.1 == b.1);
    let starts: Vec<Vec<f64>> = rated.iter().take(ZOOMED).map(|r| r.1.clone()).collect();
    for x0 in starts {
        let x = zoom(&problem, &region, &bounds, &x0);
        if let Some(f) = rate(&problem, &bounds, &x) {
            rated.push((f, x));
        }
    }
    let (misfit, x) = rated
        .into_iter()
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .ok_or(YardstickError::NoReferenceRoot(minima.len()))?;
    Ok(Yardstick {
        misfit,
        x,
        grid_points,
        evaluations: problem.evaluations(),
        polished: minima.len(),
    })
}

/// The lowest point on the search path of a pattern search from `x0` in (ln c_P, r, ξ): at
/// each of [`ZOOM_LEVELS`] levels the best of 5 × 5 × 5 points around the centre at
/// [`ZOOM_STEPS`] (halved at each level, unless the best lies on the pattern's rim), inside the
/// box.
fn zoom(problem: &Problem<'_>, region: &SpeedBox, bounds: &Bounds, x0: &[f64]) -> Vec<f64> {
    let (l0, r0) = crate::physics::soil::speeds_of(10f64.powf(x0[0]), x0[1], region.rho);
    let mut centre = [l0, r0, x0[2]];
    let mut best_x = x0.to_vec();
    let mut best_f = problem.value(x0);
    let mut h = ZOOM_STEPS;
    for _ in 0..ZOOM_LEVELS {
        let mut moved_to = None;
        for a in -2i32..=2 {
            for b in -2i32..=2 {
                for c in -2i32..=2 {
                    let p = [
                        centre[0] + f64::from(a) * h[0],
                        centre[1] + f64::from(b) * h[1],
                        centre[2] + f64::from(c) * h[2],
                    ];
                    if !region.contains(p[0], p[1]) {
                        continue;
                    }
                    let Some(x) = coordinates(region, p[0], p[1], p[2]) else {
                        continue;
                    };
                    if !bounds.contains(&x) {
                        continue;
                    }
                    let f = problem.value(&x);
                    if f < best_f {
                        best_f = f;
                        best_x = x;
                        moved_to = Some((p, a.abs() == 2 || b.abs() == 2 || c.abs() == 2));
                    }
                }
            }
        }
        match moved_to {
            Some((p, true)) => centre = p,
            Some((p, false)) => {
                centre = p;
                h = h.map(|v| 0.5 * v);
            }
            None => h = h.map(|v| 0.5 * v),
        }
    }
    best_x
}

/// The misfit at `x` (inside `bounds`) on the reference path, `None` where it finds no root.
fn rate(problem: &Problem<'_>, bounds: &Bounds, x: &[f64]) -> Option<f64> {
    if !bounds.contains(x) {
        return None;
    }
    let sys = problem.system_at(x)?;
    let k: Vec<_> = problem
        .reference_roots(&sys)?
        .iter()
        .map(|r| r.k1)
        .collect();
    let f = problem.objective_of(&k);
    f.is_finite().then_some(f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::invert::problem::Measurement;
    use crate::physics::soil::speeds_of;
    use crate::physics::solver::{solve_curve, Continuation};
    use crate::physics::{ContactMode, Fluid, Material, Model, Pipe, Soil, System};

    /// Noise-free measurements of a pipe in a known soil (reference path), with stated
    /// standard deviations of 1 % on Re k and 5 % on the attenuation: the truth is an optimum
    /// with χ² = 0.
    fn noise_free(pipe: Pipe, material: Material, soil: Soil, xi: f64, hz: &[f64]) -> SegmentData {
        let sys = System::new(
            Fluid::water(),
            pipe,
            soil,
            xi,
            Model::Full,
            ContactMode::Reciprocal,
        )
        .expect("a system");
        let omegas: Vec<f64> = hz.iter().map(|f| std::f64::consts::TAU * f).collect();
        let measurements = solve_curve(&sys, &omegas, Continuation::default())
            .into_iter()
            .zip(&omegas)
            .map(|(r, &w)| {
                let k = r.expect("a root").k1;
                Measurement::new(w, k.re, -k.im, Some(0.01 * k.re), Some(0.05 * -k.im))
                    .expect("valid")
            })
            .collect();
        SegmentData {
            fluid: Fluid::water(),
            pipe,
            soil_density: soil.density,
            material: Some(material),
            measurements,
        }
    }

    /// On a plastic pipe whose soil the data identify, the yardstick, which never sees the
    /// soil, reaches the truth's χ² = 0 (to 1e-6) and recovers c_P and c_S to 1 %; its grid
    /// is as dense as stated.
    #[test]
    fn the_yardstick_finds_the_known_soil_of_a_plastic_pipe() {
        let props = Material::Mdpe.typical();
        let pipe = Pipe::from_outside_diameter(props, 0.125, 0.0114).expect("valid");
        let soil = Soil::new(8.0e7, 0.3, 1850.0, 0.0).expect("valid");
        let data = noise_free(
            pipe,
            Material::Mdpe,
            soil,
            0.5,
            &[80.0, 150.0, 250.0, 350.0, 450.0, 550.0],
        );
        let y = yardstick(&data, &FitSettings::default()).expect("a yardstick");
        assert!(y.misfit < 1e-6, "{}", y.misfit);
        let (e, nu) = (10f64.powf(y.x[0]), y.x[1]);
        let (l, r) = speeds_of(e, nu, 1850.0);
        let (l0, r0) = speeds_of(8.0e7, 0.3, 1850.0);
        assert!((l - l0).abs() < 0.01, "ln c_P {l} against {l0}");
        assert!((r / r0 - 1.0).abs() < 0.01, "r {r} against {r0}");
        // 201 or 202 values of ln c_P inside the box at each r, 5 gaps of 3 points each.
        let regular = 201 * R_POINTS * XI_POINTS;
        let gap = 15 * GAP_R_POINTS * GAP_XI_POINTS;
        assert!(
            y.grid_points >= regular + gap && y.grid_points <= regular + 2 * gap + 1000,
            "{}",
            y.grid_points
        );
        assert!(y.evaluations > y.grid_points);
        assert!(y.polished >= 1 && y.polished <= POLISHED, "{}", y.polished);
    }

    /// On a metal pipe the data fix c_P and barely c_S: the yardstick still reaches the
    /// truth's χ² = 0 (to 1e-6) and c_P to 1 %.
    #[test]
    fn the_yardstick_finds_the_known_soil_of_an_iron_pipe() {
        let pipe = Pipe::new(1.70e11, 0.28, 7100.0, 0.01, 0.082, 0.006).expect("valid");
        let soil = Soil::new(5.0e7, 0.35, 1900.0, 0.0).expect("valid");
        let data = noise_free(
            pipe,
            Material::DuctileIron,
            soil,
            0.3,
            &[150.0, 400.0, 800.0, 1300.0],
        );
        let y = yardstick(&data, &FitSettings::default()).expect("a yardstick");
        assert!(y.misfit < 1e-6, "{}", y.misfit);
        let (l, _) = speeds_of(10f64.powf(y.x[0]), y.x[1], 1900.0);
        let (l0, _) = speeds_of(5.0e7, 0.35, 1900.0);
        assert!((l - l0).abs() < 0.01, "ln c_P {l} against {l0}");
    }

    /// What the yardstick does not cover is refused with a reason, not rated.
    #[test]
    fn the_yardstick_refuses_what_it_does_not_grid() {
        let data = crate::bench::synthetic_iron_data();
        let paper = FitSettings::paper(Model::Full, ContactMode::Reciprocal);
        assert_eq!(
            yardstick(&data, &paper).unwrap_err(),
            YardstickError::Unsupported
        );
        let with_effect = FitSettings {
            effects: vec![crate::physics::effects::Effect::SoilDamping],
            ..FitSettings::default()
        };
        assert_eq!(
            yardstick(&data, &with_effect).unwrap_err(),
            YardstickError::Unsupported
        );
        let empty = SegmentData {
            measurements: Vec::new(),
            ..data
        };
        assert_eq!(
            yardstick(&empty, &FitSettings::default()).unwrap_err(),
            YardstickError::NoMeasurements
        );
    }
}
