//! Fitting one segment: the search (differential evolution in the speed coordinates and in
//! (log10 E_m, ν_m, …), polishes, the faces of the box, the grazing probe), the check of its
//! optima on the reference path (model §5.3–5.4), and the retries; the result is then built
//! once from the optima ([`super::assemble`]).

use num_complex::Complex64;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::assemble::assemble;
use super::flags::FlagCode;
use super::probes;
use super::problem::{
    Method, Param, Problem, SegmentData, SolvePath, Weighting, FAILED_SOLVE_OBJECTIVE,
};
use super::provenance::{Provenance, SearchError, Stage, StageRecord, StageStop};
use super::result::FitResult;
use super::speed_search;
use crate::optimize::{
    DeMethod, DifferentialEvolution, FiniteDifference, LevenbergMarquardt, LmStopReason, Objective,
    OptimizeError,
};
use crate::physics::effects::Effect;
use crate::physics::solver::Root;
use crate::physics::{ContactMode, Model, System};
use crate::types::FitStatus;

/// Settings of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct FitSettings {
    /// Inversion method.
    pub method: Method,
    /// Model variant (`full_model` in `effects` upgrades `seed` to `full`).
    pub model: Model,
    /// Contact reading.
    pub contact_mode: ContactMode,
    /// Effects switched on, by name.
    pub effects: Vec<Effect>,
    /// Independent DE runs (≥ 1); more than one enables the multiple-minima check.
    pub restarts: usize,
    /// Evaluation budget of one default-method DE run, per fitted parameter.
    pub evaluations_per_dimension: usize,
}

impl Default for FitSettings {
    fn default() -> Self {
        Self {
            method: Method::Default,
            model: Model::Full,
            contact_mode: ContactMode::Reciprocal,
            effects: Vec::new(),
            restarts: DEFAULT_RESTARTS,
            evaluations_per_dimension: DEFAULT_EVALUATIONS_PER_DIMENSION,
        }
    }
}

impl FitSettings {
    /// The paper's method (model §7.1–7.3) with `seed` or `full` model.
    pub fn paper(model: Model, contact_mode: ContactMode) -> Self {
        Self {
            method: Method::Paper,
            model,
            contact_mode,
            effects: Vec::new(),
            restarts: 1,
            evaluations_per_dimension: DEFAULT_EVALUATIONS_PER_DIMENSION,
        }
    }
}

/// The fast search path and the reference path agree at the optimum when every wavenumber
/// agrees to this relative amount (the fast tolerance is 1e-10; another root differs by O(1)).
pub const PATH_AGREEMENT_RTOL: f64 = 1e-6;

/// Independent DE runs of the default method.
pub const DEFAULT_RESTARTS: usize = 2;
/// Evaluation budget of one default DE run per fitted parameter: enough to find the basins the
/// faces and probes do not, which look where the DE runs do not (evidence: docs/search.md,
/// "The DE runs").
pub const DEFAULT_EVALUATIONS_PER_DIMENSION: usize = 110;
/// The budget of each DE run in (log10 E_m, ν_m, …) that follows one in the speed coordinates,
/// as a percentage of [`DEFAULT_EVALUATIONS_PER_DIMENSION`] (never below one population): it
/// adds a population spread uniformly in ν_m, which needs few generations (evidence:
/// docs/search.md, "The DE runs").
pub const SECOND_RUN_BUDGET_PERCENT: usize = 40;
/// Initial population of the default DE (L-SHADE, shrinking linearly to 4 over the budget).
pub const DEFAULT_POPULATION: usize = 100;
/// Spread test of the default DE: stop when the population's objective values agree within
/// this absolute amount (in chi-square units: far below the Δχ² = 1 of one sigma) …
pub const SPREAD_ATOL_CHI2: f64 = 1e-2;
/// … or within this relative amount (the LM polish finishes the convergence).
pub const SPREAD_RTOL: f64 = 1e-3;
/// Absolute spread tolerance for the relative-error objective (dimensionless squares).
pub const SPREAD_ATOL_RELATIVE: f64 = 1e-8;

/// The seed of restart `r` of a fit seeded with `seed`.
pub fn restart_seed(seed: u64, r: usize) -> u64 {
    crate::seed::derive(seed, r as u64)
}

/// One optimum found by one restart (or by the nested start).
#[derive(Clone)]
pub(super) struct Optimum {
    pub(super) x: Vec<f64>,
    pub(super) cost: f64,
}

/// Fit one segment. Deterministic for a given `seed`.
pub fn fit_segment(data: &SegmentData, settings: &FitSettings, seed: u64) -> FitResult {
    fit_from(data, settings, seed, None)
}

/// The optimum of a base fit of a segment (the same settings without the added effects), from
/// which a fit with effects also starts: its parameter values and its fitted system.
#[derive(Debug, Clone)]
pub struct BaseOptimum {
    /// (parameter, value in physical units) of every fitted parameter of the base.
    values: Vec<(Param, f64)>,
    /// The base's system, for the effects' neutral values (a pipe's own loss factor).
    system: System,
}

