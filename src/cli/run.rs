//! `pipewave run DIR [--db PATH] [--jobs N] [--seed S]`: the one-command job. Imports
//! `DIR/segments.csv` and `DIR/measurements.csv` into `DIR/pipewave.sqlite` (or `--db`),
//! calibrates what changed, then exports `DIR/out/` and writes the audit report.
//!
//! Re-running on an unchanged directory imports nothing and refits nothing.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clap::Args;
use pipewave::batch::CalibrateOptions;
use pipewave::db::{self, Database, ImportOptions, ImportSource};
use pipewave::network::{MEASUREMENTS_CSV, SEGMENTS_CSV};

use super::calibrate::{self, RunArgs};
use super::Outcome;

/// Default database file inside the network directory.
pub const DEFAULT_DB: &str = "pipewave.sqlite";
/// Output directory inside the network directory.
pub const OUT_DIR: &str = "out";

/// A step after the calibration: its name and what runs it (`None`: not available yet).
type LaterStep = (
    &'static str,
    Option<fn(&Database, &Path) -> anyhow::Result<()>>,
);

/// The steps after the calibration, in order, each given the database and `DIR/out/`. Export
/// and audit are being written; wire each by replacing its `None` with `Some(function)`.
const LATER_STEPS: [LaterStep; 2] = [("export", None), ("audit", None)];

/// Arguments of `run`.
#[derive(Debug, Args)]
pub struct RunDirArgs {
    /// The network directory, holding segments.csv and measurements.csv.
    #[arg(value_name = "DIR")]
    dir: PathBuf,
    /// The database (default: DIR/pipewave.sqlite).
    #[arg(long, value_name = "PATH")]
    db: Option<PathBuf>,
    #[command(flatten)]
    run: RunArgs,
}

/// Import, calibrate, then the later steps.
pub fn run(args: &RunDirArgs) -> anyhow::Result<Outcome> {
    let db_path = args.db.clone().unwrap_or_else(|| args.dir.join(DEFAULT_DB));
    let mut database = import_dir(&args.dir, &db_path)?;
    let opts = CalibrateOptions {
        jobs: args.run.jobs.map(|j| j as usize),
        seed: args.run.seed,
        ..CalibrateOptions::default()
    };
    let outcome = calibrate::execute(&mut database, &opts)?;
    if outcome == Outcome::Interrupted {
        return Ok(outcome);
    }
    let out = args.dir.join(OUT_DIR);
    for (name, step) in LATER_STEPS {
        match step {
            Some(f) => f(&database, &out).with_context(|| format!("{name} failed"))?,
            None => println!("{name}: not yet available"),
        }
    }
    Ok(outcome)
}

/// Import a network directory's two files into the database at `db_path` (created if
/// missing), printing the import summary. Any invalid row rejects the import (exit 2).
pub fn import_dir(dir: &Path, db_path: &Path) -> anyhow::Result<Database> {
    if !dir.is_dir() {
        bail!(
            "{} is not a directory; give a network directory holding {SEGMENTS_CSV} and \
             {MEASUREMENTS_CSV} (`pipewave synth --out DIR` makes one)",
            dir.display()
        );
    }
    let mut sources = Vec::with_capacity(2);
    for name in [SEGMENTS_CSV, MEASUREMENTS_CSV] {
        let p = dir.join(name);
        if !p.is_file() {
            bail!(
                "{} not found: a network directory holds {SEGMENTS_CSV} and {MEASUREMENTS_CSV}",
                p.display()
            );
        }
        sources.push(ImportSource::from_path(&p)?);
    }
    let mut database = super::open_database(db_path)?;
    let report = db::import(
        database.conn_mut(),
        Some(&sources[0]),
        Some(&sources[1]),
        ImportOptions::default(),
    )
    .with_context(|| {
        format!(
            "import into {} failed; nothing was written",
            db_path.display()
        )
    })?;
    for e in &report.errors {
        eprintln!("{e}");
    }
    if report.rejected {
        bail!(
            "import rejected: {} problem(s) found in {}, nothing was written (fix the rows \
             above, or import with `pipewave import --skip-invalid`)",
            report.errors.len(),
            dir.display()
        );
    }
    println!("{}", super::import::summary(&report));
    Ok(database)
}
