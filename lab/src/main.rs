//! The `pipewave-lab` binary: the independent two-campaign generator and its scorer.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Parser, Subcommand};
use pipewave_lab::{campaigns, score};

#[derive(Parser)]
#[command(
    name = "pipewave-lab",
    version,
    about = "Independent generators and scorers for pipewave"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Write DIR/segments.csv, DIR/measurements.csv (campaigns IG-A and IG-B) and DIR/truth.csv.
    Campaigns {
        /// Output directory (created if missing; its three files are overwritten).
        #[arg(long)]
        out: PathBuf,
        /// Number of segments, each measured in both campaigns (1-1000000).
        #[arg(long, default_value_t = 1500, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
        segments: u64,
        /// Seed of the random streams.
        #[arg(long, default_value_t = 1001)]
        seed: u64,
        /// Fraction of the segments changed between the campaigns (0-1).
        #[arg(long, default_value_t = 0.3)]
        changed_fraction: f64,
    },
    /// Score a pipewave CSV export (`pipewave export --format csv`) against a truth.csv.
    ScoreCampaigns {
        /// The export.
        #[arg(long)]
        export: PathBuf,
        /// truth.csv of `pipewave-lab campaigns` or `pipewave synth --campaigns 2`.
        #[arg(long)]
        truth: PathBuf,
        /// An export of the latest campaign fitted alone: its σ replaces speed_by_campaign's.
        #[arg(long)]
        single: Option<PathBuf>,
    },
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Campaigns {
            out,
            segments,
            seed,
            changed_fraction,
        } => {
            let opts = campaigns::Options {
                segments: segments as usize,
                seed,
                changed_fraction,
            };
            let segs = campaigns::generate(&opts)?;
            campaigns::write(&out, &segs)?;
            print!("{}", campaigns::summarize(&segs));
            println!(
                "wrote {}/{{segments,measurements,truth}}.csv",
                out.display()
            );
        }
        Command::ScoreCampaigns {
            export,
            truth,
            single,
        } => {
            let s = score::score_files(&export, &truth, single.as_deref())?;
            print!("{s}");
        }
    }
    Ok(())
}
