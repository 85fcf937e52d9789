//! `pipewave fit --segments FILE --measurements FILE --out FILE [--model ...] [--method ...]
//! [--contact-mode ...] [--effects ...] [--jobs N] [--seed S]`: fit segments from CSV files
//! without keeping a database. The files are imported into a scratch database in the system's
//! temporary directory (removed afterwards), calibrated, and the fits written as the export CSV.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::builder::PossibleValuesParser;
use clap::Args;
use pipewave::batch::CalibrateOptions;
use pipewave::db::{self, ImportOptions, ImportSource};
use pipewave::export::{self, ExportFormat};
use pipewave::physics::effects::parse_effects;

use super::calibrate::{self, RunArgs};
use super::Outcome;

/// Arguments of `fit`.
#[derive(Debug, Args)]
pub struct FitArgs {
    /// Inventory (segments.csv format).
    #[arg(long, value_name = "FILE")]
    segments: PathBuf,
    /// Field wavenumbers (measurements.csv format).
    #[arg(long, value_name = "FILE")]
    measurements: PathBuf,
    /// Where to write the fits (the `export --format csv` columns).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    #[command(flatten)]
    run: RunArgs,
    /// Model variant.
    #[arg(long, default_value = "full", value_parser = PossibleValuesParser::new(["full", "seed"]))]
    model: String,
    /// Reading of the contact coefficient.
    #[arg(long, default_value = "reciprocal",
          value_parser = PossibleValuesParser::new(["reciprocal", "printed", "blend"]))]
    contact_mode: String,
    /// Inversion method.
    #[arg(long, default_value = "default", value_parser = PossibleValuesParser::new(["default", "paper"]))]
    method: String,
    /// Effects to switch on, comma-separated.
    #[arg(long, value_name = "NAME,...")]
    effects: Option<String>,
}

/// Import into a scratch database, calibrate, write the CSV, remove the scratch files.
pub fn run(args: &FitArgs) -> anyhow::Result<Outcome> {
    super::guard_outputs(
        None,
        &[&args.segments, &args.measurements],
        &[(&args.out, pipewave::outfile::Contents::Plain)],
    )?;
    let opts = CalibrateOptions {
        jobs: args.run.jobs.map(|j| j as usize),
        seed: args.run.seed,
        method: args.method.parse()?,
        model: args.model.parse()?,
        contact_mode: args.contact_mode.parse()?,
        effects: parse_effects(args.effects.as_deref().unwrap_or("")).context("--effects")?,
        ..CalibrateOptions::default()
    };
    let segments = ImportSource::from_path(&args.segments)?;
    let measurements = ImportSource::from_path(&args.measurements)?;
    let scratch = std::env::temp_dir().join(format!(
        "pipewave-fit-{}-{}.sqlite",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0)
    ));
    let result = (|| -> anyhow::Result<Outcome> {
        let mut database = super::create_database(&scratch)?;
        let report = db::import(
            database.conn_mut(),
            Some(&segments),
            Some(&measurements),
            ImportOptions::default(),
        )?;
        for e in &report.errors {
            eprintln!("{e}");
        }
        if report.problems > 0 {
            bail!("{} invalid rows: nothing was fitted", report.problems);
        }
        let outcome = calibrate::execute(&mut database, &opts)?;
        let s = export::write(&database, ExportFormat::Csv, &args.out)?;
        println!("fit: {} segments -> {}", s.segments, args.out.display());
        Ok(outcome)
    })();
    for suffix in ["", "-wal", "-shm"] {
        let mut p = scratch.clone().into_os_string();
        p.push(suffix);
        let _ = std::fs::remove_file(PathBuf::from(p));
    }
    result
}
