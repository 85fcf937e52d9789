//! Benchmarks printed by `pipewave bench` (speed is measured here, never asserted in tests).
//!
//! Each figure is the median over several timed batches, single-threaded, in whatever profile
//! the binary was built with (use `--release`).

use std::hint::black_box;
use std::time::Instant;

use num_complex::Complex64;

use crate::physics::solver::{
    solve_curve, solve_direct, solve_from_guess_tol, Continuation, Tolerance,
};
use crate::physics::{ContactMode, Evaluator, Fluid, Model, Pipe, Soil, System};
use crate::special::{hankel_ratio, psi};

/// One measured figure.
#[derive(Debug, Clone)]
pub struct Figure {
    /// What was timed.
    pub name: String,
    /// Median time per operation, µs.
    pub micros: f64,
    /// A note (iterations, evaluations, …).
    pub note: String,
}

/// Median of `batches` timings of `reps` calls of `f`, in µs per call.
pub fn time_per_call(batches: usize, reps: usize, mut f: impl FnMut(usize)) -> f64 {
    let mut v: Vec<f64> = (0..batches)
        .map(|b| {
            let t = Instant::now();
            for i in 0..reps {
                f(b * reps + i);
            }
            t.elapsed().as_secs_f64() * 1e6 / reps as f64
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The paper's cast-iron main (spec Appendix A case A) with the estimated soil.
pub fn case_a() -> System {
    let pipe = Pipe::new(1.22e11, 0.25, 7800.0, 0.01, 0.069, 0.006).expect("valid");
    let soil = Soil::new(4.79e7, 0.3326, 1999.0, 0.0).expect("valid");
    System::new(
        Fluid::water(),
        pipe,
        soil,
        0.0,
        Model::Full,
        ContactMode::Reciprocal,
    )
    .expect("valid")
}

/// The four Table 2 angular frequencies of the paper, rad/s.
pub const TABLE2_OMEGA: [f64; 4] = [3121.958, 4167.04, 7221.736, 10314.48];

/// Forward-model figures: special functions, one residual, one root (cold and continued) and a
/// 4-frequency evaluation with the inversion's settings.
pub fn forward_figures(scale: usize) -> Vec<Figure> {
    let sys = case_a();
    let reps = 2000 * scale;
    let mut out = Vec::new();
    let z = Complex64::new(1.1, -0.01);
    out.push(Figure {
        name: "Hankel ratio P(z) (Amos, scaled pair)".into(),
        micros: time_per_call(7, reps, |i| {
            black_box(hankel_ratio(black_box(z + 1e-9 * i as f64)).ok());
        }),
        note: "z = 1.1 - 0.01i".into(),
    });
    out.push(Figure {
        name: "fluid loading psi(z^2) (Bessel J pair)".into(),
        micros: time_per_call(7, reps, |i| {
            black_box(psi(black_box(Complex64::new(-0.3 - 1e-9 * i as f64, 0.01))).ok());
        }),
        note: "full model only".into(),
    });
    let ev = Evaluator::new(&sys, 3121.958);
    out.push(Figure {
        name: "residual F(k1), full/reciprocal".into(),
        micros: time_per_call(7, reps, |i| {
            black_box(
                ev.residual(black_box(Complex64::new(2.48 + 1e-9 * i as f64, -0.006)))
                    .ok(),
            );
        }),
        note: "2 Hankel ratios + psi + alpha".into(),
    });
    let cold = solve_direct(&sys, 3121.958).expect("root");
    out.push(Figure {
        name: "root, cold (from the in-vacuo root P39), reference tolerance".into(),
        micros: time_per_call(7, reps / 4, |i| {
            black_box(solve_direct(&sys, 3121.958 + 1e-9 * i as f64).ok());
        }),
        note: format!(
            "{} Muller iterations + 3 start evaluations",
            cold.iterations
        ),
    });
    let k0 = cold.k1;
    let w1 = 3121.958 * 1.05;
    for (label, tol) in [
        ("reference", Tolerance::REFERENCE),
        ("fast", Tolerance::FAST),
    ] {
        let r = solve_from_guess_tol(&sys, w1, k0 * (w1 / 3121.958), tol).expect("root");
        out.push(Figure {
            name: format!("root, continued from a neighbour 5 % lower, {label} tolerance"),
            micros: time_per_call(7, reps / 4, |i| {
                let w = w1 + 1e-9 * i as f64;
                black_box(solve_from_guess_tol(&sys, w, k0 * (w / 3121.958), tol).ok());
            }),
            note: format!("{} Muller iterations + 3 start evaluations", r.iterations),
        });
    }
    for (label, ramp, tol) in [
        ("inversion settings (no ramp, fast)", 0, Tolerance::FAST),
        ("8-point ramp, fast", 8, Tolerance::FAST),
        (
            "29-point ramp, reference (spec P41)",
            29,
            Tolerance::REFERENCE,
        ),
    ] {
        let opts = Continuation {
            ramp_points: ramp,
            tolerance: tol,
        };
        out.push(Figure {
            name: format!("4-frequency evaluation, {label}"),
            micros: time_per_call(7, reps / 16, |i| {
                let mut w = TABLE2_OMEGA;
                w[3] += 1e-9 * i as f64;
                black_box(solve_curve(&sys, &w, opts));
            }),
            note: "paper Table 2 frequencies, case A".into(),
        });
    }
    out
}

/// Print figures as an aligned table.
pub fn print_figures(title: &str, figs: &[Figure]) {
    println!("{title}");
    for f in figs {
        println!("  {:>10.2} us  {:<66} {}", f.micros, f.name, f.note);
    }
}
