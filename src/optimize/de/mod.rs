//! Differential evolution (Storn & Price 1997) over a box.
//!
//! Two methods share one builder, [`DifferentialEvolution`]:
//!
//! * [`DeMethod::Paper`] reproduces the optimiser of Lu et al. (Sensors 2022) as written
//!   down in docs/model.md (§7, equations P54–P59): classic DE/rand/1/bin with
//!   `NP = 50`, `CR = 0.5`, `G_max = 300`, the decreasing mutation factor
//!   `F_g = 2 − g/300`, clamping of the donor to the bounds, greedy selection and a
//!   stagnation stop. Everything the paper leaves open is fixed here and documented in
//!   [`paper`].
//! * [`DeMethod::Shade`] (the default) is SHADE (Tanabe & Fukunaga 2013): Latin-hypercube
//!   initial population, success-history adaptation of `F` and `CR`,
//!   current-to-pbest/1/bin mutation with an external archive, midpoint bound handling,
//!   linear population size reduction over the evaluation budget (L-SHADE, Tanabe &
//!   Fukunaga 2014) and a convergence test on the spread of the population's objective
//!   values. See [`shade`].
//!
//! Both use a synchronous ("deferred") generation update: all trial vectors of generation
//! `g` are built from the population as it was at the start of `g`, and only then does
//! selection replace parents. Non-finite objective values count as +∞.

pub mod paper;
pub mod shade;

use rand::Rng;

use super::{
    invalid, sanitize, Bounds, Control, NoObserver, Objective, Observer, OptimizeError, Progress,
    StopReason,
};

/// Which differential-evolution variant to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum DeMethod {
    /// The paper's classic DE/rand/1/bin (P54–P59), see [`paper`].
    Paper,
    /// SHADE (Tanabe & Fukunaga 2013) with Latin-hypercube initialisation, linear population
    /// size reduction and a spread-based convergence test, see [`shade`]. The default.
    #[default]
    Shade,
}

/// Paper (P54–P59) population size `NP`.
pub const PAPER_POPULATION: usize = 50;
/// Paper (P57) crossover rate `CR`.
pub const PAPER_CROSSOVER_RATE: f64 = 0.5;
/// Paper (P59) generation limit `G_max`.
pub const PAPER_MAX_GENERATIONS: usize = 300;
/// Paper (P54) mutation factor at `g = 0`: `F_g = F_START − (F_START − F_END)·g/G_max`.
pub const PAPER_F_START: f64 = 2.0;
/// Paper (P54) mutation factor at `g = G_max`.
pub const PAPER_F_END: f64 = 1.0;
/// Stagnation window `t` of the paper's stop test P59 (not given in the paper; chosen):
/// stop when the best value changed by less than [`PAPER_STAGNATION_EPS`] over this many
/// generations.
pub const PAPER_STAGNATION_GENERATIONS: usize = 20;
/// Tolerance `ε` of the paper's stop test P59 (not given in the paper; chosen), absolute,
/// in objective units.
pub const PAPER_STAGNATION_EPS: f64 = 1e-6;

