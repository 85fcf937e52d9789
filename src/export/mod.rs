//! GIS export of the calibration results: one record per segment of the inventory, with its
//! latest fit, written as a GeoPackage, GeoJSON or CSV file.
//!
//! - [`record`]: the per-segment record shared by the three formats and the audit report, read
//!   from the database a page at a time ([`Records`]), and the list of exported properties
//!   ([`record::PROPERTIES`]).
//! - [`numbers`]: the order of the columns and how the CSV and GeoJSON print numbers (rounded
//!   to their errors for people, or every digit).
//! - [`crs`](crate::db::crs): coordinate reference systems (EPSG definitions and reprojection).
//! - [`gpkg`], [`geojson`], [`csv`]: the writers.
//! - [`spreadsheet`](crate::spreadsheet): the rule every CSV writer follows so a cell never
//!   opens as a formula.
//!
//! Every writer streams: it writes each record as it is read, so an export of 100,000 segments
//! holds one page of records, not the network.
//!
//! Every writer writes a temporary file beside the target and renames it over the target at the
//! end, so a failed export never leaves a half-written file, and it refuses to replace the
//! pipewave database itself (or any other pipewave database). A symlink is followed (its
//! target is written, the link kept); a character device or FIFO (`/dev/null`, a pipe to
//! another program) is written directly, never replaced (`resolve_out`).

pub mod columns;
pub mod csv;
pub mod field;
pub mod geojson;
pub mod gpkg;
pub mod numbers;
pub mod record;
pub mod style;
pub mod zones;

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::db::{Database, DbError};
use crate::outfile::{Contents, OutFile, OutputError};

pub use numbers::Precision;
pub use record::{load_records, Records, SegmentExport, PAGE_SIZE, PROPERTIES};

/// The output formats of `pipewave export`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ExportFormat {
    /// OGC GeoPackage 1.2 (`.gpkg`), in the segments' own coordinate system, with a default
    /// QGIS style.
    Gpkg,
    /// RFC 7946 GeoJSON, WGS 84 longitude/latitude.
    GeoJson,
    /// CSV keyed by `segment_id`, for joining onto an existing pipe layer.
    Csv,
}

impl ExportFormat {
    /// The name used on the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            ExportFormat::Gpkg => "gpkg",
            ExportFormat::GeoJson => "geojson",
            ExportFormat::Csv => "csv",
        }
    }
}

impl fmt::Display for ExportFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for ExportFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "gpkg" | "geopackage" => Ok(ExportFormat::Gpkg),
            "geojson" | "json" => Ok(ExportFormat::GeoJson),
            "csv" => Ok(ExportFormat::Csv),
            _ => Err(format!(
                "unknown export format '{s}'; expected gpkg, geojson or csv"
            )),
        }
    }
}

/// What an export (or the audit report) did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ExportSummary {
    /// Segments written (every segment of the inventory).
    pub segments: usize,
    /// Of which with a geometry: in the output (GeoPackage, GeoJSON), or for the CSV, which
    /// has no geometry column, a readable line in a known system (what the others would draw).
    pub with_geometry: usize,
    /// Of which with a fit.
    pub fitted: usize,
    /// Things the user should know (unknown coordinate system, unreadable geometry, ...), one
    /// line each.
    pub warnings: Vec<String>,
}

