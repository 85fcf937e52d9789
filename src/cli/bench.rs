//! `pipewave bench`: print timing figures (speed is measured here, never asserted in tests).
//!
//! Without options: per-fit times on a realistic synthetic network (`--network N`,
//! `--materials plastic-heavy`), then forward-model and single-segment inversion figures (an
//! earlier version is timed by building it beside this one: `scripts/compare-builds.sh`).
//! `--verify N`: the default fit against the independent yardstick (a dense grid in the soil
//! speeds, polished). `--calibrate N`: calibrate throughput on N synthetic segments.
//! `--recovery DIR`: how well the calibration of a synthetic network directory recovered its
//! truth (imports and calibrates DIR first, as `run` does, if needed).

use std::path::PathBuf;

use clap::Args;
use pipewave::batch::CalibrateOptions;
use pipewave::bench::throughput::{calibrate_throughput, Throughput};
use pipewave::db;
use pipewave::synth::network::{read_truth, recovery, TRUTH_CSV};

use super::calibrate::{self, RunArgs};
use super::run::{import_dir, DEFAULT_DB};
use super::{bounds, Outcome};

/// Arguments of `bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Repeat factor of the forward-model figures: larger values time longer batches. Range
    /// 0 – 1000 (0 counts as 1).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = bounds::size(0, 1000))]
    scale: usize,
    /// Seeds per case for the inversion figures (0 skips them). Range 0 – 100,000.
    #[arg(long, value_name = "N", default_value_t = 100, value_parser = bounds::size(0, 100_000))]
    fits: usize,
    /// Time a calibrate run of N synthetic segments (in a temporary database); without --jobs,
    /// on every core between two runs on one core, with the speed-up. Range 1 – 1000000.
    #[arg(long, value_name = "N", value_parser = bounds::count(1, bounds::MAX_SEGMENTS))]
    calibrate: Option<u32>,
    /// Compare the fits of a synthetic network directory with its truth.csv.
    #[arg(long, value_name = "DIR")]
    recovery: Option<PathBuf>,
    /// Segments of the realistic synthetic network whose per-fit times are printed, on one
    /// core (0 skips them). To time another version, build it beside this one:
    /// scripts/compare-builds.sh OLD_REV. Range 0 – 1000000.
    #[arg(long, value_name = "N", default_value_t = 200,
          value_parser = bounds::size(0, u64::from(bounds::MAX_SEGMENTS)))]
    network: usize,
    /// Seed of that network and of --verify's (pass new values for fresh seeds). Range 0 –
    /// 2^64 − 1.
    #[arg(long, value_name = "S", default_value_t = pipewave::bench::throughput::BENCH_NETWORK_SEED)]
    network_seed: u64,
    /// Material mix of that network: default (the synthetic network's) or plastic-heavy.
    #[arg(long, value_name = "MIX", default_value = "default")]
    materials: pipewave::synth::bench::MaterialMix,
    /// Compare the default fit with the independent yardstick (a dense grid in the soil speeds
    /// and the contact, its best minima polished) on N segments of a realistic network; print
    /// the worst case and the share of fits each search stage won. Range 1 – 1000000.
    #[arg(long, value_name = "N", value_parser = bounds::size(1, u64::from(bounds::MAX_SEGMENTS)))]
    verify: Option<usize>,
    /// Time the staleness sweep of calibrate (every segment's inputs hash recomputed from its
    /// stored rows) on a temporary database of N segments with 5 measurements each: the first
    /// sweep hashes every segment, the second finds nothing changed, as a nightly calibrate
    /// with nothing to do. Range 1 – 1000000.
    #[arg(long, value_name = "N", value_parser = bounds::count(1, bounds::MAX_SEGMENTS))]
    staleness: Option<u32>,
    /// Database of --recovery (default: DIR/pipewave.sqlite).
    #[arg(long, value_name = "PATH", requires = "recovery")]
    db: Option<PathBuf>,
    #[command(flatten)]
    run: RunArgs,
}