/// SHADE default initial population: `SHADE_POP_PER_DIM · dim`, clamped to
/// [`SHADE_POP_MIN`, `SHADE_POP_MAX`]; it then shrinks linearly to
/// [`SHADE_FINAL_POPULATION`] as the evaluation budget is spent, so the average population
/// over a run is about half of this. A large early population finds small basins, a small
/// late one converges quickly (measured in `tests/optimizer.rs`: a constant 20–40 lost the
/// global basin of the two-basin problems far more often for the same budget).
pub const SHADE_POP_PER_DIM: usize = 25;
/// Smallest default initial SHADE population.
pub const SHADE_POP_MIN: usize = 50;
/// Largest default initial SHADE population.
pub const SHADE_POP_MAX: usize = 100;
/// SHADE default objective-evaluation budget: sized for an objective costing 10–20 µs that
/// must be minimised in well under 50 ms.
pub const SHADE_MAX_EVALUATIONS: usize = 4000;
/// SHADE default generation limit (normally the evaluation budget binds first).
pub const SHADE_MAX_GENERATIONS: usize = 1000;
/// SHADE default absolute spread tolerance `atol` (objective units).
pub const SHADE_ATOL: f64 = 1e-12;
/// SHADE default relative spread tolerance `rtol`.
pub const SHADE_RTOL: f64 = 1e-6;
/// Final population size of the default linear population size reduction (L-SHADE,
/// Tanabe & Fukunaga 2014).
pub const SHADE_FINAL_POPULATION: usize = 4;
/// SHADE default success-history memory size `H`.
pub const SHADE_MEMORY_SIZE: usize = 6;
/// SHADE default upper limit of the pbest fraction `p` (drawn per individual uniformly in
/// `[2/NP, p_max]`). Tanabe & Fukunaga 2013 use 0.2; a larger value makes the
/// current-to-pbest mutation less greedy, which in `tests/optimizer.rs` raised the rate of
/// finding a small global basin (two-basin functions) at no cost on the unimodal ones.
pub const SHADE_PBEST_MAX: f64 = 0.6;
/// SHADE default archive size as a multiple of `NP` (`|A| = NP` in Tanabe & Fukunaga 2013).
pub const SHADE_ARCHIVE_RATE: f64 = 1.0;
/// Initial value of the SHADE memories `M_F` and `M_CR` (Tanabe & Fukunaga 2013).
pub const SHADE_INITIAL_MEMORY: f64 = 0.5;

/// Differential-evolution settings. Create with [`DifferentialEvolution::new`] (or
/// [`paper`](Self::paper) / [`shade`](Self::shade)), adjust with the checked setters, run
/// with [`minimize`](Self::minimize).
///
/// Settings that only one method uses are documented as such and ignored by the other.
#[derive(Debug, Clone, PartialEq)]
pub struct DifferentialEvolution {
    method: DeMethod,
    population_size: Option<usize>,
    max_generations: usize,
    max_evaluations: Option<usize>,
    stagnation: Option<(usize, f64)>,
    spread_tolerance: Option<(f64, f64)>,
    crossover_rate: f64,
    f_start: f64,
    f_end: f64,
    initial_f: f64,
    memory_size: usize,
    pbest_max: f64,
    archive_rate: f64,
    final_population: Option<usize>,
}

impl Default for DifferentialEvolution {
    fn default() -> Self {
        Self::new(DeMethod::default())
    }
}

impl DifferentialEvolution {
    /// Settings with the defaults of `method`.
    ///
    /// * `Paper`: `NP = 50`, `CR = 0.5`, `F_g = 2 − g/G_max`, `G_max = 300`, no evaluation
    ///   limit, stagnation stop with `t = 20`, `ε = 1e-6`, no spread test.
    /// * `Shade`: initial `NP = 25·dim` clamped to `[50, 100]`, reduced linearly to 4 over
    ///   the budget (L-SHADE), `H = 6`, `M_F = M_CR = 0.5`, `p_max = 0.6`, `|A| = NP`, at
    ///   most 4000 evaluations and 1000 generations, spread test with `atol = 1e-12`,
    ///   `rtol = 1e-6`, no stagnation stop.
    pub fn new(method: DeMethod) -> Self {
        match method {
            DeMethod::Paper => Self {
                method,
                population_size: Some(PAPER_POPULATION),
                max_generations: PAPER_MAX_GENERATIONS,
                max_evaluations: None,
                stagnation: Some((PAPER_STAGNATION_GENERATIONS, PAPER_STAGNATION_EPS)),
                spread_tolerance: None,
                crossover_rate: PAPER_CROSSOVER_RATE,
                f_start: PAPER_F_START,
                f_end: PAPER_F_END,
                initial_f: SHADE_INITIAL_MEMORY,
                memory_size: SHADE_MEMORY_SIZE,
                pbest_max: SHADE_PBEST_MAX,
                archive_rate: SHADE_ARCHIVE_RATE,
                final_population: None,
            },
            DeMethod::Shade => Self {
                method,
                population_size: None,
                max_generations: SHADE_MAX_GENERATIONS,
                max_evaluations: Some(SHADE_MAX_EVALUATIONS),
                stagnation: None,
                spread_tolerance: Some((SHADE_ATOL, SHADE_RTOL)),
                crossover_rate: SHADE_INITIAL_MEMORY,
                f_start: PAPER_F_START,
                f_end: PAPER_F_END,
                initial_f: SHADE_INITIAL_MEMORY,
                memory_size: SHADE_MEMORY_SIZE,
                pbest_max: SHADE_PBEST_MAX,
                archive_rate: SHADE_ARCHIVE_RATE,
                final_population: Some(SHADE_FINAL_POPULATION),
            },
        }
    }

