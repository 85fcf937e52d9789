use std::cell::{Cell, RefCell};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::optimize::FnObjective;

fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

fn sphere(x: &[f64]) -> f64 {
    x.iter().map(|v| (v - 0.3) * (v - 0.3)).sum()
}

/// Records every point it is asked to evaluate.
struct Recorder<F> {
    dim: usize,
    f: F,
    points: RefCell<Vec<Vec<f64>>>,
}

impl<F: Fn(&[f64]) -> f64> Objective for Recorder<F> {
    fn dim(&self) -> usize {
        self.dim
    }
    fn value(&self, x: &[f64]) -> f64 {
        self.points.borrow_mut().push(x.to_vec());
        (self.f)(x)
    }
}

#[test]
fn setters_reject_bad_input() {
    let de = DifferentialEvolution::default();
    assert_eq!(de.method(), DeMethod::Shade);
    assert!(de.clone().population_size(3).is_err());
    assert!(de.clone().population_size(4).is_ok());
    assert!(de.clone().crossover_rate(-0.1).is_err());
    assert!(de.clone().crossover_rate(1.1).is_err());
    assert!(de.clone().crossover_rate(f64::NAN).is_err());
    assert!(de.clone().crossover_rate(0.0).is_ok());
    assert!(de.clone().crossover_rate(1.0).is_ok());
    assert!(de.clone().mutation_factor(0.0).is_err());
    assert!(de.clone().mutation_factor(-1.0).is_err());
    assert!(de.clone().mutation_factor(f64::NAN).is_err());
    assert!(de.clone().mutation_factor(2.5).is_err());
    assert!(de.clone().paper_f_schedule(2.0, 0.0).is_err());
    assert!(de.clone().max_generations(0).is_err());
    assert!(de.clone().max_evaluations(3).is_err());
    assert!(de.clone().stagnation(0, 1e-6).is_err());
    assert!(de.clone().stagnation(5, -1.0).is_err());
    assert!(de.clone().stagnation(5, f64::INFINITY).is_err());
    assert!(de.clone().spread_tolerance(0.0, 0.0).is_err());
    assert!(de.clone().spread_tolerance(-1e-9, 1e-6).is_err());
    assert!(de.clone().spread_tolerance(1e-9, f64::NAN).is_err());
    assert!(de.clone().memory_size(0).is_err());
    assert!(de.clone().pbest_max(0.0).is_err());
    assert!(de.clone().pbest_max(1.5).is_err());
    assert!(de.clone().archive_rate(-1.0).is_err());
    assert!(de.clone().population_reduction(3).is_err());
    let err = de.clone().crossover_rate(2.0).unwrap_err();
    assert!(matches!(
        err,
        OptimizeError::InvalidSetting {
            name: "crossover_rate",
            ..
        }
    ));
    assert!(err.to_string().contains("crossover_rate"));
}

#[test]
fn run_checks_dimensions_and_budget() {
    let obj = FnObjective::new(2, sphere);
    let b3 = Bounds::uniform(3, -1.0, 1.0).unwrap();
    assert!(matches!(
        DifferentialEvolution::shade().minimize(&obj, &b3, &mut rng(0)),
        Err(OptimizeError::DimensionMismatch { .. })
    ));
    let b2 = Bounds::uniform(2, -1.0, 1.0).unwrap();
    let small = DifferentialEvolution::paper().max_evaluations(10).unwrap();
    assert!(matches!(
        small.minimize(&obj, &b2, &mut rng(0)),
        Err(OptimizeError::BudgetTooSmall { .. })
    ));
    let empty = FnObjective::new(0, sphere);
    assert!(DifferentialEvolution::shade()
        .minimize(&empty, &b2, &mut rng(0))
        .is_err());
}

#[test]
fn default_population_sizes() {
    let shade = DifferentialEvolution::shade();
    assert_eq!(shade.population_size_for(1), 50);
    assert_eq!(shade.population_size_for(3), 75);
    assert_eq!(shade.population_size_for(7), 100);
    assert_eq!(DifferentialEvolution::paper().population_size_for(3), 50);
}