impl BaseOptimum {
    /// The optimum of a fit; `None` for a failed fit.
    pub fn of(fit: &FitResult) -> Option<BaseOptimum> {
        if fit.status == FitStatus::Failed {
            return None;
        }
        Some(BaseOptimum {
            values: fit.estimates.iter().map(|e| (e.param, e.value)).collect(),
            system: fit.system?,
        })
    }

    /// The optimum of a stored base fit of `data` made with `settings`: the values of its
    /// fitted parameters (physical units). `None` when one is missing or gives no system.
    pub fn from_values(
        data: &SegmentData,
        settings: &FitSettings,
        values: Vec<(Param, f64)>,
    ) -> Option<BaseOptimum> {
        let problem = problem_for(data, settings);
        let x: Vec<f64> = problem
            .specs
            .iter()
            .map(|s| {
                let v = values.iter().find(|v| v.0 == s.param)?.1;
                v.is_finite().then(|| s.coordinate(v))
            })
            .collect::<Option<_>>()?;
        let system = problem.system_at(&x)?;
        Some(BaseOptimum { values, system })
    }

    fn get(&self, p: Param) -> Option<f64> {
        self.values.iter().find(|v| v.0 == p).map(|v| v.1)
    }
}

/// Fit one segment with effects beyond those of a `base` fit of the same segment: besides the
/// usual search, start from the base optimum with every added effect at its neutral value,
/// and keep the better. Where the extended model contains the base model (soil_damping,
/// air_in_water, wall_thinning, pipe_loss), the result's misfit is never above the base fit's
/// (up to the solver's tolerance), whatever the search does.
pub fn fit_extended(
    data: &SegmentData,
    settings: &FitSettings,
    seed: u64,
    base: &FitResult,
) -> FitResult {
    fit_from(data, settings, seed, BaseOptimum::of(base).as_ref())
}

/// Fit one segment with `settings.effects` through the nested-fit guarantee of
/// [`fit_extended`] (the one path of every fit with effects): from `stored_base`, the values of
/// a stored fit of the same inputs without effects, when given and usable; otherwise the base
/// is fitted first (its evaluations are counted in the result's).
pub fn fit_with_effects(
    data: &SegmentData,
    settings: &FitSettings,
    seed: u64,
    stored_base: Option<Vec<(Param, f64)>>,
) -> FitResult {
    if settings.effects.is_empty() {
        return fit_segment(data, settings, seed);
    }
    let base_settings = FitSettings {
        effects: Vec::new(),
        ..settings.clone()
    };
    if let Some(base) = stored_base.and_then(|v| BaseOptimum::from_values(data, &base_settings, v))
    {
        return fit_from(data, settings, seed, Some(&base));
    }
    let base_fit = fit_segment(data, &base_settings, seed);
    let mut r = fit_from(data, settings, seed, BaseOptimum::of(&base_fit).as_ref());
    r.evaluations += base_fit.evaluations;
    r
}

fn fit_from(
    data: &SegmentData,
    settings: &FitSettings,
    seed: u64,
    base: Option<&BaseOptimum>,
) -> FitResult {
    let problem = problem_for(data, settings);
    let n_meas = data.measurements.len();
    if n_meas == 0 {
        return FitResult::failed_by(settings, problem.weighting, 0, SearchError::NoMeasurements);
    }
    let start = base.and_then(|b| nested_start(&problem, b));
    let first = fit_once(data, settings, seed, start.as_deref());
    let retry = settings.method == Method::Default
        && first.has_flag(FlagCode::HighMisfit)
        && first
            .chi2_per_dof
            .is_some_and(|c| c <= HIGH_MISFIT_RETRY_MAX_CHI2_PER_DOF);
    if !retry {
        return first;
    }
    // The model does not explain the data within their noise: before saying so, one more
    // search from another seed (see [`HIGH_MISFIT_RETRY_STREAM`]), the better answer kept.
    let second = fit_once(
        data,
        settings,
        crate::seed::derive(seed, HIGH_MISFIT_RETRY_STREAM),
        start.as_deref(),
    );
    let evaluations = first.evaluations + second.evaluations;
    let result_seconds = first.result_seconds + second.result_seconds;
    let from_second = second.status != FitStatus::Failed && second.misfit < first.misfit;
    let mut r = if from_second { second } else { first };
    r.evaluations = evaluations;
    r.result_seconds = result_seconds;
    r.provenance.searches = 2;
    r.provenance.from_second_search = from_second;
    r
}

