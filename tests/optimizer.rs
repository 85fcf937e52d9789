//! Integration tests of `pipewave::optimize` used as a library: differential evolution on
//! standard test functions (success rates over many seeds, Paper vs SHADE), and the
//! DE → Levenberg–Marquardt → covariance pipeline on a curve fit.
//!
//! Run with `cargo test --test optimizer -- --nocapture` to see the success-rate table.

use pipewave::optimize::linalg::covariance_from_jacobian;
use pipewave::optimize::{
    Bounds, DeMethod, DifferentialEvolution, FnObjective, LeastSquares, LevenbergMarquardt,
    Objective, StopReason,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// A benchmark: objective, box, and a success test on the returned point.
struct Bench {
    name: &'static str,
    dim: usize,
    lower: f64,
    upper: f64,
    f: fn(&[f64]) -> f64,
    /// Success: the returned point lies within `tol` (max-norm) of the global minimiser.
    optimum: fn(usize) -> Vec<f64>,
    tol: f64,
}

fn sphere(x: &[f64]) -> f64 {
    x.iter().map(|v| v * v).sum()
}

fn rosenbrock(x: &[f64]) -> f64 {
    x.windows(2)
        .map(|w| 100.0 * (w[1] - w[0] * w[0]).powi(2) + (1.0 - w[0]).powi(2))
        .sum()
}

fn ackley(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let s1 = x.iter().map(|v| v * v).sum::<f64>() / n;
    let s2 = x
        .iter()
        .map(|v| (std::f64::consts::TAU * v).cos())
        .sum::<f64>()
        / n;
    -20.0 * (-0.2 * s1.sqrt()).exp() - s2.exp() + 20.0 + std::f64::consts::E
}

fn rastrigin(x: &[f64]) -> f64 {
    10.0 * x.len() as f64
        + x.iter()
            .map(|v| v * v - 10.0 * (std::f64::consts::TAU * v).cos())
            .sum::<f64>()
}

/// Centre of the rotated ellipsoid.
const ELLIPSOID_CENTRE: [f64; 4] = [1.0, -2.0, 0.5, 3.0];

/// Ill-conditioned rotated elliptic function (condition number 1e6): a narrow valley not
/// aligned with the axes. Rotation: Householder reflection `I − 2vvᵀ/vᵀv`, `v = (1,2,3,4)`.
fn rotated_ellipsoid(x: &[f64]) -> f64 {
    let v = [1.0, 2.0, 3.0, 4.0];
    let vv: f64 = v.iter().map(|a| a * a).sum();
    let d: Vec<f64> = x.iter().zip(ELLIPSOID_CENTRE).map(|(a, c)| a - c).collect();
    let vd: f64 = v.iter().zip(&d).map(|(a, b)| a * b).sum();
    (0..4)
        .map(|i| {
            let y = d[i] - 2.0 * v[i] * vd / vv;
            1e6f64.powf(i as f64 / 3.0) * y * y
        })
        .sum()
}

/// Two Gaussian wells in 2-D: a wide shallow one (depth 0.8, width 2.5 at (2.5, 2.5)) and a
/// narrower deeper one (depth 1.0, width 1.0 at (7.5, 7.0)) that holds the global minimum.
fn two_basin_2d(x: &[f64]) -> f64 {
    two_basin(x, &[2.5, 2.5], &[7.5, 7.0], 1.0)
}

/// Two Gaussian wells in 3-D, the global one the narrower: wide (depth 0.8, width 2.5 at
/// (2.5, 2.5, 2.5)) and narrow (depth 1.0, width 1.5 at (7.5, 7.0, 7.5)). Smooth.
fn two_basin_3d(x: &[f64]) -> f64 {
    two_basin(x, &[2.5, 2.5, 2.5], &[7.5, 7.0, 7.5], 1.5)
}

/// As [`two_basin_3d`] with the global well narrowed to width 1.2: only 0.2 % of the box
/// lies below the floor of the wide well, a deliberately deceptive case.
fn two_basin_3d_narrow(x: &[f64]) -> f64 {
    two_basin(x, &[2.5, 2.5, 2.5], &[7.5, 7.0, 7.5], 1.2)
}

fn two_basin(x: &[f64], wide: &[f64], narrow: &[f64], narrow_width: f64) -> f64 {
    let d2 = |c: &[f64]| x.iter().zip(c).map(|(a, b)| (a - b) * (a - b)).sum::<f64>();
    1.0 - 0.8 * (-d2(wide) / (2.0 * 2.5 * 2.5)).exp()
        - (-d2(narrow) / (2.0 * narrow_width * narrow_width)).exp()
}

/// Global minimiser of a two-Gaussian function: the narrow well's centre, shifted slightly by
/// the wide well's tail. Located by a deterministic compass search started at the centre, so
/// the reference does not rely on the optimiser under test.
fn pattern_search(f: fn(&[f64]) -> f64, start: &[f64]) -> Vec<f64> {
    let mut x = start.to_vec();
    let mut fx = f(&x);
    let mut step = 0.5;
    while step > 1e-12 {
        let mut improved = false;
        for q in 0..x.len() {
            for s in [step, -step] {
                let mut y = x.clone();
                y[q] += s;
                let fy = f(&y);
                if fy < fx {
                    x = y;
                    fx = fy;
                    improved = true;
                }
            }
        }
        if !improved {
            step *= 0.5;
        }
    }
    x
}

fn benches() -> Vec<Bench> {
    vec![
        Bench {
            name: "sphere-5D",
            dim: 5,
            lower: -5.0,
            upper: 5.0,
            f: sphere,
            optimum: |n| vec![0.0; n],
            tol: 1e-3,
        },
        Bench {
            name: "rosenbrock-2D",
            dim: 2,
            lower: -5.0,
            upper: 5.0,
            f: rosenbrock,
            optimum: |n| vec![1.0; n],
            tol: 1e-2,
        },
        Bench {
            name: "rosenbrock-3D",
            dim: 3,
            lower: -5.0,
            upper: 5.0,
            f: rosenbrock,
            optimum: |n| vec![1.0; n],
            tol: 1e-2,
        },
        Bench {
            name: "ackley-3D",
            dim: 3,
            lower: -32.768,
            upper: 32.768,
            f: ackley,
            optimum: |n| vec![0.0; n],
            tol: 1e-3,
        },
        Bench {
            name: "rastrigin-2D",
            dim: 2,
            lower: -5.12,
            upper: 5.12,
            f: rastrigin,
            optimum: |n| vec![0.0; n],
            tol: 1e-3,
        },
        Bench {
            name: "rastrigin-3D",
            dim: 3,
            lower: -5.12,
            upper: 5.12,
            f: rastrigin,
            optimum: |n| vec![0.0; n],
            tol: 1e-3,
        },
        Bench {
            name: "rot-ellipsoid-4D",
            dim: 4,
            lower: -5.0,
            upper: 5.0,
            f: rotated_ellipsoid,
            optimum: |_| ELLIPSOID_CENTRE.to_vec(),
            tol: 1e-2,
        },
        Bench {
            name: "two-basin-2D",
            dim: 2,
            lower: 0.0,
            upper: 10.0,
            f: two_basin_2d,
            optimum: |_| pattern_search(two_basin_2d, &[7.5, 7.0]),
            tol: 1e-3,
        },
        Bench {
            name: "two-basin-3D",
            dim: 3,
            lower: 0.0,
            upper: 10.0,
            f: two_basin_3d,
            optimum: |_| pattern_search(two_basin_3d, &[7.5, 7.0, 7.5]),
            tol: 1e-3,
        },
        Bench {
            name: "two-basin-3D-narrow",
            dim: 3,
            lower: 0.0,
            upper: 10.0,
            f: two_basin_3d_narrow,
            optimum: |_| pattern_search(two_basin_3d_narrow, &[7.5, 7.0, 7.5]),
            tol: 1e-3,
        },
    ]
}

#[derive(Debug, Clone, Copy)]
struct Stats {
    success: f64,
    mean_evals: f64,
    max_evals: usize,
}

fn run_bench(b: &Bench, method: DeMethod, seeds: u64) -> Stats {
    let de = DifferentialEvolution::new(method);
    let obj = FnObjective::new(b.dim, b.f);
    let bounds = Bounds::uniform(b.dim, b.lower, b.upper).unwrap();
    let opt = (b.optimum)(b.dim);
    let mut ok = 0;
    let mut evals = 0;
    let mut max_evals = 0;
    for seed in 0..seeds {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let r = de.minimize(&obj, &bounds, &mut rng).unwrap();
        let err =
            r.x.iter()
                .zip(&opt)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
        if err <= b.tol {
            ok += 1;
        }
        evals += r.evaluations;
        max_evals = max_evals.max(r.evaluations);
    }
    Stats {
        success: ok as f64 / seeds as f64,
        mean_evals: evals as f64 / seeds as f64,
        max_evals,
    }
}

/// Success rates of SHADE (the default) vs the paper's DE over 50 seeds each (100 for the
/// 3-D two-basin problems, the shape of the product's inversion). Success: the returned
/// point is within `tol` (max-norm) of the global minimiser.
#[test]
fn success_rates_default_vs_paper() {
    eprintln!(
        "{:<20} {:>5} | {:>8} {:>10} {:>6} | {:>8} {:>10} {:>6}",
        "function", "seeds", "SHADE ok", "mean evals", "max", "Paper ok", "mean evals", "max"
    );
    let mut table = std::collections::HashMap::new();
    for b in benches() {
        let seeds = if b.name.starts_with("two-basin-3D") {
            100
        } else {
            50
        };
        let s = run_bench(&b, DeMethod::Shade, seeds);
        let p = run_bench(&b, DeMethod::Paper, seeds);
        eprintln!(
            "{:<20} {:>5} | {:>8.2} {:>10.0} {:>6} | {:>8.2} {:>10.0} {:>6}",
            b.name,
            seeds,
            s.success,
            s.mean_evals,
            s.max_evals,
            p.success,
            p.mean_evals,
            p.max_evals
        );
        table.insert(b.name, (s, p));
    }
    let shade = |name: &str| table[name].0;
    let paper = |name: &str| table[name].1;
    // The default must solve the standard functions essentially always within its budget.
    for name in [
        "sphere-5D",
        "rosenbrock-2D",
        "rosenbrock-3D",
        "ackley-3D",
        "rastrigin-2D",
        "rastrigin-3D",
        "two-basin-2D",
    ] {
        assert!(shade(name).success >= 0.96, "{name}: {:?}", shade(name));
    }
    // The condition-1e6 valley needs the whole budget for 1e-2 accuracy (measured 0.94).
    assert!(shade("rot-ellipsoid-4D").success >= 0.85);
    for (name, (s, _)) in &table {
        assert!(s.max_evals <= 4000, "{name}: budget exceeded");
    }
    // The product's case: a smooth 3-D problem with two basins, the global one smaller.
    assert!(
        shade("two-basin-3D").success >= 0.97,
        "{:?}",
        shade("two-basin-3D")
    );
    // The deceptive variant is not solved reliably by either method; SHADE still does
    // far better than the paper's method (measured about 0.6–0.7 vs 0.01).
    assert!(shade("two-basin-3D-narrow").success >= 0.5);
    assert!(paper("two-basin-3D-narrow").success <= 0.2);
    // The paper's method (F from 2 down to 1, clamping, stop after 20 generations without
    // 1e-6 progress) is far less reliable: it mostly stops before reaching 1e-3 accuracy.
    for name in [
        "sphere-5D",
        "rosenbrock-2D",
        "rot-ellipsoid-4D",
        "two-basin-3D",
    ] {
        assert!(
            paper(name).success + 0.5 <= shade(name).success,
            "{name}: paper {:?} vs shade {:?}",
            paper(name),
            shade(name)
        );
    }
    // ... and where it runs to G_max it spends more evaluations than SHADE's whole budget.
    assert!(paper("ackley-3D").max_evals > 4000);
}

/// Damped oscillation `y = a exp(−b t) cos(ω t)`: its misfit in `ω` has many local minima,
/// so DE is needed to find the basin and LM to polish.
struct Oscillation {
    t: Vec<f64>,
    y: Vec<f64>,
}

impl Oscillation {
    fn model(p: &[f64], t: f64) -> f64 {
        p[0] * (-p[1] * t).exp() * (p[2] * t).cos()
    }

    /// Data from `truth` plus a deterministic zero-mean perturbation of amplitude `noise`.
    fn new(truth: [f64; 3], noise: f64) -> Self {
        let t: Vec<f64> = (0..60).map(|k| 0.1 * k as f64).collect();
        let y = t
            .iter()
            .enumerate()
            .map(|(k, &t)| Self::model(&truth, t) + noise * ((k * 7919 % 61) as f64 / 30.0 - 1.0))
            .collect();
        Self { t, y }
    }
}

impl LeastSquares for Oscillation {
    fn n_params(&self) -> usize {
        3
    }
    fn n_residuals(&self) -> usize {
        self.t.len()
    }
    fn residuals(&self, x: &[f64], out: &mut [f64]) -> bool {
        for ((o, &t), &y) in out.iter_mut().zip(&self.t).zip(&self.y) {
            *o = Self::model(x, t) - y;
        }
        true
    }
}

#[test]
fn de_then_lm_then_covariance() {
    use pipewave::optimize::SumOfSquares;
    let truth = [2.0, 0.3, 4.0];
    let bounds = Bounds::from_pairs(&[(0.1, 5.0), (0.0, 2.0), (0.5, 10.0)]).unwrap();

    // Noiseless: DE lands in the global basin, LM recovers the parameters exactly.
    let problem = Oscillation::new(truth, 0.0);
    let objective = SumOfSquares(&problem);
    assert_eq!(objective.dim(), 3);
    for seed in 0..10 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let de = DifferentialEvolution::default()
            .minimize(&objective, &bounds, &mut rng)
            .unwrap();
        assert!(de.evaluations <= 4000);
        let lm = LevenbergMarquardt::new()
            .minimize(&problem, &de.x, Some(&bounds))
            .unwrap();
        for (x, t) in lm.x.iter().zip(truth) {
            assert!(
                (x - t).abs() < 1e-7,
                "seed {seed}: {:?} from {:?}",
                lm.x,
                de.x
            );
        }
        assert!(lm.cost <= de.f);
    }

    // Noisy: the covariance from LM's Jacobian gives error bars that cover the truth.
    let problem = Oscillation::new(truth, 0.05);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let de = DifferentialEvolution::default()
        .minimize(&SumOfSquares(&problem), &bounds, &mut rng)
        .unwrap();
    let lm = LevenbergMarquardt::new()
        .minimize(&problem, &de.x, Some(&bounds))
        .unwrap();
    let (m, n) = (problem.n_residuals(), 3);
    let sigma2 = lm.cost / (m - n) as f64;
    let cov = covariance_from_jacobian(&lm.jacobian, m, n, sigma2);
    assert!(!cov.rank_deficient);
    assert!(cov.condition_number.is_finite() && cov.condition_number > 1.0);
    for (i, &t) in truth.iter().enumerate() {
        let se = cov.std_errors[i];
        assert!(se > 0.0 && se < 0.2 * t, "se[{i}] = {se}");
        assert!(
            (lm.x[i] - t).abs() < 4.0 * se,
            "param {i}: {} ± {se}",
            lm.x[i]
        );
        assert_eq!(cov.correlation[i * n + i], 1.0);
    }
    // Amplitude and decay rate are positively correlated in this model.
    assert!(cov.correlation[1] > 0.3, "{:?}", cov.correlation);
    eprintln!(
        "noisy fit: x = {:?}, se = {:?}, cond = {:.1}, DE evals {}, LM evals {}",
        lm.x, cov.std_errors, cov.condition_number, de.evaluations, lm.evaluations
    );
}

/// The stop reason is data: SHADE on a shifted sphere with non-zero minimum converges by
/// the spread test, and a tiny generation cap is reported as such.
#[test]
fn stop_reasons_are_reported() {
    let obj = FnObjective::new(2, |x: &[f64]| 1.0 + x[0] * x[0] + x[1] * x[1]);
    let bounds = Bounds::uniform(2, -3.0, 3.0).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let r = DifferentialEvolution::default()
        .minimize(&obj, &bounds, &mut rng)
        .unwrap();
    assert_eq!(r.stop_reason, StopReason::Converged);
    let r = DifferentialEvolution::default()
        .max_generations(3)
        .unwrap()
        .minimize(&obj, &bounds, &mut rng)
        .unwrap();
    assert_eq!(
        (r.stop_reason, r.generations),
        (StopReason::MaxGenerations, 3)
    );
}