#[test]
fn same_seed_is_bit_identical_and_seeds_differ() {
    let obj = FnObjective::new(3, |x: &[f64]| sphere(x) + 0.1 * (5.0 * x[0]).sin().powi(2));
    let b = Bounds::uniform(3, -2.0, 2.0).unwrap();
    for de in [
        DifferentialEvolution::shade(),
        DifferentialEvolution::paper(),
    ] {
        let a = de.minimize(&obj, &b, &mut rng(7)).unwrap();
        let c = de.minimize(&obj, &b, &mut rng(7)).unwrap();
        assert_eq!(a.f.to_bits(), c.f.to_bits());
        assert_eq!(
            a.x.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            c.x.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(a, c); // populations, counts and stop reason too
        let d = de.minimize(&obj, &b, &mut rng(8)).unwrap();
        assert_ne!(a.population, d.population);
        assert_ne!(a.x, d.x);
    }
}

#[test]
fn paper_f_schedule_matches_p54() {
    let de = DifferentialEvolution::paper();
    assert_eq!(paper::mutation_factor(&de, 0), 2.0);
    assert!((paper::mutation_factor(&de, 150) - 1.5).abs() < 1e-15);
    assert!((paper::mutation_factor(&de, 300) - 1.0).abs() < 1e-15);
    assert!((paper::mutation_factor(&de, 30) - (2.0 - 30.0 / 300.0)).abs() < 1e-15);
}

#[test]
fn paper_clamps_donors_and_never_leaves_the_box() {
    // Optimum outside the box in x0: many donors (F ≈ 2) overshoot and are clamped.
    let obj = Recorder {
        dim: 2,
        f: |x: &[f64]| (x[0] - 5.0).powi(2) + x[1] * x[1],
        points: RefCell::new(Vec::new()),
    };
    let b = Bounds::from_pairs(&[(-1.0, 1.0), (-1.0, 1.0)]).unwrap();
    let r = DifferentialEvolution::paper()
        .minimize(&obj, &b, &mut rng(3))
        .unwrap();
    let pts = obj.points.borrow();
    assert_eq!(pts.len(), r.evaluations);
    assert!(pts.iter().all(|p| b.contains(p)));
    // Clamping puts points exactly on the bounds.
    let on_bound = pts
        .iter()
        .filter(|p| p.iter().any(|&v| v == 1.0 || v == -1.0))
        .count();
    assert!(on_bound > pts.len() / 10, "{on_bound} of {}", pts.len());
    assert_eq!(r.x[0], 1.0);
    assert!(r.x[1].abs() < 1e-2);
}

#[test]
fn shade_stays_in_box_with_midpoint_rule() {
    let obj = Recorder {
        dim: 2,
        f: |x: &[f64]| (x[0] - 5.0).powi(2) + x[1] * x[1],
        points: RefCell::new(Vec::new()),
    };
    let b = Bounds::uniform(2, -1.0, 1.0).unwrap();
    let r = DifferentialEvolution::shade()
        .minimize(&obj, &b, &mut rng(3))
        .unwrap();
    let pts = obj.points.borrow();
    assert!(pts.iter().all(|p| b.contains(p)));
    // Midpoint repair approaches the bound geometrically but does not pile points on it.
    let on_bound = pts.iter().filter(|p| p[0] == 1.0).count();
    assert!(on_bound < pts.len() / 100, "{on_bound}");
    assert!(1.0 - r.x[0] < 1e-6 && r.x[1].abs() < 1e-3, "{:?}", r.x);
}

#[test]
fn latin_hypercube_fills_every_stratum() {
    let np = 17;
    let mut pop = Population::new(np, 3);
    let b = Bounds::from_pairs(&[(0.0, 1.0), (-5.0, 5.0), (100.0, 200.0)]).unwrap();
    shade::initialise(&mut pop, &b, &mut rng(11));
    for q in 0..3 {
        let mut strata: Vec<usize> = (0..np)
            .map(|i| {
                let t = (pop.row(i)[q] - b.lower()[q]) / b.width(q);
                ((t * np as f64).floor() as usize).min(np - 1)
            })
            .collect();
        strata.sort_unstable();
        assert_eq!(strata, (0..np).collect::<Vec<_>>());
    }
}

#[test]
fn non_finite_region_is_avoided() {
    // The objective decreases towards x0 = -5 but is NaN for x0 < 1 and -inf for x1 > 4:
    // treating non-finite values as worst puts the optimum at x0 -> 1, x1 = 0.
    let f = |x: &[f64]| {
        if x[0] < 1.0 {
            f64::NAN
        } else if x[1] > 4.0 {
            f64::NEG_INFINITY
        } else {
            x[0] + x[1] * x[1]
        }
    };
    let obj = FnObjective::new(2, f);
    let b = Bounds::uniform(2, -5.0, 5.0).unwrap();
    // The paper's method stops early (P59) and is less precise, hence its looser tolerance.
    for (de, tol) in [
        (DifferentialEvolution::shade(), 1e-3),
        (DifferentialEvolution::paper(), 0.3),
    ] {
        for seed in 0..5 {
            let r = de.minimize(&obj, &b, &mut rng(seed)).unwrap();
            assert!(r.f.is_finite(), "{:?}", r.stop_reason);
            assert!(r.x[0] >= 1.0 && r.x[0] < 1.0 + tol, "{:?}", r.x);
            assert!(r.x[1].abs() < tol.sqrt(), "{:?}", r.x);
            assert!(r
                .population_f
                .iter()
                .all(|v| !v.is_nan() && *v > f64::NEG_INFINITY));
        }
    }
}

#[test]
fn all_infinite_objective_terminates() {
    let obj = FnObjective::new(2, |_: &[f64]| f64::NAN);
    let b = Bounds::uniform(2, -1.0, 1.0).unwrap();
    let r = DifferentialEvolution::shade()
        .minimize(&obj, &b, &mut rng(0))
        .unwrap();
    assert_eq!(r.f, f64::INFINITY);
    assert_eq!(r.stop_reason, StopReason::MaxEvaluations);
    assert_eq!(r.evaluations, SHADE_MAX_EVALUATIONS);
    let r = DifferentialEvolution::paper()
        .minimize(&obj, &b, &mut rng(0))
        .unwrap();
    assert_eq!(r.stop_reason, StopReason::MaxGenerations);
    assert_eq!(r.evaluations, 50 * 301);
}

#[test]
fn observer_sees_every_generation_and_can_cancel() {
    let obj = FnObjective::new(2, sphere);
    let b = Bounds::uniform(2, -1.0, 1.0).unwrap();
    let mut seen = Vec::new();
    let mut obs = |p: &Progress<'_>| {
        seen.push((p.generation, p.evaluations, p.best_f, p.spread));
        assert_eq!(p.best_x.len(), 2);
        if p.generation == 5 {
            Control::Cancel
        } else {
            Control::Continue
        }
    };
    let r = DifferentialEvolution::paper()
        .minimize_observed(&obj, &b, &mut rng(1), &mut obs)
        .unwrap();
    assert_eq!(r.stop_reason, StopReason::Cancelled);
    assert_eq!(r.generations, 5);
    assert_eq!(r.evaluations, 50 * 6);
    assert_eq!(seen.len(), 6);
    for (g, w) in seen.windows(2).enumerate() {
        assert_eq!(w[0].0, g);
        assert_eq!(w[1].1, w[0].1 + 50);
        assert!(w[1].2 <= w[0].2, "best must not get worse");
    }
    assert_eq!(seen[5].2, r.f);
    assert!(seen.iter().all(|s| s.3 >= 0.0));
}

