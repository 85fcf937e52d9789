//! `pipewave plan --db DB --count N --out next.csv`: the next measurement campaign (P83).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use pipewave::field::plan;
use pipewave::outfile::Contents;
use pipewave::spreadsheet::{self, spreadsheet_safe};

use super::open_database as open_existing;
use super::{bounds, Outcome};

/// Arguments of `plan`.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// The pipewave database (calibrated: the plan reads its soil field).
    #[arg(long, value_name = "DB")]
    db: PathBuf,
    /// How many segments to choose. Range 1 – 1000000.
    #[arg(long, value_name = "N", value_parser = bounds::count(1, bounds::MAX_SEGMENTS))]
    count: u32,
    /// The CSV file to write, best first (replaced if it exists).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Worker threads (default: all cores; the plan does not depend on it). Range 1 – 512, as
    /// calibrate's.
    #[arg(long, value_name = "N", value_parser = bounds::jobs())]
    jobs: Option<u32>,
}

/// Choose, store and write the plan.
pub fn run(args: &PlanArgs) -> anyhow::Result<Outcome> {
    super::guard_outputs(Some(&args.db), &[], &[(&args.out, Contents::Plain)])?;
    let mut database = open_existing(&args.db)?;
    let jobs = args
        .jobs
        .map_or_else(pipewave::batch::default_jobs, |j| j as usize);
    let picks = plan::plan(database.conn_mut(), args.count as usize, jobs)
        .with_context(|| format!("plan of {} failed", args.db.display()))?;
    // Through the output guard, and spreadsheet-safe like every CSV pipewave writes.
    let mut w = spreadsheet::writer_from_path(&args.out)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    w.write_record([
        "segment_id",
        "rank",
        "expected_gain",
        "leak_band_speed_std_m_per_s",
        "weight",
    ])?;
    for p in &picks {
        w.write_record([
            spreadsheet_safe(&p.segment_id).into_owned(),
            p.rank.to_string(),
            format!("{:.6e}", p.expected_gain),
            p.leak_band_speed_std_m_per_s
                .map_or(String::new(), |v| format!("{v:.3}")),
            format!("{:.2}", p.weight),
        ])?;
    }
    spreadsheet::finish(w).with_context(|| format!("cannot write {}", args.out.display()))?;
    let risk_weighted = pipewave::db::field::count_risk_weighted(database.conn())
        .with_context(|| format!("cannot read {}", args.db.display()))?;
    println!("plan: {} segments -> {}", picks.len(), args.out.display());
    println!("plan: {}", plan::HYPOTHETICAL_MEASUREMENT);
    let unit = if risk_weighted > 0 {
        println!(
            "plan: weight: risk_weight ({risk_weighted} segment{}), length in m elsewhere",
            if risk_weighted == 1 { "" } else { "s" }
        );
        "risk_weight units (metres of pipe where none is given)"
    } else {
        println!("plan: weight: length in m (no risk_weight in the inventory)");
        "metres of pipe"
    };
    if let Some(first) = picks.first() {
        println!(
            "plan: {} (the first pick's)",
            plan::gain_in_words(first.expected_gain, unit)
        );
    }
    Ok(Outcome::Done)
}