    /// The paper's method with its defaults.
    pub fn paper() -> Self {
        Self::new(DeMethod::Paper)
    }

    /// SHADE with its defaults.
    pub fn shade() -> Self {
        Self::new(DeMethod::Shade)
    }

    /// The configured method.
    pub fn method(&self) -> DeMethod {
        self.method
    }

    /// Population size `NP` (≥ 4: mutation needs the target plus three distinct others);
    /// for `Shade` with population reduction, the initial size.
    pub fn population_size(mut self, np: usize) -> Result<Self, OptimizeError> {
        if np < 4 {
            return Err(invalid("population_size", np, "must be >= 4"));
        }
        self.population_size = Some(np);
        Ok(self)
    }

    /// The population size used for a problem of dimension `dim`.
    pub fn population_size_for(&self, dim: usize) -> usize {
        self.population_size
            .unwrap_or_else(|| (SHADE_POP_PER_DIM * dim).clamp(SHADE_POP_MIN, SHADE_POP_MAX))
    }

    /// Generation limit (`G_max`, ≥ 1). For `Paper` it also sets the length of the
    /// mutation-factor schedule `F_g`.
    pub fn max_generations(mut self, g: usize) -> Result<Self, OptimizeError> {
        if g == 0 {
            return Err(invalid("max_generations", g, "must be >= 1"));
        }
        self.max_generations = g;
        Ok(self)
    }

    /// Objective-evaluation budget (≥ 4, and at least `NP` when the run starts). The last
    /// generation may be cut short so the budget is never exceeded.
    pub fn max_evaluations(mut self, n: usize) -> Result<Self, OptimizeError> {
        if n < 4 {
            return Err(invalid("max_evaluations", n, "must be >= 4"));
        }
        self.max_evaluations = Some(n);
        Ok(self)
    }

    /// Removes the evaluation budget (generation limit only).
    pub fn unlimited_evaluations(mut self) -> Self {
        self.max_evaluations = None;
        self
    }

    /// Stagnation stop (P59): stop when `|best_g − best_{g−t}| < eps`, with
    /// `generations = t ≥ 1` and `eps ≥ 0` in objective units.
    pub fn stagnation(mut self, generations: usize, eps: f64) -> Result<Self, OptimizeError> {
        if generations == 0 {
            return Err(invalid(
                "stagnation.generations",
                generations,
                "must be >= 1",
            ));
        }
        if !(eps >= 0.0 && eps.is_finite()) {
            return Err(invalid("stagnation.eps", eps, "must be finite and >= 0"));
        }
        self.stagnation = Some((generations, eps));
        Ok(self)
    }

    /// Disables the stagnation stop.
    pub fn no_stagnation(mut self) -> Self {
        self.stagnation = None;
        self
    }

    /// Spread convergence test: stop when `f_worst − f_best ≤ atol + rtol·|f_best|`
    /// (`atol, rtol ≥ 0`, not both zero).
    pub fn spread_tolerance(mut self, atol: f64, rtol: f64) -> Result<Self, OptimizeError> {
        if !(atol >= 0.0 && atol.is_finite()) {
            return Err(invalid(
                "spread_tolerance.atol",
                atol,
                "must be finite and >= 0",
            ));
        }
        if !(rtol >= 0.0 && rtol.is_finite()) {
            return Err(invalid(
                "spread_tolerance.rtol",
                rtol,
                "must be finite and >= 0",
            ));
        }
        if atol == 0.0 && rtol == 0.0 {
            return Err(invalid(
                "spread_tolerance",
                "0, 0",
                "atol and rtol cannot both be 0",
            ));
        }
        self.spread_tolerance = Some((atol, rtol));
        Ok(self)
    }

