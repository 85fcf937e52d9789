//! `pipewave export --db DB --format gpkg|geojson|csv --out FILE`.

use std::path::PathBuf;

use anyhow::bail;
use clap::{Args, ValueEnum};
use pipewave::db::Database;
use pipewave::export::{self, ExportFormat, ExportSummary};

use super::Outcome;

/// The formats, as clap values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// OGC GeoPackage 1.4, in the segments' own coordinate system.
    Gpkg,
    /// RFC 7946 GeoJSON, WGS 84 longitude/latitude.
    Geojson,
    /// CSV keyed by segment_id, to join onto an existing pipe layer.
    Csv,
}

impl From<FormatArg> for ExportFormat {
    fn from(f: FormatArg) -> Self {
        match f {
            FormatArg::Gpkg => ExportFormat::Gpkg,
            FormatArg::Geojson => ExportFormat::GeoJson,
            FormatArg::Csv => ExportFormat::Csv,
        }
    }
}

/// Arguments of `export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The pipewave database to read (it must exist).
    #[arg(long, value_name = "DB")]
    db: PathBuf,
    /// Output format.
    #[arg(long, value_enum)]
    format: FormatArg,
    /// The file to write (replaced if it exists; never a pipewave database).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

/// Open an existing database (never create one: an export of nothing helps nobody).
pub fn open_existing(path: &std::path::Path) -> anyhow::Result<Database> {
    if !path.exists() {
        bail!(
            "no database at {}; run `pipewave import --db {}` first, or check the path",
            path.display(),
            path.display()
        );
    }
    Ok(Database::open_reader(path)?)
}

/// Print the warnings on stderr and one summary line on stdout.
pub fn report(what: &str, out: &std::path::Path, s: &ExportSummary) {
    for w in &s.warnings {
        eprintln!("warning: {w}");
    }
    println!(
        "wrote {what} {}: {} segments ({} fitted, {} with geometry)",
        out.display(),
        s.segments,
        s.fitted,
        s.with_geometry
    );
}

/// Run the export.
pub fn run(args: &ExportArgs) -> anyhow::Result<Outcome> {
    let database = open_existing(&args.db)?;
    let format = ExportFormat::from(args.format);
    let summary = export::write(&database, format, &args.out)?;
    report(&format!("the {format} export"), &args.out, &summary);
    Ok(Outcome::Done)
}