/// Everything that can go wrong while writing an export or a report, worded for the engineer
/// running it; each message names the file.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Reading the pipewave database failed.
    #[error("cannot read the results from the database {}", path.display())]
    Database {
        /// The database path.
        path: PathBuf,
        /// What went wrong.
        #[source]
        source: DbError,
    },
    /// The output path may not be written (a directory, a database, an input, a read-only
    /// file).
    #[error(transparent)]
    Output(#[from] OutputError),
    /// Creating, writing or renaming the output failed.
    #[error("cannot write {}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// SQLite failed while writing the GeoPackage.
    #[error("cannot write the GeoPackage {}", path.display())]
    Gpkg {
        /// The file.
        path: PathBuf,
        /// What SQLite said.
        #[source]
        source: rusqlite::Error,
    },
    /// Serialising JSON or CSV failed.
    #[error("cannot write {}: {message}", path.display())]
    Encode {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

impl ExportError {
    pub(crate) fn db(db: &Database) -> impl Fn(DbError) -> ExportError + '_ {
        move |source| ExportError::Database {
            path: db.path().to_path_buf(),
            source,
        }
    }
}

/// Write the export of every segment in `format` to `out_path` (replacing the file if it
/// exists, unless it is a pipewave database), reading the database [`PAGE_SIZE`] segments at a
/// time. The CSV and GeoJSON print numbers for people ([`Precision::People`]).
pub fn write(
    db: &Database,
    format: ExportFormat,
    out_path: &Path,
) -> Result<ExportSummary, ExportError> {
    write_paged(db, format, out_path, PAGE_SIZE)
}

/// [`write()`] with the CSV's and GeoJSON's numbers printed at `precision` (the GeoPackage
/// always keeps every digit).
pub fn write_with_precision(
    db: &Database,
    format: ExportFormat,
    out_path: &Path,
    precision: Precision,
) -> Result<ExportSummary, ExportError> {
    write_pages(db, format, out_path, PAGE_SIZE, precision)
}

/// [`write()`], reading the database `page_size` segments at a time: the file is the same for
/// every page size; what the export holds is one page of records (with their curves) and a few
/// numbers per segment (the leak-band speed for the style's classes, the GeoPackage's spatial
/// index).
pub fn write_paged(
    db: &Database,
    format: ExportFormat,
    out_path: &Path,
    page_size: usize,
) -> Result<ExportSummary, ExportError> {
    write_pages(db, format, out_path, page_size, Precision::default())
}

fn write_pages(
    db: &Database,
    format: ExportFormat,
    out_path: &Path,
    page_size: usize,
    precision: Precision,
) -> Result<ExportSummary, ExportError> {
    let suggested = match format {
        ExportFormat::Gpkg => "pipewave.gpkg",
        ExportFormat::GeoJson => "pipewave.geojson",
        ExportFormat::Csv => "pipewave.csv",
    };
    let contents = match format {
        ExportFormat::Gpkg => Contents::GeoPackage,
        ExportFormat::GeoJson | ExportFormat::Csv => Contents::Plain,
    };
    check_out_path(db, out_path, contents, suggested)?;
    let records = Records::new(db, page_size);
    let _snapshot = records.snapshot()?;
    let tally = match format {
        ExportFormat::Gpkg => gpkg::write(&records, out_path)?,
        ExportFormat::GeoJson => geojson::write(&records, out_path, precision)?,
        ExportFormat::Csv => csv::write(&records, out_path, precision)?,
    };
    if format != ExportFormat::Gpkg {
        // The default QGIS style beside the file (the GeoPackage holds its own).
        write_file_atomically(
            &style::qml_path(out_path),
            style::qml(tally.speeds.iter().copied()).as_bytes(),
        )?;
    }
    Ok(tally.summary)
}

/// What a writer counts while the records stream past: the summary, and the leak-band speeds
/// for the style's classes.
#[derive(Debug, Default)]
pub(crate) struct Tally {
    /// Counts and warnings (those of reading the records first).
    pub summary: ExportSummary,
    /// The segments' leak-band speeds, m/s (those they have).
    pub speeds: Vec<f64>,
}

impl Tally {
    /// Count one record.
    pub fn add(&mut self, rec: &SegmentExport) {
        self.summary.segments += 1;
        self.summary.fitted += usize::from(rec.fit.is_some());
        self.speeds.extend(rec.leak_band_speed);
    }
}

/// Refuse an output path that the guard of [`crate::outfile`] refuses: a directory, the database
/// being read, any other database, an input or a read-only file. `contents` says whether a
/// GeoPackage is written (which may replace a GeoPackage).
pub(crate) fn check_out_path(
    db: &Database,
    out: &Path,
    contents: Contents,
    suggested: &'static str,
) -> Result<(), ExportError> {
    crate::outfile::protect_database(db.path());
    crate::outfile::check(out, contents, suggested)?;
    Ok(())
}

/// Write `out` through an [`OutFile`] with `fill`, which writes the contents into a buffered
/// writer; the file replaces `out` only when `fill` and the final flush succeed.
pub(crate) fn write_streamed<T>(
    out: &Path,
    fill: impl FnOnce(&mut OutFile) -> Result<T, ExportError>,
) -> Result<T, ExportError> {
    let mut file = OutFile::create(out, Contents::Plain)?;
    let t = fill(&mut file)?;
    file.commit()?;
    Ok(t)
}

/// Write bytes to `out` through an [`OutFile`].
pub(crate) fn write_file_atomically(out: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    crate::outfile::write_bytes(out, Contents::Plain, bytes)?;
    Ok(())
}