/// `--staleness N`: time the two sweeps on a temporary database.
fn staleness(n: usize) -> anyhow::Result<()> {
    const PER_SEGMENT: usize = 5;
    let dir = std::env::temp_dir().join(format!("pipewave-bench-staleness-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let result = (|| -> anyhow::Result<()> {
        let mut db = pipewave::db::Database::open(dir.join("bench.sqlite"))?;
        pipewave::db::staleness::fill_for_bench(db.conn_mut(), n, PER_SEGMENT)?;
        for what in [
            "first sweep (hashes every segment)",
            "second sweep (nothing changed)",
        ] {
            let t = std::time::Instant::now();
            let s = pipewave::db::refresh_all_inputs_hashes(db.conn_mut())?;
            let secs = t.elapsed().as_secs_f64();
            println!(
                "staleness: {} segments, {} measurements: {what}: {:.3} s ({:.2} µs a segment), {} stored",
                s.segments,
                s.measurements,
                secs,
                1e6 * secs / s.segments.max(1) as f64,
                s.first_hashed + s.changed.len()
            );
        }
        Ok(())
    })();
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Print one calibrate throughput measurement of `n` segments.
fn print_throughput(n: usize, t: &Throughput) {
    println!(
        "calibrate ({} synthetic segments, {} job{}):",
        n,
        t.jobs,
        if t.jobs == 1 { "" } else { "s" }
    );
    println!(
        "  {:>10.2} segments/s       wall clock, including the database writes",
        t.segments_per_second()
    );
    println!(
        "  {:>10.1} ms per segment   wall clock / segments",
        t.wall_ms_per_segment()
    );
    println!(
        "  {:>10.1} ms per segment   one worker's time (fit + curve), mean",
        t.worker_ms_per_segment
    );
    // The workers' time over the wall clock of all of them: what the batch machinery (feed,
    // writer, the last fits' tail) leaves unused, whatever the machine's load.
    println!(
        "  {:>10.1} % busy fitting  workers' time / ({} × wall clock)",
        100.0 * t.worker_ms_per_segment * t.segments_per_second() / (1e3 * t.jobs as f64),
        t.jobs
    );
    match t.peak_rss_kb {
        Some(kb) => println!(
            "  {:>10.1} MB peak RSS      VmHWM of the whole process",
            kb as f64 / 1024.0
        ),
        None => println!("           - peak RSS      (no /proc/self/status here)"),
    }
    println!(
        "  {:>10.1} s  setup         generate + import (not timed above)",
        t.setup_s
    );
    println!("  {}", t.summary.line());
}

/// Run the benchmarks and print them.
pub fn run(args: &BenchArgs) -> anyhow::Result<Outcome> {
    if cfg!(debug_assertions) {
        eprintln!(
            "note: this is a debug build; run `cargo run --release -- bench` for real figures"
        );
    }
    let opts = CalibrateOptions {
        jobs: args.run.jobs.map(|j| j as usize),
        seed: args.run.seed,
        ..CalibrateOptions::default()
    };
    let mut outcome = Outcome::Done;
    if let Some(n) = args.staleness {
        staleness(n as usize)?;
    }
    if let Some(n) = args.calibrate {
        let n = n as usize;
        // Without --jobs, the run on every core is bracketed by two on a single core, and the
        // speed-up over their mean is printed: a ratio measured in one run, in which a drift
        // of a shared machine's load between the runs mostly cancels.
        let one = CalibrateOptions {
            jobs: Some(1),
            ..opts.clone()
        };
        let bracket = args.run.jobs.is_none() && opts.worker_count() > 1;
        let before = if bracket {
            let t = calibrate_throughput(n, &one)?;
            print_throughput(n, &t);
            Some(t)
        } else {
            None
        };
        let t = calibrate_throughput(n, &opts)?;
        print_throughput(n, &t);
        if let Some(before) = before {
            let after = calibrate_throughput(n, &one)?;
            print_throughput(n, &after);
            let single = 0.5 * (before.segments_per_second() + after.segments_per_second());
            println!(
                "speed-up from 1 job to {} (same run, over the mean of the 1-job runs before and after): {:.2}x",
                t.jobs,
                t.segments_per_second() / single
            );
        }
    }
    if let Some(dir) = &args.recovery {
        let db_path = args.db.clone().unwrap_or_else(|| dir.join(DEFAULT_DB));
        let truth = read_truth(&dir.join(TRUTH_CSV))?;
        let mut database = import_dir(dir, &db_path, false)?;
        outcome = calibrate::execute(&mut database, &opts)?;
        let fits = db::latest_fits(database.conn(), None)?;
        print!(
            "{}",
            recovery::compare(&fits, &truth, &recovery::soil_densities(database.conn())?)
        );
    }
    if let Some(n) = args.verify {
        let net = pipewave::synth::bench::bench_network(n, args.network_seed, args.materials);
        let rows = pipewave::bench::verify(&net, opts.worker_count());
        pipewave::bench::print_verify(&rows);
    }
    if args.calibrate.is_none() && args.recovery.is_none() && args.verify.is_none() {
        if args.network > 0 {
            let net = pipewave::synth::bench::bench_network(
                args.network,
                args.network_seed,
                args.materials,
            );
            let fits = pipewave::bench::network_figures(&net);
            let label = format!(
                "{} mix, seed {}",
                match args.materials {
                    pipewave::synth::bench::MaterialMix::Default => "default",
                    pipewave::synth::bench::MaterialMix::PlasticHeavy => "plastic-heavy",
                },
                args.network_seed
            );
            pipewave::bench::print_network_figures(&label, &fits);
        }
        let figs = pipewave::bench::forward_figures(args.scale.max(1));
        pipewave::bench::print_figures("forward model (one core):", &figs);
        if args.fits > 0 {
            let fits = pipewave::bench::inversion_figures(args.fits);
            pipewave::bench::print_fit_figures(&fits);
        }
    }
    Ok(outcome)
}
