//! Benchmarks printed by `pipewave bench` (speed is measured here, never asserted in tests).
//!
//! Each figure is the median over several timed batches, single-threaded, in whatever profile
//! the binary was built with (use `--release`). [`throughput`] times a whole calibrate run.

pub mod throughput;

use std::hint::black_box;
use std::time::Instant;

use num_complex::Complex64;

use crate::physics::solver::{
    solve_curve, solve_direct, solve_from_guess_tol, Continuation, Tolerance,
};
use crate::physics::{ContactMode, Evaluator, Fluid, Model, Pipe, Soil, System};
use crate::special::{bessel_j_ratio, hankel_ratio, hankel_ratio_amos, principal_sqrt, psi};
use crate::synth::bench::BenchSegment;

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

/// The paper's cast-iron main (model Appendix A case A) with the estimated soil.
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
    for (label, zz, note) in [
        ("radiating", z, "z = 1.1 - 0.01i"),
        ("evanescent", Complex64::new(0.02, -3.0), "z = 0.02 - 3i"),
    ] {
        out.push(Figure {
            name: format!("Hankel ratio P(z), {label} (K0/K1 series or continued fraction)"),
            micros: time_per_call(7, reps, |i| {
                black_box(hankel_ratio(black_box(zz + 1e-9 * i as f64)).ok());
            }),
            note: note.into(),
        });
        out.push(Figure {
            name: format!("Hankel ratio P(z), {label} (Amos, scaled pair, as in 0.1)"),
            micros: time_per_call(7, reps, |i| {
                black_box(hankel_ratio_amos(black_box(zz + 1e-9 * i as f64)).ok());
            }),
            note: note.into(),
        });
    }
    out.push(Figure {
        name: "fluid loading psi(z^2) (continued fraction)".into(),
        micros: time_per_call(7, reps, |i| {
            black_box(psi(black_box(Complex64::new(-0.3 - 1e-9 * i as f64, 0.01))).ok());
        }),
        note: "full model only".into(),
    });
    out.push(Figure {
        name: "fluid loading psi(z^2) (Amos J pair, as in 0.1)".into(),
        micros: time_per_call(7, reps, |i| {
            // ψ = z·J₀(z)/(2·J₁(z)) with z = √w (eq. P24), the ratio by Amos: the path psi
            // takes beyond the continued fraction's range, and the only one pipewave 0.1 had.
            let z = principal_sqrt(black_box(Complex64::new(-0.3 - 1e-9 * i as f64, 0.01)));
            black_box(bessel_j_ratio(z).map(|q| z * q * 0.5).ok());
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
            note: match tol.method {
                crate::physics::solver::RootMethod::Muller => {
                    format!("{} Muller iterations + 3 start evaluations", r.iterations)
                }
                crate::physics::solver::RootMethod::Newton => {
                    format!("{} Newton iterations (F and dF/dk1 each)", r.iterations)
                }
            },
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

/// One line of the inversion benchmark.
#[derive(Debug, Clone)]
pub struct FitFigure {
    /// Case and method.
    pub name: String,
    /// Median wall time per fit, ms (one core).
    pub ms_per_fit: f64,
    /// Mean forward evaluations per fit.
    pub evaluations: f64,
    /// Fits that reached the global optimum (within 1e-6 relative of the reference misfit).
    pub global: usize,
    /// Fits within the looser criterion (Δχ² = 1 for chi-square, 1 % otherwise).
    pub global_stat: Option<usize>,
    /// Which looser criterion.
    pub loose_label: &'static str,
    /// Fits run.
    pub runs: usize,
}

/// The paper's cast-iron case (Table 2, inferred DN125 geometry): 4 frequencies, no stds, as
/// in the sample network (`network::published::lu2022`).
pub fn paper_case_data() -> crate::invert::SegmentData {
    crate::synth::network::published::lu2022()
        .and_then(|c| {
            c.segment_data()
                .map_err(|e| crate::synth::network::published::PublishedDataError {
                    file: "seed_cast_iron_table2.csv",
                    line: 0,
                    message: e.to_string(),
                })
        })
        .expect("the embedded published data are valid")
}

/// A synthetic 4-frequency DN150 ductile-iron segment in loam with stated 1 %/5 % noise.
pub fn synthetic_iron_data() -> crate::invert::SegmentData {
    use rand::SeedableRng;
    let pipe = Pipe::new(1.70e11, 0.28, 7100.0, 0.01, 0.082, 0.006).expect("valid");
    let soil = Soil::new(5.0e7, 0.35, 1900.0, 0.0).expect("valid");
    let sys = System::new(
        Fluid::water(),
        pipe,
        soil,
        0.3,
        Model::Full,
        ContactMode::Reciprocal,
    )
    .expect("valid");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let meas = crate::synth::measure(&sys, &[150.0, 400.0, 800.0, 1300.0], &mut rng)
        .expect("forward model solves");
    crate::synth::segment_data(crate::physics::Material::DuctileIron, pipe, 1900.0, &meas)
}

/// A synthetic 6-frequency MDPE service pipe (OD 125 mm, SDR 11) in sand, stated noise: a
/// case whose soil is well identified.
pub fn synthetic_mdpe_data() -> crate::invert::SegmentData {
    use rand::SeedableRng;
    let props = crate::physics::Material::Mdpe.typical();
    let pipe = Pipe::from_outside_diameter(props, 0.125, 0.0114).expect("valid");
    let soil = Soil::new(8.0e7, 0.3, 1850.0, 0.0).expect("valid");
    let sys = System::new(
        Fluid::water(),
        pipe,
        soil,
        0.5,
        Model::Full,
        ContactMode::Reciprocal,
    )
    .expect("valid");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
    let meas = crate::synth::measure(&sys, &[80.0, 150.0, 250.0, 350.0, 450.0, 550.0], &mut rng)
        .expect("forward model solves");
    crate::synth::segment_data(crate::physics::Material::Mdpe, pipe, 1850.0, &meas)
}

/// Fit time, evaluations and global-optimum rate, default against paper method, over `seeds`
/// seeds.
///
/// Each method is judged on its own objective (the default's chi-square, or relative least
/// squares without stds; the paper's f of P53). The reference optimum of an objective is the
/// lowest value found by any run: a long default fit (4 restarts of 3000 evaluations per
/// parameter), four long paper runs, and every benchmarked run. A run "finds the global
/// optimum" when it ends within 1e-6 relative of that value (`global`); the looser
/// `global_stat` counts runs within Δχ² = 1 for chi-square (statistically indistinguishable, a
/// one-sigma region) and within 1 % otherwise.
pub fn inversion_figures(seeds: usize) -> Vec<FitFigure> {
    use crate::invert::{fit_segment, FitSettings, Weighting};
    let mut out = Vec::new();
    for (case, data) in [
        ("paper cast-iron case (no stds)", paper_case_data()),
        (
            "synthetic DI DN150, 4 frequencies (chi-square)",
            synthetic_iron_data(),
        ),
        (
            "synthetic MDPE 125 mm, 6 frequencies (chi-square)",
            synthetic_mdpe_data(),
        ),
    ] {
        let long = FitSettings {
            restarts: 4,
            evaluations_per_dimension: 3000,
            ..FitSettings::default()
        };
        let paper = FitSettings::paper(Model::Full, ContactMode::Reciprocal);
        let mut best_default = fit_segment(&data, &long, 12345).misfit;
        let mut best_paper = (0..4)
            .map(|s| fit_segment(&data, &paper, 1000 + s).misfit)
            .fold(f64::INFINITY, f64::min);
        let mut rows = Vec::new();
        for (label, settings) in [("default", FitSettings::default()), ("paper", paper)] {
            let mut times = Vec::with_capacity(seeds);
            let mut misfits = Vec::with_capacity(seeds);
            let mut evals = 0usize;
            let mut weighting = Weighting::Relative;
            for seed in 0..seeds as u64 {
                let t = Instant::now();
                let r = fit_segment(&data, &settings, seed);
                times.push(t.elapsed().as_secs_f64() * 1e3);
                evals += r.evaluations;
                misfits.push(r.misfit);
                weighting = r.weighting;
            }
            let best = misfits.iter().copied().fold(f64::INFINITY, f64::min);
            if label == "default" {
                best_default = best_default.min(best);
            } else {
                best_paper = best_paper.min(best);
            }
            times.sort_by(f64::total_cmp);
            rows.push((label, times[times.len() / 2], evals, misfits, weighting));
        }
        for (label, ms, evals, misfits, weighting) in rows {
            let target = if label == "default" {
                best_default
            } else {
                best_paper
            };
            let global = misfits
                .iter()
                .filter(|&&m| m <= target * (1.0 + 1e-6))
                .count();
            // The looser criterion: within Δχ² = 1 for chi-square, otherwise within 1 % of the
            // reference objective value.
            let stat = if label == "default" && weighting == Weighting::ChiSquare {
                misfits.iter().filter(|&&m| m <= target + 1.0).count()
            } else {
                misfits.iter().filter(|&&m| m <= target * 1.01).count()
            };
            out.push(FitFigure {
                name: format!("{case}, {label} method"),
                ms_per_fit: ms,
                evaluations: evals as f64 / seeds as f64,
                global,
                global_stat: Some(stat),
                loose_label: if label == "default" && weighting == Weighting::ChiSquare {
                    "chi2 + 1"
                } else {
                    "1 %"
                },
                runs: seeds,
            });
        }
    }
    out
}

/// Print the inversion figures.
pub fn print_fit_figures(figs: &[FitFigure]) {
    println!("inversion of one segment (one core):");
    for f in figs {
        let stat = f
            .global_stat
            .map(|s| format!(" (within {}: {s}/{})", f.loose_label, f.runs))
            .unwrap_or_default();
        println!(
            "  {:>8.1} ms/fit  {:>7.0} evaluations/fit  global optimum {:>3}/{:<3}{stat}  {}",
            f.ms_per_fit, f.evaluations, f.global, f.runs, f.name
        );
    }
}

/// What one timed fit of a network segment gave.
#[derive(Debug, Clone)]
pub struct TimedFit {
    /// Wall time of the fit and its stored curve, ms.
    pub ms: f64,
    /// CPU time of the fit and its stored curve on this thread, ms.
    pub cpu_ms: f64,
    /// Forward evaluations of the fit.
    pub evaluations: usize,
    /// The final misfit (NaN when the fit failed).
    pub misfit: f64,
    /// The fit failed.
    pub failed: bool,
    /// Wall time of building the result after the search (what the data determine: soil
    /// speeds, intervals, the curve with its errors, findings), ms.
    pub result_ms: f64,
    /// Which stage of the search found the answer, and what every stage did.
    pub provenance: crate::invert::Provenance,
}

/// Fit one segment with its stored curve (what a `calibrate` worker does: the fit result
/// carries the curve with its errors), timed.
pub fn timed_fit(seg: &BenchSegment, settings: &crate::invert::FitSettings) -> TimedFit {
    let t = Instant::now();
    let cpu = thread_cpu_ms();
    let r = crate::invert::fit_segment(&seg.data, settings, seg.seed);
    black_box(r.curve.len());
    TimedFit {
        result_ms: r.result_seconds * 1e3,
        cpu_ms: thread_cpu_ms() - cpu,
        ms: t.elapsed().as_secs_f64() * 1e3,
        evaluations: r.evaluations,
        misfit: r.misfit,
        failed: r.status == crate::types::FitStatus::Failed,
        provenance: r.provenance,
    }
}

/// Median, 90th, 99th percentile and maximum of a sample (type-7 quantiles), with its mean.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Distribution {
    /// Median.
    pub median: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Maximum.
    pub max: f64,
    /// Mean.
    pub mean: f64,
}

impl Distribution {
    /// The distribution of `v` (NaN everywhere when empty).
    pub fn of(v: &[f64]) -> Self {
        let mut s: Vec<f64> = v.to_vec();
        s.sort_by(f64::total_cmp);
        let q = |p: f64| crate::synth::network::recovery::quantile(&s, p);
        Distribution {
            median: q(0.5),
            p90: q(0.9),
            p99: q(0.99),
            max: s.last().copied().unwrap_or(f64::NAN),
            mean: s.iter().sum::<f64>() / s.len().max(1) as f64,
        }
    }
}

/// CPU time of the calling thread, ms: unlike wall time, not inflated when other processes
/// share the cores. Portable through the `cpu-time` crate (`CLOCK_THREAD_CPUTIME_ID` on Unix,
/// `GetThreadTimes` on Windows); NaN where the platform cannot tell.
pub fn thread_cpu_ms() -> f64 {
    cpu_time::ThreadTime::try_now().map_or(f64::NAN, |t| t.as_duration().as_secs_f64() * 1e3)
}

/// Per-fit figures of the default fit on a network. An earlier version is timed by building it
/// beside this one and alternating the two (`scripts/compare-builds.sh`), not inside this run.
#[derive(Debug, Clone)]
pub struct NetworkRun {
    /// One entry per segment, in network order.
    pub fits: Vec<TimedFit>,
}

impl NetworkRun {
    /// Distribution of the per-fit CPU time, ms.
    pub fn cpu(&self) -> Distribution {
        Distribution::of(&self.fits.iter().map(|f| f.cpu_ms).collect::<Vec<_>>())
    }
    /// Distribution of the per-fit wall time, ms.
    pub fn wall(&self) -> Distribution {
        Distribution::of(&self.fits.iter().map(|f| f.ms).collect::<Vec<_>>())
    }
    /// Mean evaluations per fit.
    pub fn mean_evaluations(&self) -> f64 {
        self.fits.iter().map(|f| f.evaluations).sum::<usize>() as f64
            / self.fits.len().max(1) as f64
    }
    /// Failed fits.
    pub fn failed(&self) -> usize {
        self.fits.iter().filter(|f| f.failed).count()
    }
    /// What the search's stages did over these fits.
    pub fn stages(&self) -> crate::invert::StageStatistics {
        let mut s = crate::invert::StageStatistics::default();
        for f in &self.fits {
            s.observe(&f.provenance);
        }
        s
    }
}

/// Time the default fit (with its stored curve) on every segment of `net`, one after another on
/// the calling thread.
pub fn network_figures(net: &[BenchSegment]) -> NetworkRun {
    let settings = crate::invert::FitSettings::default();
    NetworkRun {
        fits: net.iter().map(|seg| timed_fit(seg, &settings)).collect(),
    }
}

/// Print the network figures: per-fit CPU and wall time, evaluations, the share of the time
/// spent building the result, and what the search's stages did.
pub fn print_network_figures(label: &str, run: &NetworkRun) {
    println!(
        "fits on a realistic synthetic network ({label}, {} segments, fit + stored curve, one core):",
        run.fits.len()
    );
    let (c, w) = (run.cpu(), run.wall());
    println!(
        "  CPU ms/fit: median {:>6.1}  p90 {:>6.1}  p99 {:>6.1}  max {:>7.1}  mean {:>6.1} \
         | wall median {:>6.1} max {:>7.1} | {:>5.0} evaluations/fit, {} failed",
        c.median,
        c.p90,
        c.p99,
        c.max,
        c.mean,
        w.median,
        w.max,
        run.mean_evaluations(),
        run.failed()
    );
    let (res, all): (f64, f64) = run
        .fits
        .iter()
        .fold((0.0, 0.0), |(a, b), f| (a + f.result_ms, b + f.ms));
    println!(
        "  of the fits' wall time, {:.1} % builds the result after the search (soil speeds, \
         intervals, curve with errors, findings)",
        100.0 * res / all.max(f64::MIN_POSITIVE)
    );
    print!("{}", run.stages());
}

/// Evaluations per parameter of each DE run of the exhaustive search ([`exhaustive_fit`]):
/// about 29× the default budget ([`crate::invert::fit::DEFAULT_EVALUATIONS_PER_DIMENSION`]).
pub const EXHAUSTIVE_EVALUATIONS_PER_DIMENSION: usize = 3200;
/// Restarts of the exhaustive search ([`exhaustive_fit`]).
pub const EXHAUSTIVE_RESTARTS: usize = 6;
/// `bench --verify` passes when no segment's χ² is more than this above the yardstick's.
pub const VERIFY_DCHI2_MAX: f64 = 0.1;

/// The default fit's own search run far longer: [`EXHAUSTIVE_RESTARTS`] DE runs of
/// [`EXHAUSTIVE_EVALUATIONS_PER_DIMENSION`] evaluations per parameter, probes included, from
/// another seed. `bench --verify` judged the fit against it up to fit algorithm 20; it shares
/// the search's code, so it now serves only to check the yardstick
/// ([`crate::invert::yardstick`]) against what the search itself can reach
/// (`examples/search_misses.rs`).
pub fn exhaustive_fit(seg: &BenchSegment) -> crate::invert::FitResult {
    let exhaustive = crate::invert::FitSettings {
        restarts: EXHAUSTIVE_RESTARTS,
        evaluations_per_dimension: EXHAUSTIVE_EVALUATIONS_PER_DIMENSION,
        ..crate::invert::FitSettings::default()
    };
    crate::invert::fit_segment(
        &seg.data,
        &exhaustive,
        crate::seed::splitmix64(seg.seed ^ 0x5eed),
    )
}

/// One segment of `bench --verify`.
#[derive(Debug, Clone)]
pub struct VerifyRow {
    /// Asset id.
    pub id: String,
    /// Inventory material.
    pub material: crate::physics::Material,
    /// χ² of the default fit.
    pub chi2: f64,
    /// χ² of the independent yardstick ([`crate::invert::yardstick`]); NaN where it could not
    /// rate the segment.
    pub chi2_yardstick: f64,
    /// Forward evaluations of the yardstick.
    pub yardstick_evaluations: usize,
    /// Which stage of the search found the fit's answer, and what every stage did.
    pub provenance: crate::invert::Provenance,
}

impl VerifyRow {
    /// χ² of the default fit above the yardstick's (0 where the fit is lower or the yardstick
    /// could not rate the segment; NaN when the fit failed).
    pub fn excess(&self) -> f64 {
        self.chi2 - self.chi2_yardstick.min(self.chi2)
    }
}

/// Fit every segment of `net` with the default settings and rate it with the independent
/// yardstick, on `jobs` threads (the figures do not depend on the thread count).
pub fn verify(net: &[BenchSegment], jobs: usize) -> Vec<VerifyRow> {
    use rayon::prelude::*;
    let settings = crate::invert::FitSettings::default();
    let work = || {
        net.par_iter()
            .map(|seg| {
                let cur = crate::invert::fit_segment(&seg.data, &settings, seg.seed);
                let yard = crate::invert::yardstick::yardstick(&seg.data, &settings);
                VerifyRow {
                    id: seg.id.clone(),
                    material: seg.material,
                    chi2: cur.misfit,
                    chi2_yardstick: yard.as_ref().map_or(f64::NAN, |y| y.misfit),
                    yardstick_evaluations: yard.as_ref().map_or(0, |y| y.evaluations),
                    provenance: cur.provenance,
                }
            })
            .collect()
    };
    match rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.max(1))
        .build()
    {
        Ok(pool) => pool.install(work),
        Err(_) => work(),
    }
}

/// Print the worst case of `bench --verify` and the share of fits each search stage won; true
/// when every segment passes.
pub fn print_verify(rows: &[VerifyRow]) -> bool {
    use crate::invert::yardstick as y;
    let failed = rows.iter().filter(|r| !r.chi2.is_finite()).count();
    let unrated = rows.iter().filter(|r| r.chi2_yardstick.is_nan()).count();
    let worst = rows
        .iter()
        .filter(|r| r.chi2.is_finite())
        .max_by(|a, b| a.excess().total_cmp(&b.excess()));
    let over = rows
        .iter()
        .filter(|r| r.excess().is_nan() || r.excess() > VERIFY_DCHI2_MAX)
        .count();
    let default = crate::invert::FitSettings::default();
    let evaluations = rows.iter().map(|r| r.yardstick_evaluations).sum::<usize>() as f64
        / rows.len().max(1) as f64;
    println!(
        "verify: {} segments, default fit ({} evaluations per parameter, {} restarts) against \
         the yardstick: a grid of ln c_P every {} (and {:?} of each gap between measured phase \
         speeds) by {} values of c_S/c_P by {} of the contact ({} by {} at the gap points), \
         its {} best minima polished ({:.0} evaluations a segment)",
        rows.len(),
        default.evaluations_per_dimension,
        default.restarts,
        y::LN_CP_STEP,
        y::GAP_FRACTIONS,
        y::R_POINTS,
        y::XI_POINTS,
        y::GAP_R_POINTS,
        y::GAP_XI_POINTS,
        y::POLISHED,
        evaluations
    );
    if let Some(w) = worst {
        println!(
            "  worst: {} ({:?}) chi2 {:.4} vs yardstick {:.4}: {:+.4}",
            w.id,
            w.material,
            w.chi2,
            w.chi2_yardstick,
            w.excess()
        );
    }
    println!(
        "  {} segment(s) more than {} above the yardstick's chi2 (failed fits count), {} failed, \
         {} not rated by the yardstick",
        over, VERIFY_DCHI2_MAX, failed, unrated
    );
    let mut listed: Vec<&VerifyRow> = rows
        .iter()
        .filter(|r| r.excess().is_nan() || r.excess() > VERIFY_DCHI2_MAX)
        .collect();
    listed.sort_by(|a, b| b.excess().total_cmp(&a.excess()));
    for r in listed {
        println!(
            "    {} ({:?}) chi2 {:.4} vs yardstick {:.4}: {:+.4}",
            r.id,
            r.material,
            r.chi2,
            r.chi2_yardstick,
            r.excess()
        );
    }
    let mut stages = crate::invert::StageStatistics::default();
    for r in rows {
        stages.observe(&r.provenance);
    }
    print!("{stages}");
    over == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_cpu_time_counts_this_threads_work_not_its_sleep() {
        let t0 = thread_cpu_ms();
        assert!(t0.is_finite() && t0 >= 0.0, "{t0}");
        std::thread::sleep(std::time::Duration::from_millis(200));
        let slept = thread_cpu_ms() - t0;
        // Busy work: about 50 ms of arithmetic on any machine of the last decade.
        let t1 = thread_cpu_ms();
        let mut x = 1.0f64;
        for i in 0..20_000_000u64 {
            x = (x * 1.000_000_1 + (i & 7) as f64).sqrt();
        }
        black_box(x);
        let worked = thread_cpu_ms() - t1;
        assert!(slept < 50.0, "sleeping 200 ms cost {slept} ms of CPU");
        assert!(worked > slept, "work {worked} ms, sleep {slept} ms");
    }

    #[test]
    fn quantiles_are_type_7() {
        let v: Vec<f64> = (1..=11).rev().map(f64::from).collect();
        let d = Distribution::of(&v);
        assert_eq!(d.median, 6.0);
        assert!((d.p90 - 10.0).abs() < 1e-12);
        assert!((d.p99 - 10.9).abs() < 1e-12);
        assert_eq!(d.max, 11.0);
        assert_eq!(d.mean, 6.0);
        assert!(Distribution::of(&[]).median.is_nan());
    }
}
