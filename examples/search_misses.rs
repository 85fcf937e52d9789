//! How often the default fit ends more than 0.1 in χ² above the independent yardstick
//! (`invert::yardstick`), over fresh realistic networks, and which search stage found each
//! answer; with `exhaustive`, also how often the yardstick reaches the χ² of the default
//! search run far longer (`bench::exhaustive_fit`).
//!
//! search_misses MIX SEED NETWORKS SEGMENTS JOBS [exhaustive]
//!
//! Each fit is timed on the thread's CPU clock.
//!
//! MIX is `default` or `plastic-heavy`; the networks have seeds SEED, SEED + 1, …. The figures
//! do not depend on JOBS. With ROWS=1, every segment's χ² and evaluations are printed too.
//! With YARDSTICK=0 the yardstick is not run (about 1 s a segment): with ROWS=1, a fast paired
//! comparison of two builds, segment by segment; only the segments whose χ² rose need the
//! yardstick (ONLY=ID) to tell a new miss. RESTARTS=N and EVALUATIONS=N set the fit's DE runs
//! and their budget per parameter (`FitSettings`; the yardstick keeps the defaults), to
//! measure what a larger global stage buys.

use std::time::Instant;

use pipewave::bench::{exhaustive_fit, thread_cpu_ms, Distribution, VERIFY_DCHI2_MAX};
use pipewave::invert::yardstick::yardstick;
use pipewave::invert::{fit_segment, FitSettings, StageStatistics};
use pipewave::synth::bench::{bench_network, MaterialMix};
use rayon::prelude::*;

/// One segment's figures.
struct Row {
    id: String,
    material: pipewave::physics::Material,
    fit: f64,
    yard: f64,
    exhaustive: Option<f64>,
    /// Where the exhaustive search's and the yardstick's optima lie, in the speed coordinates.
    places: String,
    /// Where the fit lies.
    place: String,
    yard_evaluations: usize,
    provenance: pipewave::invert::Provenance,
    /// The fit's CPU ms and evaluations.
    cost: (f64, usize),
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let usage = "search_misses MIX SEED NETWORKS SEGMENTS JOBS [exhaustive]";
    let arg = |i: usize| args.get(i).map(String::as_str).unwrap_or("");
    let parsed = (|| -> Result<(MaterialMix, u64, u64, usize, usize), String> {
        Ok((
            arg(1).parse()?,
            arg(2).parse().map_err(|e| format!("SEED: {e}"))?,
            arg(3).parse().map_err(|e| format!("NETWORKS: {e}"))?,
            arg(4).parse().map_err(|e| format!("SEGMENTS: {e}"))?,
            arg(5).parse().map_err(|e| format!("JOBS: {e}"))?,
        ))
    })();
    let (mix, seed, networks, segments, jobs) = match parsed {
        Ok(p) => p,
        Err(e) => {
            eprintln!("{e}\nusage: {usage}");
            std::process::exit(2);
        }
    };
    let exhaustive = arg(6) == "exhaustive";
    let with_yardstick = std::env::var("YARDSTICK").map_or(true, |v| v != "0");
    let settings = FitSettings::default();
    let budget = |name: &str, default: usize| -> usize {
        match std::env::var(name) {
            Ok(v) => v.parse().unwrap_or_else(|e| {
                eprintln!("{name}={v}: {e}");
                std::process::exit(2);
            }),
            Err(_) => default,
        }
    };
    let fit_settings = FitSettings {
        restarts: budget("RESTARTS", settings.restarts),
        evaluations_per_dimension: budget("EVALUATIONS", settings.evaluations_per_dimension),
        ..settings.clone()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.max(1))
        .build()
        .expect("a thread pool");
    let started = Instant::now();
    let mut rows: Vec<Row> = Vec::new();
    for n in 0..networks {
        let mut net = bench_network(segments, seed + n, mix);
        // ONLY=ID,ID,…: only these segments of each network (to look at a few again).
        if let Ok(only) = std::env::var("ONLY") {
            net.retain(|s| only.split(',').any(|id| id == s.id));
        }
        rows.extend(pool.install(|| {
            net.par_iter()
                .map(|seg| {
                    let t = thread_cpu_ms();
                    let fit = fit_segment(&seg.data, &fit_settings, seg.seed);
                    let ms = thread_cpu_ms() - t;
                    let yard = with_yardstick.then(|| yardstick(&seg.data, &settings));
                    let yard = yard.as_ref().and_then(|y| y.as_ref().ok());
                    let ex = exhaustive.then(|| exhaustive_fit(seg));
                    Row {
                        id: format!("{}/{}", seed + n, seg.id),
                        material: seg.material,
                        fit: fit.misfit,
                        yard: yard.map_or(f64::NAN, |y| y.misfit),
                        yard_evaluations: yard.map_or(0, |y| y.evaluations),
                        exhaustive: ex.as_ref().map(|e| e.misfit),
                        places: places(&seg.data, ex.as_ref(), yard),
                        place: place_of(&seg.data, &fit),
                        cost: (ms, fit.evaluations),
                        provenance: fit.provenance,
                    }
                })
                .collect::<Vec<_>>()
        }));
    }
    let seconds = started.elapsed().as_secs_f64();
    let total = rows.len();
    let excess = |r: &Row| r.fit - r.yard.min(r.fit);
    let misses: Vec<&Row> = rows
        .iter()
        .filter(|r| excess(r).is_nan() || excess(r) > VERIFY_DCHI2_MAX)
        .collect();
    println!(
        "{total} segments ({networks} network(s) of {segments}, seeds {seed}..{}, {mix:?} mix), {:.0} s",
        seed + networks - 1,
        seconds
    );
    if with_yardstick {
        println!(
            "  fit more than {VERIFY_DCHI2_MAX} above the yardstick (or failed): {}; yardstick not rated: {}; \
             mean yardstick evaluations {:.0}",
            misses.len(),
            rows.iter().filter(|r| r.yard.is_nan()).count(),
            rows.iter().map(|r| r.yard_evaluations).sum::<usize>() as f64 / total.max(1) as f64
        );
        for r in &misses {
            println!(
                "    {} ({:?}) fit {:.4} yardstick {:.4} won by {:?}\n{}\n      fit:        {}",
                r.id, r.material, r.fit, r.yard, r.provenance.winner, r.places, r.place
            );
        }
    } else {
        println!(
            "  yardstick skipped (YARDSTICK=0), so no misses counted; failed fits: {}",
            rows.iter().filter(|r| r.fit.is_nan()).count()
        );
    }
    // ROWS=1: every segment's χ² and evaluations, to check that a change of the code leaves
    // each fit unchanged to the evaluation.
    if std::env::var("ROWS").is_ok_and(|v| v == "1") {
        for r in &rows {
            println!("    row {} chi2 {:e} evaluations {}", r.id, r.fit, r.cost.1);
        }
    }
    if with_yardstick {
        let below = rows.iter().filter(|r| r.yard < r.fit - 1e-6).count();
        println!("  yardstick below the fit by more than 1e-6: {below}");
    }
    if exhaustive {
        for tol in [1e-3, 1e-2, 0.1] {
            let reached = rows
                .iter()
                .filter(|r| r.exhaustive.is_some_and(|e| r.yard <= e + tol))
                .count();
            println!("  yardstick within {tol} of the exhaustive chi2 or lower: {reached}/{total}");
        }
        for r in rows
            .iter()
            .filter(|r| r.exhaustive.is_some_and(|e| r.yard > e + 0.01))
        {
            println!(
                "    {} ({:?}) yardstick {:.4} exhaustive {:.4} fit {:.4}\n{}",
                r.id,
                r.material,
                r.yard,
                r.exhaustive.unwrap_or(f64::NAN),
                r.fit,
                r.places
            );
        }
        let fit_over = rows
            .iter()
            .filter(|r| r.exhaustive.is_some_and(|e| r.fit > e + VERIFY_DCHI2_MAX))
            .count();
        println!("  fit more than {VERIFY_DCHI2_MAX} above the exhaustive chi2: {fit_over}");
    }
    let mut stages = StageStatistics::default();
    for r in &rows {
        stages.observe(&r.provenance);
    }
    print!("{stages}");
    let cost = |name: &str, ms: Vec<f64>, evaluations: Vec<usize>| {
        let d = Distribution::of(&ms);
        println!(
            "  {name}: CPU ms/fit median {:.1} p90 {:.1} p99 {:.1} max {:.1}; {:.0} evaluations/fit",
            d.median,
            d.p90,
            d.p99,
            d.max,
            evaluations.iter().sum::<usize>() as f64 / evaluations.len().max(1) as f64
        );
    };
    cost(
        "today's search",
        rows.iter().map(|r| r.cost.0).collect(),
        rows.iter().map(|r| r.cost.1).collect(),
    );
}

