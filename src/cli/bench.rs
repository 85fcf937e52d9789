//! `pipewave bench`: print timing figures (speed is measured here, never asserted in tests).

use clap::Args;

use super::Outcome;

/// Arguments of `bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Repeat factor: larger values time longer batches.
    #[arg(long, default_value_t = 1)]
    scale: usize,
    /// Seeds per case for the inversion figures (0 skips them).
    #[arg(long, default_value_t = 100)]
    fits: usize,
}

/// Run the benchmarks and print them.
pub fn run(args: &BenchArgs) -> anyhow::Result<Outcome> {
    if cfg!(debug_assertions) {
        eprintln!(
            "note: this is a debug build; run `cargo run --release -- bench` for real figures"
        );
    }
    let figs = pipewave::bench::forward_figures(args.scale.max(1));
    pipewave::bench::print_figures("forward model (one core):", &figs);
    if args.fits > 0 {
        let fits = pipewave::bench::inversion_figures(args.fits);
        pipewave::bench::print_fit_figures(&fits);
    }
    Ok(Outcome::Done)
}