/// Seed stream of the second search of a fit flagged `high_misfit` (far from the restarts'
/// streams 0, 1, …; the same fit whatever the thread count). Rarely, both DE runs and every
/// probe end in a basin far above the global one. A misfit that high is flagged (p <
/// [`MISFIT_P_VALUE`](super::flags::MISFIT_P_VALUE)); up to
/// [`HIGH_MISFIT_RETRY_MAX_CHI2_PER_DOF`] a second search runs, so that the flag means the
/// model, not the search, fails to explain the data (evidence: docs/search.md, "The second
/// search of a high misfit").
pub const HIGH_MISFIT_RETRY_STREAM: u64 = 0x6869_6768;

/// χ²/dof up to which a fit flagged `high_misfit` searches once more. Further up the data are
/// mostly defective (a unit error, an outlier, a wrong record), and no search mends them; a
/// search that missed its global optimum can still end at χ²/dof 10–15 (evidence:
/// docs/search.md, "The second search of a high misfit").
pub const HIGH_MISFIT_RETRY_MAX_CHI2_PER_DOF: f64 = 20.0;

/// The problem of fitting `data` with `settings`.
pub(super) fn problem_for<'a>(data: &'a SegmentData, settings: &'a FitSettings) -> Problem<'a> {
    Problem::new(
        data,
        settings.method,
        settings.model,
        settings.contact_mode,
        &settings.effects,
    )
}

/// One search (fast path, and the safe path where the fast one tracked another root at its
/// optimum) and its result.
fn fit_once(
    data: &SegmentData,
    settings: &FitSettings,
    seed: u64,
    start: Option<&[f64]>,
) -> FitResult {
    fit_by_plan(data, settings, &Plan::Search { seed, start })
}

