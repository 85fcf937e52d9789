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
use pipewave::outfile::Contents;
use pipewave::synth::network::{MEASUREMENTS_CSV, SEGMENTS_CSV};

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
    /// After calibrating, diagnose the fitted segments, switch on for each the effect the
    /// diagnosis names and refit, all before the export (default: off). The diagnosis report
    /// goes to DIR/out/diagnosis/.
    #[arg(long)]
    diagnose: bool,
    /// Import the valid rows of DIR's files and list the invalid ones (file, line, column),
    /// then go on with the other steps, instead of importing nothing (as `import
    /// --skip-invalid`).
    #[arg(long)]
    skip_invalid: bool,
}

/// Directory of the diagnosis report inside the output directory (`run --diagnose`).
pub const DIAGNOSIS_DIR: &str = "diagnosis";

/// Import, calibrate, then the later steps.
pub fn run(args: &RunDirArgs) -> anyhow::Result<Outcome> {
    let db_path = args.db.clone().unwrap_or_else(|| args.dir.join(DEFAULT_DB));
    let out = args.dir.join(OUT_DIR);
    let (gpkg, csv, report) = (
        out.join(GPKG_FILE),
        out.join(CSV_FILE),
        out.join(REPORT_FILE),
    );
    let inputs = [args.dir.join(SEGMENTS_CSV), args.dir.join(MEASUREMENTS_CSV)];
    super::guard_database(&db_path, &[&inputs[0], &inputs[1]])?;
    super::guard_outputs(
        Some(&db_path),
        &[&inputs[0], &inputs[1]],
        &[
            (&gpkg, Contents::GeoPackage),
            (&csv, Contents::Plain),
            (&report, Contents::Plain),
        ],
    )?;
    let mut database = import_dir(&args.dir, &db_path, args.skip_invalid)?;
    let opts = CalibrateOptions {
        jobs: args.run.jobs.map(|j| j as usize),
        seed: args.run.seed,
        ..CalibrateOptions::default()
    };
    let mut outcome = calibrate::execute(&mut database, &opts)?;
    if outcome == Outcome::Interrupted {
        return Ok(outcome);
    }
    if args.diagnose {
        outcome = diagnose_and_refit(&mut database, &args.dir, &opts)?;
        if outcome == Outcome::Interrupted {
            return Ok(outcome);
        }
    }
    write_outputs(&database, &args.dir.join(OUT_DIR))?;
    Ok(outcome)
}

/// Diagnose every fitted segment, store the extended fits and switch the named effects on
/// (as `diagnose` does), then calibrate again: a segment whose effects changed is refitted
/// with them, so the exports that follow reflect them. Prints what it did.
fn diagnose_and_refit(
    database: &mut Database,
    dir: &Path,
    opts: &CalibrateOptions,
) -> anyhow::Result<Outcome> {
    use pipewave::diagnose::run::{diagnose_database, DiagnoseOptions};
    let out_dir = dir.join(OUT_DIR).join(DIAGNOSIS_DIR);
    std::fs::create_dir_all(&out_dir)
        .with_context(|| format!("cannot create the directory {}", out_dir.display()))?;
    let d = diagnose_database(
        database.conn_mut(),
        &DiagnoseOptions {
            segments: None,
            jobs: opts.worker_count(),
            apply: true,
            candidates: pipewave::physics::effects::Effect::ALL.to_vec(),
            out_dir,
            group_by: Default::default(),
            convert_units: Vec::new(),
        },
    )?;
    println!("{}", d.line());
    let outcome = calibrate::execute(database, opts)?;
    let named: usize = d.named.values().sum();
    println!(
        "run --diagnose: {} segments diagnosed, an effect named and switched on for {named}; \
         {} extended fits stored by the diagnosis; the calibration above refitted what they \
         left stale, so the exports below reflect the effects",
        d.diagnosed, d.stored
    );
    Ok(outcome)
}

/// Import a network directory's two files into the database at `db_path` (created if
/// missing), printing the import summary. Any invalid row rejects the import (exit 2), unless
/// `skip_invalid`: then the valid rows are imported and the invalid ones listed.
pub fn import_dir(dir: &Path, db_path: &Path, skip_invalid: bool) -> anyhow::Result<Database> {
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
    let mut database = super::create_database(db_path)?;
    let report = db::import(
        database.conn_mut(),
        Some(&sources[0]),
        Some(&sources[1]),
        ImportOptions {
            skip_invalid,
            ..ImportOptions::default()
        },
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
    let n_bad = report.problems;
    if n_bad > report.errors.len() {
        eprintln!(
            "... and {} more problems (the first {} are listed)",
            n_bad - report.errors.len(),
            report.errors.len()
        );
    }
    if report.rejected {
        bail!(
            "import rejected: {} problem(s) found in {}, nothing was written ({})",
            report.problems,
            dir.display(),
            super::import::rejected_hint(
                &report,
                "add --skip-invalid to import the valid rows and go on"
            )
        );
    }
    println!("{}", super::import::summary(&report));
    if n_bad > 0 {
        eprintln!(
            "skipped {n_bad} invalid row{} (listed above); the valid rows were imported",
            if n_bad == 1 { "" } else { "s" }
        );
    }
    Ok(database)
}
