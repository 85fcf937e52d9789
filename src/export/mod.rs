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
    /// Of which with a geometry in the output.
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
    /// The output path is the database being read, or another pipewave database.
    #[error(
        "refusing to write {} over {}: it is a pipewave database; give another --out path",
        format,
        path.display()
    )]
    WouldOverwriteDatabase {
        /// The output path.
        path: PathBuf,
        /// What was being written.
        format: &'static str,
    },
    /// The output path is a directory.
    #[error("{} is a directory; give the path of the file to write, such as {}", path.display(), path.join(suggested).display())]
    OutIsDirectory {
        /// The output path.
        path: PathBuf,
        /// A file name to suggest.
        suggested: &'static str,
    },
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
    check_out_path(db, out_path, format.as_str(), suggested)?;
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

/// Refuse an output path that is a directory, the database being read, or any pipewave database.
pub(crate) fn check_out_path(
    db: &Database,
    out: &Path,
    format: &'static str,
    suggested: &'static str,
) -> Result<(), ExportError> {
    if out.is_dir() {
        return Err(ExportError::OutIsDirectory {
            path: out.to_path_buf(),
            suggested,
        });
    }
    if !out.exists() {
        return Ok(());
    }
    let same = match (out.canonicalize(), db.path().canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if same || is_pipewave_database(out) {
        return Err(ExportError::WouldOverwriteDatabase {
            path: out.to_path_buf(),
            format,
        });
    }
    Ok(())
}

/// True when the file is a SQLite database with pipewave's `segments` and `fits` tables. Any
/// failure to tell (not SQLite, unreadable) answers false: such a file is not a pipewave database.
fn is_pipewave_database(path: &Path) -> bool {
    // Only a regular file can be a database; opening a FIFO to look would wait for a writer.
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return false;
    }
    let Ok(mut f) = std::fs::File::open(path) else {
        return false;
    };
    let mut magic = [0u8; 16];
    if std::io::Read::read_exact(&mut f, &mut magic).is_err() || &magic != b"SQLite format 3\0" {
        return false;
    }
    let flags =
        rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY | rusqlite::OpenFlags::SQLITE_OPEN_NO_MUTEX;
    let Ok(conn) = rusqlite::Connection::open_with_flags(path, flags) else {
        return false;
    };
    conn.query_row(
        "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name IN ('segments', 'fits')",
        [],
        |r| r.get::<_, i64>(0),
    )
    .map(|n| n == 2)
    .unwrap_or(false)
}

/// Where an output path leads: the file it names after following its symlinks, and whether
/// that is a stream (a character device such as `/dev/null` or `/dev/stdout`, or a FIFO) to be
/// written directly rather than replaced.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum OutTarget {
    /// A regular file, or a path that does not exist yet: written through a temporary file
    /// renamed over it.
    File(PathBuf),
    /// A device or FIFO: opened for writing as it is, never replaced.
    Stream(PathBuf),
}

/// Follow `out`'s symlinks (also to a target that does not exist yet, which is then created)
/// and tell a stream from a file. A symlink is never replaced: its target is written.
pub(crate) fn resolve_out(out: &Path) -> OutTarget {
    let mut path = out.to_path_buf();
    // A loop of links ends here and is left to the write to report.
    for _ in 0..40 {
        match std::fs::symlink_metadata(&path) {
            Ok(m) if m.file_type().is_symlink() => match std::fs::read_link(&path) {
                Ok(t) => {
                    path = match path.parent() {
                        Some(dir) if t.is_relative() => dir.join(t),
                        _ => t,
                    }
                }
                Err(_) => break,
            },
            Ok(m) if is_stream(&m.file_type()) => return OutTarget::Stream(path),
            _ => break,
        }
    }
    OutTarget::File(path)
}

#[cfg(unix)]
fn is_stream(t: &std::fs::FileType) -> bool {
    use std::os::unix::fs::FileTypeExt;
    t.is_char_device() || t.is_fifo() || t.is_block_device() || t.is_socket()
}

#[cfg(not(unix))]
fn is_stream(t: &std::fs::FileType) -> bool {
    !t.is_file() && !t.is_dir() && !t.is_symlink()
}

/// A temporary path for the contents of `out`: beside the file it names (same directory, so
/// the final rename is atomic), or in the system's temporary directory for a stream.
pub(crate) fn temp_path(out: &Path) -> PathBuf {
    let (dir, target) = match resolve_out(out) {
        OutTarget::File(p) => (None, p),
        OutTarget::Stream(p) => (Some(std::env::temp_dir()), p),
    };
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "export".into());
    let tmp = format!(".{name}.tmp-{}", std::process::id());
    match dir {
        Some(d) => d.join(tmp),
        None => target.with_file_name(tmp),
    }
}

/// Move the finished temporary file over the file `out` names, or copy it into the stream `out`
/// names; on failure remove the temporary file.
pub(crate) fn commit_temp(tmp: &Path, out: &Path) -> Result<(), ExportError> {
    let result = match resolve_out(out) {
        OutTarget::File(target) => std::fs::rename(tmp, target),
        OutTarget::Stream(target) => std::fs::File::open(tmp)
            .and_then(|mut from| {
                let mut to = std::fs::OpenOptions::new().write(true).open(target)?;
                std::io::copy(&mut from, &mut to)?;
                std::io::Write::flush(&mut to)
            })
            .and_then(|()| std::fs::remove_file(tmp)),
    };
    result.map_err(|source| {
        let _ = std::fs::remove_file(tmp);
        ExportError::Write {
            path: out.to_path_buf(),
            source,
        }
    })
}

/// Finish a write into the temporary file `tmp`: on success move it over `out`, on failure
/// remove it.
pub(crate) fn finish_temp<T>(
    tmp: &Path,
    out: &Path,
    result: Result<T, ExportError>,
) -> Result<T, ExportError> {
    match result {
        Ok(t) => {
            commit_temp(tmp, out)?;
            Ok(t)
        }
        Err(e) => {
            let _ = std::fs::remove_file(tmp);
            Err(e)
        }
    }
}

/// Write `out` through a temporary file with `fill`, which writes the contents into a buffered
/// writer; the file replaces `out` only when `fill` and the final flush succeed.
pub(crate) fn write_streamed<T>(
    out: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> Result<T, ExportError>,
) -> Result<T, ExportError> {
    let tmp = temp_path(out);
    let result = std::fs::File::create(&tmp)
        .map_err(|source| ExportError::Write {
            path: out.to_path_buf(),
            source,
        })
        .and_then(|f| {
            let mut w = std::io::BufWriter::new(f);
            let t = fill(&mut w)?;
            std::io::Write::flush(&mut w).map_err(|source| ExportError::Write {
                path: out.to_path_buf(),
                source,
            })?;
            Ok(t)
        });
    finish_temp(&tmp, out, result)
}

/// Write bytes to `out` through a temporary file.
pub(crate) fn write_file_atomically(out: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    let tmp = temp_path(out);
    std::fs::write(&tmp, bytes).map_err(|source| {
        let _ = std::fs::remove_file(&tmp);
        ExportError::Write {
            path: out.to_path_buf(),
            source,
        }
    })?;
    commit_temp(&tmp, out)
}