/// How a fit looks for its optimum.
#[derive(Clone, Copy)]
enum Plan<'p> {
    /// The whole search (DE runs, faces, probes), seeded, with a nested start if given.
    Search { seed: u64, start: Option<&'p [f64]> },
    /// Only polishes from the given points (coordinates of the problem's space): the fit of a
    /// campaign from the optimum of another campaign of the same pipe (model §7.14), where the
    /// two optima lie in one basin unless the pipe changed.
    FromStarts(&'p [Vec<f64>]),
}

/// Fit a segment by polishing from `starts` only (no global search): the optimum nearest the
/// starts, checked on the reference path and assembled as every fit is, with its errors,
/// curve and flags. Used where another fit of the same pipe gives a start in the right basin
/// (the earlier campaign, or both campaigns pooled, model §7.14). Deterministic.
pub fn refit_from(data: &SegmentData, settings: &FitSettings, starts: &[Vec<f64>]) -> FitResult {
    let problem = problem_for(data, settings);
    if data.measurements.is_empty() {
        return FitResult::failed_by(settings, problem.weighting, 0, SearchError::NoMeasurements);
    }
    fit_by_plan(data, settings, &Plan::FromStarts(starts))
}

fn fit_by_plan(data: &SegmentData, settings: &FitSettings, plan: &Plan<'_>) -> FitResult {
    let problem = problem_for(data, settings);
    let n_meas = data.measurements.len();
    match run(&problem, settings, plan) {
        Ok(r) if r.path_checked => r,
        Ok(fast) => {
            // The fast search path tracked another root at its optimum: search again with the
            // safe path (continuation ramp wherever the soil moves the root far from in vacuo).
            let mut safe = problem_for(data, settings);
            safe.path = SolvePath::Safe;
            match run(&safe, settings, plan) {
                Ok(mut r) => {
                    r.evaluations += fast.evaluations;
                    r
                }
                Err(e) => {
                    let mut r = FitResult::failed_by(settings, problem.weighting, n_meas, e);
                    r.evaluations = problem.evaluations() + safe.evaluations();
                    r.provenance.path = Some(SolvePath::Safe);
                    r.provenance.searches = 1;
                    r
                }
            }
        }
        Err(e) => {
            let mut r = FitResult::failed_by(settings, problem.weighting, n_meas, e);
            r.evaluations = problem.evaluations();
            r.provenance.path = Some(SolvePath::Fast);
            r.provenance.searches = 1;
            r
        }
    }
}

/// The base optimum in this problem's coordinates, every added effect at its neutral value.
pub(super) fn nested_start(problem: &Problem<'_>, base: &BaseOptimum) -> Option<Vec<f64>> {
    problem
        .specs
        .iter()
        .map(|s| {
            let v = match (base.get(s.param), s.param) {
                (Some(b), _) => b,
                (None, Param::Effect(e)) => e.neutral_value(&base.system)?,
                (None, _) => return None,
            };
            let c = s.coordinate(v);
            Some(if c.is_nan() {
                s.lower
            } else {
                c.clamp(s.lower, s.upper)
            })
        })
        .collect()
}

/// What the search found: its optima, whether each one's polish stopped at its iteration cap
/// (still descending), the stage that found each, and the record of every stage.
#[derive(Default)]
struct Searched {
    optima: Vec<Optimum>,
    capped: Vec<bool>,
    found_by: Vec<Stage>,
    stages: Vec<StageRecord>,
}

impl Searched {
    /// The index of the best optimum so far.
    fn best(&self) -> Option<usize> {
        (0..self.optima.len()).min_by(|&a, &b| self.optima[a].cost.total_cmp(&self.optima[b].cost))
    }

    /// The best misfit so far (+∞ when there is none).
    fn best_cost(&self) -> f64 {
        self.optima
            .iter()
            .map(|o| o.cost)
            .fold(f64::INFINITY, f64::min)
    }

    /// Where a stage begins: the evaluations so far and the best misfit.
    fn begin(&self, problem: &Problem<'_>) -> (usize, f64) {
        (problem.evaluations(), self.best_cost())
    }

    /// Files the optima `stage` found.
    fn push(&mut self, stage: Stage, found: impl IntoIterator<Item = (Optimum, bool)>) {
        for (o, c) in found {
            self.optima.push(o);
            self.capped.push(c);
            self.found_by.push(stage);
        }
    }

    /// Records `stage`, begun at `begun` ([`Searched::begin`]), as stopped by `stop`.
    fn close(&mut self, problem: &Problem<'_>, stage: Stage, stop: StageStop, begun: (usize, f64)) {
        self.stages.push(StageRecord {
            stage,
            stop,
            evaluations: problem.evaluations() - begun.0,
            best_before: begun.1,
            best_after: self.best_cost(),
        });
    }

    /// Files the optima of a stage of polishes and records it: polished when it found any,
    /// otherwise stopped by `none`.
    fn polished(
        &mut self,
        problem: &Problem<'_>,
        stage: Stage,
        begun: (usize, f64),
        found: Vec<(Optimum, bool)>,
        none: StageStop,
    ) {
        let n = found.len();
        self.push(stage, found);
        let stop = if n > 0 {
            StageStop::Polished {
                starts: n,
                optima: n,
            }
        } else {
            none
        };
        self.close(problem, stage, stop, begun);
    }
}

/// The search: every restart's DE run polished, and the nested start polished.
fn search(
    problem: &Problem<'_>,
    settings: &FitSettings,
    seed: u64,
    bounds: &crate::optimize::Bounds,
    start: Option<&[f64]>,
) -> Result<Searched, SearchError> {
    let mut s = Searched::default();
    // With the DE in the speed coordinates, the first run (and every other) samples the image
    // of the box uniformly in (ln c_P, r = c_S/c_P, …), the second in (log10 E_m, ν_m, …):
    // uniform in r, 39 % of a population lies at ν_m ≥ 0.45, uniform in ν_m 10 %, so the two
    // runs favour different basins (docs/performance.md, "The search's DE in speed coordinates").
    let in_speeds =
        speed_search::InSpeeds::new(problem, bounds).filter(|_| settings.method == Method::Default);
    let speed_bounds = in_speeds.as_ref().and_then(|s| s.speed_bounds());
    for r in 0..settings.restarts.max(1) {
        let begun = s.begin(problem);
        let mut rng = ChaCha8Rng::seed_from_u64(restart_seed(seed, r));
        let mut de = de_for(settings, problem)?;
        if r % 2 == 1 && speed_bounds.is_some() {
            // The run in (log10 E_m, ν_m, …) after one in the speed coordinates: a second
            // look at the basins the first under-samples, on a smaller budget.
            let per_dimension =
                settings.evaluations_per_dimension * SECOND_RUN_BUDGET_PERCENT / 100;
            de =
                de.max_evaluations((per_dimension * problem.specs.len()).max(DEFAULT_POPULATION))?;
        }
        let res = match (&in_speeds, &speed_bounds) {
            (Some(sp), Some(yb)) if r % 2 == 0 => {
                let mut res = de.minimize(sp, yb, &mut rng)?;
                match sp.x(&res.x) {
                    Some(x) => res.x = x,
                    None => res.f = f64::INFINITY,
                }
                res
            }
            _ => de.minimize(problem, bounds, &mut rng)?,
        };
        if !res.f.is_finite()
            || (settings.method == Method::Paper && res.f >= FAILED_SOLVE_OBJECTIVE)
        {
            s.close(problem, Stage::Global, StageStop::NoFiniteOptimum, begun);
            continue;
        }
        s.push(
            Stage::Global,
            [refine(problem, settings, bounds, res.x, res.f)],
        );
        let stop = StageStop::Population(res.stop_reason);
        s.close(problem, Stage::Global, stop, begun);
    }
    if let Some(x0) = start {
        let begun = s.begin(problem);
        let f0 = problem.value(x0);
        let found: Vec<_> = f0
            .is_finite()
            .then(|| refine(problem, settings, bounds, x0.to_vec(), f0))
            .into_iter()
            .collect();
        let none = StageStop::NoFiniteOptimum;
        s.polished(problem, Stage::NestedStart, begun, found, none);
    }
    let pieces = probes::Pieces::new(problem).filter(|_| settings.method == Method::Default);
    if let (Some(_), true) = (&pieces, in_speeds.is_some() && speed_bounds.is_some()) {
        // The faces r = r_min and ξ ∈ {0, 1} at the best optimum, and the line on the face
        // r = r_min past grazing (P44).
        let begun = s.begin(problem);
        let found = s.best().map_or_else(Vec::new, |i| {
            speed_search::faces(problem, bounds, &s.optima[i])
        });
        let none = StageStop::NotApplicable;
        s.polished(problem, Stage::SpeedFaces, begun, found, none);
    }
    if let Some(pieces) = pieces {
        // Each probe starts from the best optimum so far.
        let run_probe = |s: &mut Searched, stage: Stage, probe: &dyn Fn(&Optimum) -> Vec<_>| {
            let begun = s.begin(problem);
            let found = s.best().map_or_else(Vec::new, |i| probe(&s.optima[i]));
            s.polished(problem, stage, begun, found, StageStop::NotApplicable);
        };
        // The grazing probe again from a best it moved: its pieces are others. The first
        // round with the gap scan's starts (`probes::gap_scan`).
        for round in 0..GRAZING_ROUNDS {
            let before = s.best_cost();
            run_probe(&mut s, Stage::Grazing, &|b| {
                probes::grazing_probe(&pieces, bounds, b, round == 0)
            });
            if s.best_cost() >= before - GRAZING_ROUND_GAIN {
                break;
            }
        }
        // Where the best the probes leave lies near grazing (`Pieces::near_grazing`), the gap
        // scan once more from it: its targets follow the best's model phase speeds, and the
        // best has moved since the first scan, often along a flat valley, by less in χ² than
        // the rounds above need to go on (evidence: docs/search.md, "The rescan near grazing").
        if s.best()
            .is_some_and(|i| pieces.near_grazing(&s.optima[i].x))
        {
            run_probe(&mut s, Stage::GrazingRescan, &|b| {
                probes::grazing_probe(&pieces, bounds, b, true)
            });
        }
    }
    continued_polish(problem, settings, bounds, &mut s);
    Ok(s)
}

/// The best optimum's continued polish (the last stage of every search).
fn continued_polish(
    problem: &Problem<'_>,
    settings: &FitSettings,
    bounds: &crate::optimize::Bounds,
    s: &mut Searched,
) {
    // The best optimum's polish goes on: only the best's, since only the answer needs the
    // bottom of its valley. The candidates' polishes stop at a loose tolerance
    // ([`CANDIDATE_POLISH_RTOL`]); the best's goes on to LM's own, with forward differences
    // where it stopped on that tolerance, and with central differences where it stopped at
    // its iteration cap, still descending. In a narrow curved valley a forward-difference
    // Jacobian's error across the valley swamps the gradient along it, and forward iterations
    // can cross onto a grazing cliff (P44) where the search path and the reference path rate
    // the soil differently (evidence: docs/search.md, "The continued polish").
    if let Some(i) = s.best() {
        let begun = s.begin(problem);
        let mut polished = 0;
        for (iterations, fd) in [
            (POLISH_ITERATIONS, FiniteDifference::Forward),
            (POLISH_MORE_ITERATIONS, FiniteDifference::Central),
        ] {
            let go = match fd {
                FiniteDifference::Forward => settings.method == Method::Default && !s.capped[i],
                FiniteDifference::Central => s.capped[i],
            };
            if !go {
                continue;
            }
            polished += 1;
            let found = polish_with(
                problem,
                &s.optima[i].x,
                bounds,
                iterations,
                fd,
                Depth::Answer,
            );
            if let Some((o, c)) = found.filter(|(o, _)| o.cost < s.optima[i].cost) {
                s.optima[i] = o;
                s.capped[i] = c;
            }
        }
        let stop = match (polished, s.capped[i]) {
            (0, _) => StageStop::NotApplicable,
            (_, true) => StageStop::PolishCapped,
            (n, false) => StageStop::Polished {
                starts: n,
                optima: 0,
            },
        };
        s.close(problem, Stage::ContinuedPolish, stop, begun);
    }
}

/// The search of [`refit_from`]: a polish from every start inside the box (projected onto it
/// first), then the answer's continued polish as in [`search`].
fn from_starts(
    problem: &Problem<'_>,
    settings: &FitSettings,
    bounds: &crate::optimize::Bounds,
    starts: &[Vec<f64>],
) -> Searched {
    let mut s = Searched::default();
    let begun = s.begin(problem);
    let found: Vec<_> = starts
        .iter()
        .filter(|x| x.len() == problem.specs.len())
        .filter_map(|x| {
            let mut x = x.clone();
            bounds.clamp(&mut x);
            let f0 = problem.value(&x);
            f0.is_finite()
                .then(|| refine(problem, settings, bounds, x, f0))
        })
        .collect();
    s.polished(
        problem,
        Stage::CampaignStart,
        begun,
        found,
        StageStop::NoFiniteOptimum,
    );
    continued_polish(problem, settings, bounds, &mut s);
    s
}

/// Rounds of the grazing probe at most: another round runs from the best optimum
/// when the last improved it by more than [`GRAZING_ROUND_GAIN`] in χ², since the pieces
/// next to a new best are others: from the piece a first round moved the best to, the soil
/// moved between two measured phase speeds can reach a far better optimum (evidence:
/// docs/search.md, "The grazing probe").
pub const GRAZING_ROUNDS: usize = 3;
/// See [`GRAZING_ROUNDS`].
pub const GRAZING_ROUND_GAIN: f64 = 0.01;

/// Levenberg–Marquardt iterations of the polish of each optimum of the search.
pub const POLISH_ITERATIONS: usize = 30;
/// Further iterations for the best optimum when its polish was still descending after
/// [`POLISH_ITERATIONS`]: in a flat valley, where the data fix c_P and nearly only ξ·c_S, LM
/// creeps (evidence: docs/search.md, "The continued polish").
pub const POLISH_MORE_ITERATIONS: usize = 100;

/// The paper's answer is the best member of the final population (P59): no polish. The
/// default method polishes with Levenberg–Marquardt, keeping the start if that is better.
/// Also returns whether the polish stopped at its iteration cap.
fn refine(
    problem: &Problem<'_>,
    settings: &FitSettings,
    bounds: &crate::optimize::Bounds,
    x: Vec<f64>,
    cost: f64,
) -> (Optimum, bool) {
    match settings.method {
        Method::Paper => (Optimum { x, cost }, false),
        Method::Default => {
            polish(problem, &x, bounds, POLISH_ITERATIONS).unwrap_or((Optimum { x, cost }, false))
        }
    }
}

fn run(
    problem: &Problem<'_>,
    settings: &FitSettings,
    plan: &Plan<'_>,
) -> Result<FitResult, SearchError> {
    let bounds = problem.bounds()?;
    let Searched {
        mut optima,
        found_by,
        stages,
        ..
    } = match *plan {
        Plan::Search { seed, start } => search(problem, settings, seed, &bounds, start)?,
        Plan::FromStarts(starts) => from_starts(problem, settings, &bounds, starts),
    };
    let mut order: Vec<usize> = (0..optima.len()).collect();
    order.sort_by(|&a, &b| optima[a].cost.total_cmp(&optima[b].cost));
    if order.is_empty() {
        return Err(no_root_anywhere(problem, &bounds));
    }
    // The answer is reported on the reference path (model §5.3–5.4). Near grazing (P44) the
    // search path can follow a root on the other side of the branch cut, so its misfit may not
    // be the reference path's. The optima are checked best first, each taking the misfit the
    // reference path gives it (infinite where it finds no root), up to the first on which the
    // two paths agree; the answer is the checked optimum the reference path rates best.
    let mut checked: Vec<Checked> = Vec::new();
    let mut failure: Option<System> = None;
    // Whether an optimum checked before the answer (a better one, by the search's misfit) had
    // no root on the reference path: the fast path followed another root there, so its
    // ranking of the optima is not to be trusted.
    let mut unconfirmed = false;
    // The best reference misfit of an optimum confirmed just off a cliff: a later optimum can
    // still be better (its search misfit is lower), so the checks go on while it is.
    let mut off_cliff_best = f64::INFINITY;
    let pieces = probes::Pieces::new(problem);
    // Whether the answer, when it is optimum i, was moved off a cliff.
    let mut moved_off: Vec<usize> = Vec::new();
    for &i in &order {
        if optima[i].cost >= off_cliff_best {
            break;
        }
        let mut moved = false;
        let mut check = check_at(problem, i, &optima[i].x);
        if !matches!(&check, Check::Roots(c) if c.agree) {
            // Off the cliff: the optimum may sit on a grazing cliff, where the two paths take
            // roots on either side of it; a point just off the cliff on the low side may
            // agree (see [`probes::off_cliff`]).
            let (cost, rooted) = match &check {
                Check::Roots(c) => (c.cost, true),
                _ => (f64::INFINITY, false),
            };
            let moves = pieces
                .as_ref()
                .map_or_else(Vec::new, |p| probes::off_cliff(p, &optima[i].x, rooted));
            for x in moves {
                if let Check::Roots(c) = check_at(problem, i, &x) {
                    if c.agree && c.cost < cost {
                        optima[i].x = x;
                        check = Check::Roots(c);
                        moved = true;
                        moved_off.push(i);
                        break;
                    }
                }
            }
        }
        match check {
            Check::NoSystem => {
                optima[i].cost = f64::INFINITY;
                unconfirmed = true;
            }
            Check::NoRoot(sys) => {
                optima[i].cost = f64::INFINITY;
                unconfirmed = true;
                failure.get_or_insert(sys);
            }
            Check::Roots(c) => {
                optima[i].cost = c.cost;
                let (agree, cost) = (c.agree, c.cost);
                checked.push(c);
                if agree && !moved {
                    break;
                }
                if agree {
                    off_cliff_best = off_cliff_best.min(cost);
                }
            }
        }
    }
    let best = checked
        .into_iter()
        .filter(|c| optima[c.i].cost.is_finite())
        .min_by(|a, b| optima[a.i].cost.total_cmp(&optima[b.i].cost));
    match best {
        // The fast path tracked another root at the best optimum, or at a better one the
        // reference path has no root at: the caller searches again on the safe path
        // (continuation ramp wherever the soil moves the root far from in vacuo), whose answer
        // stands on the reference path's misfit. Otherwise a worse basin could stand in for a
        // better one the fast path saw wrongly (evidence: docs/search.md, "The safe path").
        Some(c) if (c.agree && !unconfirmed) || problem.path != SolvePath::Fast => {
            let provenance = Provenance {
                winner: Some(found_by[c.i]),
                stages,
                path: Some(problem.path),
                moved_off_cliff: moved_off.contains(&c.i),
                searches: 1,
                from_second_search: false,
                error: None,
            };
            let mut r = assemble(
                problem,
                settings,
                &bounds,
                &optima,
                c.i,
                c.sys,
                c.predicted,
                &c.roots,
            )?;
            r.provenance = provenance;
            Ok(r)
        }
        None if problem.path != SolvePath::Fast => Err(SearchError::NoRootAtOptimum {
            reason: failure
                .and_then(|sys| problem.reference_failure(&sys))
                .unwrap_or_else(|| "no root on the search path".to_string()),
        }),
        _ => {
            let mut r = FitResult::failed(
                settings,
                problem.weighting,
                problem.data.measurements.len(),
                String::new(),
            );
            r.path_checked = false;
            r.evaluations = problem.evaluations();
            Ok(r)
        }
    }
}

/// An optimum checked on the reference path.
struct Checked {
    /// Its index among the optima.
    i: usize,
    sys: System,
    /// The reference path's wavenumbers.
    predicted: Vec<Complex64>,
    /// The reference path's misfit.
    cost: f64,
    roots: Vec<Root>,
    /// The search path found the same roots.
    agree: bool,
}

/// What the reference path makes of a point.
enum Check {
    /// The parameters give no system.
    NoSystem,
    /// The reference path finds no root.
    NoRoot(System),
    Roots(Checked),
}

/// The check on the reference path of optimum `i` at `x`.
fn check_at(problem: &Problem<'_>, i: usize, x: &[f64]) -> Check {
    let Some(sys) = problem.system_at(x) else {
        return Check::NoSystem;
    };
    let Some(roots) = problem.reference_roots(&sys) else {
        return Check::NoRoot(sys);
    };
    let predicted: Vec<Complex64> = roots.iter().map(|x| x.k1).collect();
    let agree = problem.predict_system(&sys).is_some_and(|k| {
        k.iter()
            .zip(&predicted)
            .all(|(a, b)| (a - b).norm() <= PATH_AGREEMENT_RTOL * b.norm())
    });
    Check::Roots(Checked {
        i,
        cost: problem.objective_of(&predicted),
        sys,
        predicted,
        roots,
        agree,
    })
}

/// Why no soil in the search range gives an s = 1 root: the reference solver's reason (e.g.
/// grazing at a soil wave speed, no convergence) at the centre of the search box, a typical
/// soil, so the user learns the physical cause rather than only that the search failed.
fn no_root_anywhere(problem: &Problem<'_>, bounds: &crate::optimize::Bounds) -> SearchError {
    let centre: Vec<f64> = bounds
        .lower()
        .iter()
        .zip(bounds.upper())
        .map(|(lo, hi)| 0.5 * (lo + hi))
        .collect();
    let reason = problem
        .system_at(&centre)
        .and_then(|sys| problem.reference_failure(&sys))
        .unwrap_or_else(|| "the inputs give no physical system".to_string());
    let soil: Vec<String> = problem
        .specs
        .iter()
        .zip(problem.values(&centre))
        .map(|(s, v)| format!("{} = {}", s.param.name(), crate::units::short(v)))
        .collect();
    SearchError::NoRootAnywhere {
        soil: soil.join(", "),
        reason,
    }
}

/// The DE configured for the method.
fn de_for(
    settings: &FitSettings,
    problem: &Problem<'_>,
) -> Result<DifferentialEvolution, OptimizeError> {
    match settings.method {
        Method::Paper => Ok(DifferentialEvolution::new(DeMethod::Paper)),
        Method::Default => {
            let atol = match problem.weighting {
                Weighting::ChiSquare => SPREAD_ATOL_CHI2,
                Weighting::Relative => SPREAD_ATOL_RELATIVE,
            };
            DifferentialEvolution::new(DeMethod::Shade)
                .population_size(DEFAULT_POPULATION)?
                .max_evaluations(
                    (settings.evaluations_per_dimension * problem.specs.len())
                        .max(DEFAULT_POPULATION),
                )?
                .spread_tolerance(atol, SPREAD_RTOL)
        }
    }
}

/// How far a polish goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Depth {
    /// A candidate of the search (a DE optimum, a probe's start): Levenberg–Marquardt stops
    /// once a step gains or moves less than [`CANDIDATE_POLISH_RTOL`], relative.
    Candidate,
    /// The answer: LM's own tolerances (ftol 1e-12, xtol 1e-10).
    Answer,
}