    /// Disables the spread convergence test.
    pub fn no_spread_tolerance(mut self) -> Self {
        self.spread_tolerance = None;
        self
    }

    /// Crossover rate in `[0, 1]`: `CR` for `Paper` (P57); the initial value of every
    /// memory slot `M_CR` for `Shade`.
    pub fn crossover_rate(mut self, cr: f64) -> Result<Self, OptimizeError> {
        if !(0.0..=1.0).contains(&cr) {
            return Err(invalid("crossover_rate", cr, "must be in [0, 1]"));
        }
        self.crossover_rate = cr;
        Ok(self)
    }

    /// Mutation factor `F > 0` (≤ 2 for `Shade`'s memory, whose samples are capped at 1
    /// anyway): a constant `F` for `Paper` (replacing the schedule P54); the initial value
    /// of every memory slot `M_F` for `Shade`.
    pub fn mutation_factor(mut self, f: f64) -> Result<Self, OptimizeError> {
        if !(f > 0.0 && f <= 2.0) {
            return Err(invalid("mutation_factor", f, "must be in (0, 2]"));
        }
        self.f_start = f;
        self.f_end = f;
        self.initial_f = f;
        Ok(self)
    }

    /// `Paper` only: linear mutation-factor schedule `F_g = start − (start − end)·g/G_max`
    /// (P54 is `start = 2`, `end = 1`); both in `(0, 2]`.
    pub fn paper_f_schedule(mut self, start: f64, end: f64) -> Result<Self, OptimizeError> {
        for (name, v) in [
            ("paper_f_schedule.start", start),
            ("paper_f_schedule.end", end),
        ] {
            if !(v > 0.0 && v <= 2.0) {
                return Err(invalid(name, v, "must be in (0, 2]"));
            }
        }
        self.f_start = start;
        self.f_end = end;
        Ok(self)
    }

    /// `Shade` only: success-history memory size `H ≥ 1`.
    pub fn memory_size(mut self, h: usize) -> Result<Self, OptimizeError> {
        if h == 0 {
            return Err(invalid("memory_size", h, "must be >= 1"));
        }
        self.memory_size = h;
        Ok(self)
    }

    /// `Shade` only: upper limit `p_max ∈ (0, 1]` of the pbest fraction (each individual
    /// draws `p ∈ [2/NP, max(2/NP, p_max)]`).
    pub fn pbest_max(mut self, p: f64) -> Result<Self, OptimizeError> {
        if !(p > 0.0 && p <= 1.0) {
            return Err(invalid("pbest_max", p, "must be in (0, 1]"));
        }
        self.pbest_max = p;
        Ok(self)
    }

    /// `Shade` only: archive capacity as a multiple of `NP` (`≥ 0`; 0 disables the archive).
    pub fn archive_rate(mut self, rate: f64) -> Result<Self, OptimizeError> {
        if !(0.0..=10.0).contains(&rate) {
            return Err(invalid("archive_rate", rate, "must be in [0, 10]"));
        }
        self.archive_rate = rate;
        Ok(self)
    }

    /// `Shade` only: linear population size reduction (Tanabe & Fukunaga 2014, L-SHADE):
    /// after each generation the population shrinks, by dropping its worst members, to
    /// `round(NP + (final_size − NP) · evaluations / max_evaluations)`, reaching
    /// `final_size ≥ 4` when the budget is spent. Needs an evaluation budget; without one it
    /// has no effect.
    pub fn population_reduction(mut self, final_size: usize) -> Result<Self, OptimizeError> {
        if final_size < 4 {
            return Err(invalid("population_reduction", final_size, "must be >= 4"));
        }
        self.final_population = Some(final_size);
        Ok(self)
    }

    /// `Shade` only: keeps the population size constant (plain SHADE).
    pub fn no_population_reduction(mut self) -> Self {
        self.final_population = None;
        self
    }

