//! The `pipewave-lab` binary: the independent generators (two campaigns, diagnosis trials) and
//! their scorers.

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::{Parser, Subcommand};
use pipewave_lab::diagnosis::{self, Set};
use pipewave_lab::{campaigns, score, score_diagnosis};

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
    /// Write a set of diagnosis trials: DIR/segments.csv, DIR/measurements.csv, DIR/truth.csv.
    Diagnosis {
        /// Which set: hidden effects at main sizes, at the detection floor, inventory errors, or
        /// zones with an effect in part of their members.
        #[arg(long, value_enum)]
        set: Set,
        /// Output directory (created if missing; its three files are overwritten).
        #[arg(long)]
        out: PathBuf,
        /// Seed of the random streams.
        #[arg(long, default_value_t = 2001)]
        seed: u64,
        /// Number of segments (1-1000000; default 120 for main and floor, 48 for records, 320
        /// for groups).
        #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
        segments: Option<u64>,
        /// Members per zone, groups set (2-100000).
        #[arg(long, default_value_t = 40, value_parser = clap::value_parser!(u64).range(2..=100_000))]
        group_size: u64,
        /// Fraction of the zones with an effect, groups set (0-1; 0 makes a clean run).
        #[arg(long, default_value_t = 0.5)]
        affected_fraction: f64,
    },
    /// Score `pipewave diagnose` output against truth.csv of `pipewave-lab diagnosis`; repeat
    /// --truth, --diagnosis (and --groups) to score several runs together.
    ScoreDiagnosis {
        /// The set the truth files are of.
        #[arg(long, value_enum)]
        set: Set,
        /// diagnosis.csv of each run.
        #[arg(long, required = true)]
        diagnosis: Vec<PathBuf>,
        /// groups.csv of each run (groups set).
        #[arg(long)]
        groups: Vec<PathBuf>,
        /// truth.csv of each run.
        #[arg(long, required = true)]
        truth: Vec<PathBuf>,
        /// Call a group detected when its p_value is below this level (0-1), instead of when
        /// groups.csv names an effect.
        #[arg(long)]
        group_level: Option<f64>,
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
        Command::Diagnosis {
            set,
            out,
            seed,
            segments,
            group_size,
            affected_fraction,
        } => {
            let opts = diagnosis::Options {
                set,
                segments: segments.map_or(set.default_segments(), |n| n as usize),
                seed,
                group_size: group_size as usize,
                affected_fraction,
            };
            let (segs, deal) = diagnosis::generate(&opts)?;
            diagnosis::write(&out, set, &segs)?;
            print!("{}", diagnosis::summarize(&segs, &deal));
            println!(
                "wrote {}/{{segments,measurements,truth}}.csv",
                out.display()
            );
        }
        Command::ScoreDiagnosis {
            set,
            diagnosis,
            groups,
            truth,
            group_level,
        } => {
            if diagnosis.len() != truth.len() || (!groups.is_empty() && groups.len() != truth.len())
            {
                bail!(
                    "give one --diagnosis (and one --groups, if any) per --truth: {} truth, {} \
                     diagnosis, {} groups",
                    truth.len(),
                    diagnosis.len(),
                    groups.len()
                );
            }
            if let Some(l) = group_level {
                if !(l > 0.0 && l <= 1.0) {
                    bail!("--group-level must be within 0-1, got {l}");
                }
            }
            let runs: Vec<score_diagnosis::Run> = truth
                .iter()
                .enumerate()
                .map(|(i, t)| score_diagnosis::Run {
                    truth: t.clone(),
                    diagnosis: diagnosis[i].clone(),
                    groups: groups.get(i).cloned(),
                })
                .collect();
            let s = score_diagnosis::score_runs(set.name(), &runs, group_level)?;
            print!("{s}");
        }
    }
    Ok(())
}
