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
use pipewave::export::{self, ExportFormat};
use pipewave::network::{MEASUREMENTS_CSV, SEGMENTS_CSV};

use super::calibrate::{self, RunArgs};
use super::Outcome;

/// Default database file inside the network directory.
pub const DEFAULT_DB: &str = "pipewave.sqlite";
/// Output directory inside the network directory.
pub const OUT_DIR: &str = "out";

/// The files written to `DIR/out/` after the calibration.
pub const GPKG_FILE: &str = "segments.gpkg";
/// Per-segment CSV for joining onto a pipe layer.
pub const CSV_FILE: &str = "segments.csv";
/// The audit report.
pub const REPORT_FILE: &str = "report.html";

/// Export the GeoPackage and the CSV, and write the audit report, into `out`.
fn write_outputs(database: &Database, out: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create the output directory {}", out.display()))?;
    for (format, file) in [
        (ExportFormat::Gpkg, GPKG_FILE),
        (ExportFormat::Csv, CSV_FILE),
    ] {
        let path = out.join(file);
        let s = export::write(database, format, &path)?;
        for w in &s.warnings {
            eprintln!("warning: {w}");
        }
        println!("export: {} segments -> {}", s.segments, path.display());
    }
    let path = out.join(REPORT_FILE);
    let s = pipewave::report::audit::write(database, &path)?;
    for w in &s.warnings {
        eprintln!("warning: {w}");
    }
    println!("audit: {} segments -> {}", s.segments, path.display());
    Ok(())
}

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
    write_outputs(&database, &args.dir.join(OUT_DIR))?;
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
            report.problems,
            dir.display()
        );
    }
    println!("{}", super::import::summary(&report));
    Ok(database)
}