    /// Minimises `objective` over `bounds` without progress reports.
    pub fn minimize<O, R>(
        &self,
        objective: &O,
        bounds: &Bounds,
        rng: &mut R,
    ) -> Result<DeResult, OptimizeError>
    where
        O: Objective + ?Sized,
        R: Rng + ?Sized,
    {
        self.minimize_observed(objective, bounds, rng, &mut NoObserver)
    }

    /// Minimises `objective` over `bounds`, reporting to `observer` after the initial
    /// population (generation 0) and after every generation. The run is reproducible: the
    /// same settings, objective and RNG state give a bit-identical result.
    pub fn minimize_observed<O, R, Obs>(
        &self,
        objective: &O,
        bounds: &Bounds,
        rng: &mut R,
        observer: &mut Obs,
    ) -> Result<DeResult, OptimizeError>
    where
        O: Objective + ?Sized,
        R: Rng + ?Sized,
        Obs: Observer + ?Sized,
    {
        let dim = objective.dim();
        if dim == 0 {
            return Err(OptimizeError::EmptyProblem);
        }
        if bounds.dim() != dim {
            return Err(OptimizeError::DimensionMismatch {
                what: "bounds",
                expected: dim,
                found: bounds.dim(),
            });
        }
        let np = self.population_size_for(dim);
        if let Some(max) = self.max_evaluations {
            if max < np {
                return Err(OptimizeError::BudgetTooSmall {
                    max_evaluations: max,
                    population: np,
                });
            }
        }
        let mut run = Run {
            objective,
            evaluations: 0,
            max_evaluations: self.max_evaluations.unwrap_or(usize::MAX),
            // SHADE only ranks its points; the paper's DE (P51–P59) evaluates f as written.
            by_search_value: self.method == DeMethod::Shade,
        };
        let mut pop = Population::new(np, dim);
        match self.method {
            DeMethod::Paper => paper::initialise(&mut pop, bounds, rng),
            DeMethod::Shade => shade::initialise(&mut pop, bounds, rng),
        }
        for i in 0..np {
            pop.f[i] = run.eval(pop.row(i));
        }
        let mut state = shade::State::new(self, np);

        let mut history = vec![pop.best_f()];
        let mut generation = 0;
        let stop_reason = loop {
            let best = pop.best();
            let progress = Progress {
                generation,
                evaluations: run.evaluations,
                best_f: pop.f[best],
                best_x: pop.row(best),
                spread: pop.spread(),
            };
            if observer.observe(&progress) == Control::Cancel {
                break StopReason::Cancelled;
            }
            if generation > 0 {
                if let Some((atol, rtol)) = self.spread_tolerance {
                    let best_f = pop.f[best];
                    if best_f.is_finite() && pop.spread() <= atol + rtol * best_f.abs() {
                        break StopReason::Converged;
                    }
                }
                if let Some((t, eps)) = self.stagnation {
                    if generation >= t
                        && (history[generation] - history[generation - t]).abs() < eps
                    {
                        break StopReason::Stagnated;
                    }
                }
            }
            if generation >= self.max_generations {
                break StopReason::MaxGenerations;
            }
            if run.exhausted() {
                break StopReason::MaxEvaluations;
            }
            generation += 1;
            match self.method {
                DeMethod::Paper => {
                    paper::generation(self, generation, &mut pop, bounds, &mut run, rng)
                }
                DeMethod::Shade => {
                    shade::generation(&mut state, &mut pop, bounds, &mut run, rng);
                    if let (Some(final_np), Some(max)) =
                        (self.final_population, self.max_evaluations)
                    {
                        let frac = run.evaluations as f64 / max as f64;
                        let target = np as f64 + (final_np as f64 - np as f64) * frac;
                        let target = (target.round() as usize).max(final_np.min(np)).max(4);
                        if target < pop.np {
                            pop.shrink(target);
                            state.shrink_archive(target, pop.dim, rng);
                        }
                    }
                }
            }
            history.push(pop.best_f());
        };

        let best = pop.best();
        Ok(DeResult {
            x: pop.row(best).to_vec(),
            f: pop.f[best],
            generations: generation,
            evaluations: run.evaluations,
            stop_reason,
            population: (0..pop.np).map(|i| pop.row(i).to_vec()).collect(),
            population_f: pop.f.clone(),
        })
    }
}

