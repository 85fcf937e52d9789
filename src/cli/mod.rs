//! The command line: one file per subcommand, each turning its arguments into checked values
//! and calling the library. Only this module knows clap. It lives in the binary crate (not the
//! library) so that clap and anyhow stay out of the library, as docs/style.md asks.

mod audit;
mod bench;
mod bounds;
mod calibrate;
mod diagnose;
mod export;
mod fit;
mod forward;
mod import;
mod locate;
mod plan;
mod run;
mod synth;
mod wavenumbers;

use std::path::Path;
use std::process::ExitCode;

use anyhow::Context;
use pipewave::db::{Database, DbError};
use pipewave::outfile::{self, Contents};

use clap::{Parser, Subcommand};

/// Exit code: the command did its job.
pub const EXIT_OK: u8 = 0;
/// Exit code: the command finished but some segments failed.
pub const EXIT_SOME_FAILED: u8 = 1;
/// Exit code: the command could not run (bad arguments, unreadable input, database unusable).
/// clap uses the same code for argument errors.
pub const EXIT_CANNOT_RUN: u8 = 2;
/// Exit code: the run was interrupted (Ctrl-C) before it finished; what it stored is kept.
/// 128 + SIGINT, as a shell reports a process ended by Ctrl-C.
pub const EXIT_INTERRUPTED: u8 = 130;

/// Soil inversion from leak-noise wavenumbers of buried water pipes.
#[derive(Debug, Parser)]
#[command(name = "pipewave", version, about)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Import DIR/segments.csv and DIR/measurements.csv, calibrate, export and audit.
    Run(run::RunDirArgs),
    /// Load or update the inventory (segments.csv) and field measurements (measurements.csv).
    Import(import::ImportArgs),
    /// Fit every segment whose inputs or settings changed since its last fit.
    Calibrate(calibrate::CalibrateArgs),
    /// Write a synthetic network (segments.csv, measurements.csv, truth.csv).
    Synth(synth::SynthArgs),
    /// Evaluate the forward model for a table of cases (research and validation).
    Forward(forward::ForwardArgs),
    /// Print benchmark figures (build with --release).
    Bench(bench::BenchArgs),
    /// Write the fits for GIS: a GeoPackage, GeoJSON or CSV file, one feature per segment.
    Export(export::ExportArgs),
    /// Write the fit-quality report of the network: one self-contained HTML page.
    Audit(audit::AuditArgs),
    /// Find where model and measurements disagree, name the missing effect, refit with it.
    Diagnose(diagnose::DiagnoseArgs),
    /// Fit segments from CSV files without keeping a database; write the fits as CSV.
    Fit(fit::FitArgs),
    /// Field wavenumbers from hydrant-test recordings (WAV files and a layout.csv).
    Wavenumbers(wavenumbers::WavenumbersArgs),
    /// Choose the next segments to measure: the largest expected cut in speed uncertainty.
    Plan(plan::PlanArgs),
    /// Locate a leak from a correlator's delay or two recordings, with its 95 % interval.
    Locate(locate::LocateArgs),
}

/// How a command that ran ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// It did its job.
    Done,
    /// It finished, but some segments failed.
    SomeFailed,
    /// It was interrupted before it finished.
    Interrupted,
}

impl Outcome {
    /// The process exit code.
    pub fn exit_code(self) -> ExitCode {
        ExitCode::from(match self {
            Outcome::Done => EXIT_OK,
            Outcome::SomeFailed => EXIT_SOME_FAILED,
            Outcome::Interrupted => EXIT_INTERRUPTED,
        })
    }
}

/// Run the command. An `Err` means it could not run (exit 2); its chain is printed once by main.
pub fn run(cli: Cli) -> anyhow::Result<Outcome> {
    match cli.command {
        Command::Run(args) => run::run(&args),
        Command::Import(args) => import::run(&args),
        Command::Calibrate(args) => calibrate::run(&args),
        Command::Synth(args) => synth::run(&args),
        Command::Forward(args) => forward::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Export(args) => export::run(&args),
        Command::Audit(args) => audit::run(&args),
        Command::Diagnose(args) => diagnose::run(&args),
        Command::Fit(args) => fit::run(&args),
        Command::Wavenumbers(args) => wavenumbers::run(&args),
        Command::Plan(args) => plan::run(&args),
        Command::Locate(args) => locate::run(&args),
    }
}

/// The output guard of every command that writes a file ([`pipewave::outfile`]), called before
/// the command does any work: register its database and input files as protected, then refuse
/// any output that is a directory, the database, another database, an input or a read-only
/// file. The writes themselves go through the same guard.
pub(crate) fn guard_outputs(
    database: Option<&Path>,
    inputs: &[&Path],
    outputs: &[(&Path, Contents)],
) -> anyhow::Result<()> {
    if let Some(db) = database {
        outfile::protect_database(db);
    }
    for input in inputs {
        outfile::protect_input(input);
    }
    for (out, contents) in outputs {
        let suggested = out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "output".into());
        outfile::check(out, *contents, &suggested)?;
    }
    Ok(())
}

/// Refuse a database path that is one of the command's input files (`import --db segments.csv
/// --segments segments.csv` would turn the survey into a database).
pub(crate) fn guard_database(database: &Path, inputs: &[&Path]) -> anyhow::Result<()> {
    for input in inputs {
        if outfile::same_file(database, input) {
            anyhow::bail!(
                "refusing to use {} as the database: it is this command's input {}; give \
                 another --db path",
                database.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// Open an existing pipewave database for a command that reads or fits one (every command but
/// `import` and `run`): a missing file or an empty database is an error (exit 2) and nothing is
/// created.
pub(crate) fn open_database(path: &Path) -> anyhow::Result<Database> {
    named(path, Database::open_existing(path))
}

/// Open an existing pipewave database to read it (`export`, `audit`): as [`open_database`], but
/// read-only and immutable where the file or its folder cannot be written (a read-only mount).
pub(crate) fn open_reader(path: &Path) -> anyhow::Result<Database> {
    named(path, Database::open_reader(path))
}

/// Open the database at `path` for `import` and `run`, creating and migrating it if needed.
pub(crate) fn create_database(path: &Path) -> anyhow::Result<Database> {
    named(path, Database::open(path))
}

/// Name the file in messages that do not already.
fn named(path: &Path, opened: Result<Database, DbError>) -> anyhow::Result<Database> {
    match opened {
        Ok(db) => Ok(db),
        Err(e @ (DbError::Corrupt(_) | DbError::Busy(_) | DbError::Sqlite(_))) => {
            Err(anyhow::Error::new(e))
                .context(format!("cannot use the database {}", path.display()))
        }
        Err(e) => Err(e.into()),
    }
}
