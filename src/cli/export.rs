//! `pipewave export --db DB --format gpkg|geojson|csv --out FILE`.

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use pipewave::export::{self, ExportFormat, ExportSummary, Precision};

use super::Outcome;

/// The formats, as clap values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// OGC GeoPackage 1.2, in the segments' own coordinate system.
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
    /// Numbers of the CSV and GeoJSON: `people` prints each error to 2 significant digits and
    /// its value to the same decimal place, other values to 6 significant digits; `full` keeps
    /// every digit. The GeoPackage (and the database) always keep every digit.
    #[arg(long, value_enum, default_value = "people")]
    precision: PrecisionArg,
}

/// `--precision`, as clap values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PrecisionArg {
    /// Rounded to the errors (1323.2 ± 1.4).
    People,
    /// Every digit (1323.156273100555 ± 1.3588752771777628).
    Full,
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
    let format = ExportFormat::from(args.format);
    let contents = match format {
        ExportFormat::Gpkg => pipewave::outfile::Contents::GeoPackage,
        ExportFormat::GeoJson | ExportFormat::Csv => pipewave::outfile::Contents::Plain,
    };
    super::guard_outputs(Some(&args.db), &[], &[(&args.out, contents)])?;
    let database = super::open_reader(&args.db)?;
    let precision = match args.precision {
        PrecisionArg::People => Precision::People,
        PrecisionArg::Full => Precision::Full,
    };
    let summary = export::write_with_precision(&database, format, &args.out, precision)?;
    report(&format!("the {format} export"), &args.out, &summary);
    Ok(Outcome::Done)
}