#[test]
fn evaluation_budget_is_never_exceeded() {
    let count = Cell::new(0usize);
    let obj = FnObjective::new(3, |x: &[f64]| {
        count.set(count.get() + 1);
        sphere(x)
    });
    let b = Bounds::uniform(3, -5.0, 5.0).unwrap();
    for budget in [75, 76, 123, 1001] {
        count.set(0);
        let de = DifferentialEvolution::shade()
            .no_spread_tolerance()
            .max_evaluations(budget)
            .unwrap();
        let r = de.minimize(&obj, &b, &mut rng(2)).unwrap();
        assert_eq!(r.evaluations, budget);
        assert_eq!(count.get(), budget);
        assert_eq!(r.stop_reason, StopReason::MaxEvaluations);
    }
    // Population reduction shrinks the final population to 4.
    let r = DifferentialEvolution::shade()
        .no_spread_tolerance()
        .minimize(&obj, &b, &mut rng(2))
        .unwrap();
    assert_eq!(r.population.len(), SHADE_FINAL_POPULATION);
    let r = DifferentialEvolution::shade()
        .no_spread_tolerance()
        .no_population_reduction()
        .minimize(&obj, &b, &mut rng(2))
        .unwrap();
    assert_eq!(r.population.len(), 75);
}

/// Counts the evaluations by [`Objective::value`] and by [`Objective::search_value`], whose
/// values differ (a lower precision's error, as the inversion's problem).
struct TwoPrecisions {
    values: Cell<usize>,
    search_values: Cell<usize>,
}