/// Outcome of a differential-evolution run.
#[derive(Debug, Clone, PartialEq)]
pub struct DeResult {
    /// Best parameters in the final population.
    pub x: Vec<f64>,
    /// Objective value at `x` (+∞ if no finite value was ever found).
    pub f: f64,
    /// Generations completed (the last one may have been cut short by the evaluation
    /// budget).
    pub generations: usize,
    /// Objective evaluations used.
    pub evaluations: usize,
    /// Why the run ended.
    pub stop_reason: StopReason,
    /// Final population, one parameter vector per member (for `Shade` with population
    /// reduction, the reduced population: down to 4 members when the budget ran out).
    pub population: Vec<Vec<f64>>,
    /// Objective values of the final population (non-finite values stored as +∞).
    pub population_f: Vec<f64>,
}

impl DeResult {
    /// Spread `f_worst − f_best` of the final population (+∞ if any member is non-finite).
    pub fn spread(&self) -> f64 {
        spread_of(&self.population_f)
    }
}

fn spread_of(f: &[f64]) -> f64 {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &v in f {
        if !v.is_finite() {
            return f64::INFINITY;
        }
        lo = lo.min(v);
        hi = hi.max(v);
    }
    hi - lo
}

/// Evaluation bookkeeping shared by the methods.
pub(crate) struct Run<'a, O: Objective + ?Sized> {
    objective: &'a O,
    evaluations: usize,
    max_evaluations: usize,
    /// Whether the run evaluates by [`Objective::search_value`], else [`Objective::value`].
    by_search_value: bool,
}

impl<O: Objective + ?Sized> Run<'_, O> {
    fn eval(&mut self, x: &[f64]) -> f64 {
        self.evaluations += 1;
        sanitize(if self.by_search_value {
            self.objective.search_value(x)
        } else {
            self.objective.value(x)
        })
    }

    fn exhausted(&self) -> bool {
        self.evaluations >= self.max_evaluations
    }
}

/// Population stored as a flat row-major `np × dim` array plus objective values.
#[derive(Debug, Clone)]
pub(crate) struct Population {
    np: usize,
    dim: usize,
    x: Vec<f64>,
    f: Vec<f64>,
}

impl Population {
    fn new(np: usize, dim: usize) -> Self {
        Self {
            np,
            dim,
            x: vec![0.0; np * dim],
            f: vec![f64::INFINITY; np],
        }
    }

    fn row(&self, i: usize) -> &[f64] {
        &self.x[i * self.dim..(i + 1) * self.dim]
    }

    fn row_mut(&mut self, i: usize) -> &mut [f64] {
        &mut self.x[i * self.dim..(i + 1) * self.dim]
    }

    /// Index of the best member (first one on ties).
    fn best(&self) -> usize {
        let mut best = 0;
        for i in 1..self.np {
            if self.f[i] < self.f[best] {
                best = i;
            }
        }
        best
    }

    /// Keeps the `target` best members (stable order of the survivors).
    fn shrink(&mut self, target: usize) {
        let mut order: Vec<usize> = (0..self.np).collect();
        order.sort_by(|&a, &b| self.f[a].total_cmp(&self.f[b]));
        let mut keep = order[..target].to_vec();
        keep.sort_unstable();
        let dim = self.dim;
        for (new, &old) in keep.iter().enumerate() {
            self.f[new] = self.f[old];
            self.x.copy_within(old * dim..(old + 1) * dim, new * dim);
        }
        self.np = target;
        self.f.truncate(target);
        self.x.truncate(target * dim);
    }

    fn best_f(&self) -> f64 {
        self.f[self.best()]
    }

    fn spread(&self) -> f64 {
        spread_of(&self.f)
    }
}

/// Draws an index in `0..n` different from every index in `exclude` (rejection sampling;
/// requires `n > exclude.len()`).
fn distinct_index<R: Rng + ?Sized>(rng: &mut R, n: usize, exclude: &[usize]) -> usize {
    loop {
        let k = rng.gen_range(0..n);
        if !exclude.contains(&k) {
            return k;
        }
    }
}

#[cfg(test)]
mod tests;
