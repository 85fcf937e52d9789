//! Fit the segments of a realistic synthetic network one after another on one core, for
//! profiling (`valgrind --tool=callgrind target/release/examples/fit_profile 40`) or timing.
//!
//! Usage: fit_profile [SEGMENTS] [SEED] [default|plastic-heavy]

use pipewave::bench::{timed_fit, Distribution};
use pipewave::invert::FitSettings;
use pipewave::synth::bench::{bench_network, MaterialMix};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(40);
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(7);
    let mix: MaterialMix = args
        .get(3)
        .map(|s| s.parse().expect("mix"))
        .unwrap_or_default();
    let net = bench_network(n, seed, mix);
    let settings = FitSettings::default();
    let fits: Vec<_> = net.iter().map(|s| timed_fit(s, &settings)).collect();
    let ms: Vec<f64> = fits.iter().map(|f| f.ms).collect();
    let d = Distribution::of(&ms);
    let evals: usize = fits.iter().map(|f| f.evaluations).sum();
    let failed = fits.iter().filter(|f| f.failed).count();
    println!(
        "{} fits: median {:.1} ms, p90 {:.1}, p99 {:.1}, max {:.1}, mean {:.1}; {:.0} evaluations/fit; {} failed",
        fits.len(),
        d.median,
        d.p90,
        d.p99,
        d.max,
        d.mean,
        evals as f64 / fits.len() as f64,
        failed
    );
    if std::env::var_os("FIT_PROFILE_LIST").is_some() {
        for (s, f) in net.iter().zip(&fits) {
            println!(
                "{} {:?} {} freqs {:.1} ms {} evals misfit {:.3}",
                s.id,
                s.material,
                s.data.measurements.len(),
                f.ms,
                f.evaluations,
                f.misfit
            );
        }
    }
}