/// Relative tolerance (LM's `ftol` and `xtol`) of the polish of a candidate of the search,
/// where only the ranking of the optima matters; the best is then polished to the bottom
/// (`Depth::Answer`). A candidate's polish spent its last iterations gaining less than this
/// (evidence: docs/search.md, "The continued polish").
pub const CANDIDATE_POLISH_RTOL: f64 = 1e-7;

/// Levenberg–Marquardt polish of a candidate optimum of the search inside the bounds.
pub(super) fn polish(
    problem: &Problem<'_>,
    x0: &[f64],
    bounds: &crate::optimize::Bounds,
    iterations: usize,
) -> Option<(Optimum, bool)> {
    polish_with(
        problem,
        x0,
        bounds,
        iterations,
        FiniteDifference::Forward,
        Depth::Candidate,
    )
}

/// [`polish`] with the given finite differences (relative step 1e-6 forward, the scheme's
/// default central) and depth. `None` when LM fails, or ends above a start outside the box.
fn polish_with(
    problem: &Problem<'_>,
    x0: &[f64],
    bounds: &crate::optimize::Bounds,
    iterations: usize,
    fd: FiniteDifference,
    depth: Depth,
) -> Option<(Optimum, bool)> {
    let step = match fd {
        FiniteDifference::Forward => 1e-6,
        FiniteDifference::Central => fd.default_rel_step(),
    };
    let mut lm = LevenbergMarquardt::new()
        .max_iterations(iterations)
        .ok()?
        .finite_difference(fd)
        .fd_rel_step(step)
        .ok()?
        .final_jacobian(false);
    if depth == Depth::Candidate {
        lm = lm
            .ftol(CANDIDATE_POLISH_RTOL)
            .ok()?
            .xtol(CANDIDATE_POLISH_RTOL)
            .ok()?;
    }
    let r = lm.minimize(problem, x0, Some(bounds)).ok()?;
    // LM starts from x0 and accepts only steps that lower the misfit, so its answer is never
    // worse than a start inside the box (one outside is projected first).
    let start = if bounds.contains(x0) {
        r.cost
    } else {
        problem.value(x0)
    };
    if r.cost.is_finite() && r.cost <= start {
        let capped = r.stop_reason == LmStopReason::MaxIterations;
        Some((
            Optimum {
                x: r.x,
                cost: r.cost,
            },
            capped,
        ))
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fit flagged `high_misfit` searches once more only up to
    /// [`HIGH_MISFIT_RETRY_MAX_CHI2_PER_DOF`]. A segment of a bench network: from a few seeds
    /// (1 of the first 200) the search ends in a basin at χ² 65.1 (χ²/dof 5.9), the second
    /// search at 11.6; the test takes the first such seed. With its attenuations written in dB/m
    /// (8.7 × too large, a defect of the sample network) χ²/dof is far above the limit, and the
    /// fit is the first search's, evaluation for evaluation.
    #[test]
    fn a_high_misfit_is_searched_again_only_below_the_chi2_per_dof_limit() {
        use crate::synth::bench::{bench_network, MaterialMix};
        let seg = bench_network(200, 998006, MaterialMix::Default)
            .into_iter()
            .find(|s| s.id == "WM10035")
            .expect("the segment");
        let settings = FitSettings::default();
        let seed = (0..400)
            .find(|&s| fit_once(&seg.data, &settings, s, None).misfit > 50.0)
            .expect("a seed from which the first search ends in the high basin");
        let first_and_answer = |data: &SegmentData| {
            let first = fit_once(data, &settings, seed, None);
            (first, fit_segment(data, &settings, seed))
        };
        let (first, answer) = first_and_answer(&seg.data);
        assert!(first.has_flag(FlagCode::HighMisfit), "{}", first.misfit);
        assert!(first.misfit > 50.0, "{}", first.misfit);
        assert!(answer.misfit < 12.0, "{}", answer.misfit);
        assert!(answer.evaluations > first.evaluations);

        let mut defective = seg.data.clone();
        for m in &mut defective.measurements {
            m.attenuation *= 8.686;
        }
        let (first, answer) = first_and_answer(&defective);
        assert!(first.has_flag(FlagCode::HighMisfit));
        let per_dof = first.chi2_per_dof.expect("dof > 0");
        assert!(per_dof > HIGH_MISFIT_RETRY_MAX_CHI2_PER_DOF, "{per_dof}");
        assert_eq!(answer.evaluations, first.evaluations);
        assert_eq!(answer.misfit, first.misfit);
    }
}
