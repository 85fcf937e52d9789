//! `pipewave audit --db DB --out report.html`.

use std::path::PathBuf;

use clap::Args;
use pipewave::report;

use super::export::report as print_summary;
use super::Outcome;

/// Arguments of `audit`.
#[derive(Debug, Args)]
pub struct AuditArgs {
    /// The pipewave database to read (it must exist).
    #[arg(long, value_name = "DB")]
    db: PathBuf,
    /// The HTML file to write (replaced if it exists).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

/// Write the report.
pub fn run(args: &AuditArgs) -> anyhow::Result<Outcome> {
    super::guard_outputs(
        Some(&args.db),
        &[],
        &[(&args.out, pipewave::outfile::Contents::Plain)],
    )?;
    let database = super::open_reader(&args.db)?;
    let summary = report::audit::write(&database, &args.out)?;
    print_summary("the audit report", &args.out, &summary);
    Ok(Outcome::Done)
}