/// A fit's optimum in (c_P, c_S/c_P, ξ) and its model phase speeds, m/s.
fn place_of(data: &pipewave::invert::SegmentData, f: &pipewave::invert::FitResult) -> String {
    use pipewave::physics::soil::speeds_of;
    let (l, r) = speeds_of(
        f.soil_modulus().unwrap_or(f64::NAN),
        f.soil_poisson().unwrap_or(f64::NAN),
        data.soil_density,
    );
    let model: Vec<String> = data
        .measurements
        .iter()
        .zip(&f.predicted)
        .map(|(m, k)| format!("{:.1}", m.omega / k.re))
        .collect();
    format!(
        "c_P {:.2} r {:.4} xi {:.3}; model phase speeds {}",
        l.exp(),
        r,
        f.contact().unwrap_or(f64::NAN),
        model.join(" ")
    )
}

/// The exhaustive optimum and the yardstick's in (c_P, c_S/c_P, ξ), with the measured and the
/// model's phase speeds at the exhaustive optimum, m/s.
fn places(
    data: &pipewave::invert::SegmentData,
    ex: Option<&pipewave::invert::FitResult>,
    yard: Option<&pipewave::invert::yardstick::Yardstick>,
) -> String {
    use pipewave::physics::soil::speeds_of;
    let rho = data.soil_density;
    let measured: Vec<String> = data
        .measurements
        .iter()
        .map(|m| format!("{:.1}", m.phase_speed()))
        .collect();
    let mut out = format!("      measured phase speeds {}", measured.join(" "));
    if let Some(e) = ex.filter(|e| e.status != pipewave::types::FitStatus::Failed) {
        let (l, r) = speeds_of(
            e.soil_modulus().unwrap_or(f64::NAN),
            e.soil_poisson().unwrap_or(f64::NAN),
            rho,
        );
        let model: Vec<String> = data
            .measurements
            .iter()
            .zip(&e.predicted)
            .map(|(m, k)| format!("{:.1}", m.omega / k.re))
            .collect();
        out += &format!(
            "\n      exhaustive: c_P {:.2} r {:.4} xi {:.3}; model phase speeds {}",
            l.exp(),
            r,
            e.contact().unwrap_or(f64::NAN),
            model.join(" ")
        );
    }
    if let Some(y) = yard {
        let (l, r) = speeds_of(10f64.powf(y.x[0]), y.x[1], rho);
        out += &format!(
            "\n      yardstick:  c_P {:.2} r {:.4} xi {:.3}",
            l.exp(),
            r,
            y.x[2]
        );
    }
    out
}