impl Objective for TwoPrecisions {
    fn dim(&self) -> usize {
        2
    }
    fn value(&self, x: &[f64]) -> f64 {
        self.values.set(self.values.get() + 1);
        sphere(x)
    }
    fn search_value(&self, x: &[f64]) -> f64 {
        self.search_values.set(self.search_values.get() + 1);
        sphere(x) * (1.0 + 1e-7)
    }
}

/// SHADE ranks its population by search values only, and its answer carries one; the paper's
/// DE (P51–P59) evaluates the objective as written.
#[test]
fn shade_ranks_by_search_values_and_the_paper_by_values() {
    let b = Bounds::uniform(2, -5.0, 5.0).unwrap();
    for method in [DeMethod::Shade, DeMethod::Paper] {
        let obj = TwoPrecisions {
            values: Cell::new(0),
            search_values: Cell::new(0),
        };
        let r = DifferentialEvolution::new(method)
            .max_evaluations(400)
            .unwrap()
            .minimize(&obj, &b, &mut rng(3))
            .unwrap();
        let (values, searched) = (obj.values.get(), obj.search_values.get());
        match method {
            DeMethod::Shade => {
                assert_eq!((values, searched), (0, r.evaluations));
                assert_eq!(r.f, sphere(&r.x) * (1.0 + 1e-7));
            }
            DeMethod::Paper => {
                assert_eq!((values, searched), (r.evaluations, 0));
                assert_eq!(r.f, sphere(&r.x));
            }
        }
    }
}

#[test]
fn shade_converges_on_spread_with_nonzero_minimum() {
    // Minimum value 2: the relative tolerance decides; the result's spread obeys it.
    let obj = FnObjective::new(3, |x: &[f64]| 2.0 + sphere(x));
    let b = Bounds::uniform(3, -5.0, 5.0).unwrap();
    let r = DifferentialEvolution::shade()
        .minimize(&obj, &b, &mut rng(4))
        .unwrap();
    assert_eq!(r.stop_reason, StopReason::Converged);
    assert!(r.spread() <= SHADE_ATOL + SHADE_RTOL * r.f.abs());
    assert!((r.f - 2.0).abs() < 1e-6);
    assert!(r.evaluations < SHADE_MAX_EVALUATIONS);
}

#[test]
fn paper_stagnation_stop_follows_p59() {
    // A flat objective: the best never changes, so P59 fires after exactly t generations.
    let obj = FnObjective::new(2, |_: &[f64]| 1.0);
    let b = Bounds::uniform(2, -1.0, 1.0).unwrap();
    let r = DifferentialEvolution::paper()
        .minimize(&obj, &b, &mut rng(0))
        .unwrap();
    assert_eq!(r.stop_reason, StopReason::Stagnated);
    assert_eq!(r.generations, PAPER_STAGNATION_GENERATIONS);
    let r = DifferentialEvolution::paper()
        .stagnation(7, 1e-3)
        .unwrap()
        .minimize(&obj, &b, &mut rng(0))
        .unwrap();
    assert_eq!(r.generations, 7);
    let r = DifferentialEvolution::paper()
        .no_stagnation()
        .max_generations(12)
        .unwrap()
        .minimize(&obj, &b, &mut rng(0))
        .unwrap();
    assert_eq!(
        (r.stop_reason, r.generations),
        (StopReason::MaxGenerations, 12)
    );
}

#[test]
fn paper_mechanics_solve_sphere_with_moderate_f() {
    // The paper's operators with a conventional F = 0.5 and no early stop: plain
    // DE/rand/1/bin must converge on a sphere, showing that its poor default success in the
    // benchmarks comes from F_g ∈ [1, 2] and the stop rule, not from a broken operator.
    let obj = FnObjective::new(4, sphere);
    let b = Bounds::uniform(4, -5.0, 5.0).unwrap();
    let de = DifferentialEvolution::paper()
        .mutation_factor(0.5)
        .unwrap()
        .no_stagnation();
    for seed in 0..5 {
        let r = de.minimize(&obj, &b, &mut rng(seed)).unwrap();
        assert!(r.f < 1e-12, "seed {seed}: {}", r.f);
        assert_eq!(r.stop_reason, StopReason::MaxGenerations);
    }
}
