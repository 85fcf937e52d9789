//! Importing `segments.csv` and `measurements.csv` (formats in docs/interface.md).
//!
//! Semantics:
//! - All or nothing: the import runs in one transaction, and any invalid row rejects it whole,
//!   with every bad row listed. With [`ImportOptions::skip_invalid`] the valid rows are imported
//!   and the others reported. A problem with a file as a whole (empty, no data rows, bad header)
//!   rejects the import even then: no row of such a file can be trusted.
//! - Re-importing identical data writes nothing.
//! - A segment already in the database is updated when its row differs. A blank cell stores
//!   NULL; an optional column the file does not have leaves the stored values of that column
//!   as they are (a file without `soil_zone` says nothing about zones).
//! - Every segment that appears in a measurements file gets exactly that file's measurements
//!   (its old set is replaced, if different). Segments not in the file keep theirs. Nothing is
//!   ever deleted from the inventory by an import.
//! - Each touched segment's `inputs_hash` is recomputed from what is stored; calibrate refits a
//!   segment whose hash changed.
//! - With `skip_invalid`, a measurement row whose segment row was skipped is skipped too.

pub mod aliases;
mod layer;
mod measurements;
mod segments;
mod staging;
mod table;

use std::fmt;
use std::io::Read;
use std::path::{Path, PathBuf};

use rusqlite::{params, Connection, Transaction, TransactionBehavior};

pub use measurements::SAME_FREQUENCY_REL_TOL;

use super::inventory;
use super::DbError;
use crate::units::escape_controls;
use staging::Staging;

/// One import file: its name for messages, its kind, and its bytes.
#[derive(Debug, Clone)]
pub struct ImportSource {
    /// Name used in messages, e.g. `data/segments.csv`.
    pub name: String,
    /// The raw bytes (checked for UTF-8 cell by cell, so a bad byte names its line and column).
    /// Empty for a GeoPackage and a CSV file, which are read from their path
    /// ([`SourceKind::GeoPackage`], [`SourceKind::CsvFile`]).
    pub data: Vec<u8>,
    /// CSV or which GIS layer format.
    pub kind: SourceKind,
}

/// What an import file is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceKind {
    /// `segments.csv` / `measurements.csv` (docs/interface.md), the bytes.
    Csv,
    /// The same, in a file read a record at a time as it is imported (never whole in memory).
    CsvFile(PathBuf),
    /// An OGC GeoPackage, read with SQLite from this path.
    GeoPackage(PathBuf),
    /// An RFC 7946 GeoJSON FeatureCollection (the bytes).
    GeoJson,
    /// An ESRI Shapefile: the bytes are the `.shp`; its `.dbf` (attributes) and `.prj`
    /// (coordinate system) beside it.
    Shapefile {
        /// The `.dbf`, if there is one.
        dbf: Option<Vec<u8>>,
        /// The `.prj` text, if there is one.
        prj: Option<Vec<u8>>,
    },
}

/// The SQLite file header, which every GeoPackage starts with.
const SQLITE_MAGIC: &[u8] = b"SQLite format 3\0";

impl ImportSource {
    /// Read a file; its kind comes from the extension (`.gpkg`, `.geojson`/`.json`, `.shp`,
    /// anything else CSV) or, for a SQLite file, from its header.
    pub fn from_path(path: &Path) -> Result<ImportSource, DbError> {
        let read = |p: &Path| {
            std::fs::read(p).map_err(|source| DbError::ReadFile {
                path: p.to_path_buf(),
                source,
            })
        };
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        let name = path.display().to_string();
        let kind = match ext.as_str() {
            "gpkg" => SourceKind::GeoPackage(path.to_path_buf()),
            "geojson" | "json" => SourceKind::GeoJson,
            "shp" => {
                let sidecar = |e: &str| -> Result<Option<Vec<u8>>, DbError> {
                    // Upper- or lower-case extension, as the .shp has.
                    for cand in [e.to_string(), e.to_ascii_uppercase()] {
                        let p = path.with_extension(&cand);
                        if p.exists() {
                            return read(&p).map(Some);
                        }
                    }
                    Ok(None)
                };
                SourceKind::Shapefile {
                    dbf: sidecar("dbf")?,
                    prj: sidecar("prj")?,
                }
            }
            _ => SourceKind::Csv,
        };
        if let SourceKind::GeoPackage(_) = kind {
            // Check it can be read now (a mistyped path must not create a database).
            std::fs::metadata(path).map_err(|source| DbError::ReadFile {
                path: path.to_path_buf(),
                source,
            })?;
            return Ok(ImportSource {
                name,
                data: Vec::new(),
                kind,
            });
        }
        if kind == SourceKind::Csv {
            // Read now only the first bytes: whether it is readable, and whether it is a
            // GeoPackage whatever its name.
            let mut magic = Vec::with_capacity(SQLITE_MAGIC.len());
            std::fs::File::open(path)
                .and_then(|f| f.take(SQLITE_MAGIC.len() as u64).read_to_end(&mut magic))
                .map_err(|source| DbError::ReadFile {
                    path: path.to_path_buf(),
                    source,
                })?;
            let kind = if magic == SQLITE_MAGIC {
                SourceKind::GeoPackage(path.to_path_buf())
            } else {
                SourceKind::CsvFile(path.to_path_buf())
            };
            return Ok(ImportSource {
                name,
                data: Vec::new(),
                kind,
            });
        }
        let data = read(path)?;
        Ok(ImportSource { name, data, kind })
    }

    /// In-memory CSV text, for tests and for generated networks.
    pub fn from_bytes(name: impl Into<String>, data: impl Into<Vec<u8>>) -> ImportSource {
        ImportSource {
            name: name.into(),
            data: data.into(),
            kind: SourceKind::Csv,
        }
    }
}

/// Every column name an import file may have (segments and measurements), for checking
/// `--map COLUMN=FIELD`.
pub fn known_columns() -> Vec<&'static str> {
    let mut v: Vec<&'static str> = segments::COLUMNS.iter().map(|c| c.name).collect();
    for c in measurements::COLUMNS {
        if !v.contains(&c.name) {
            v.push(c.name);
        }
    }
    v
}

/// How to import.
#[derive(Debug, Clone, Default)]
pub struct ImportOptions {
    /// Import the valid rows and report the invalid ones, instead of rejecting the import.
    pub skip_invalid: bool,
    /// Reject columns pipewave does not know, instead of ignoring them with a note.
    pub strict: bool,
    /// The layer of a GeoPackage holding several (`--layer`).
    pub layer: Option<String>,
    /// `(pipewave column, the file's field)` pairs (`--map COLUMN=FIELD`), matched
    /// case-insensitively.
    pub map: Vec<(String, String)>,
    /// EPSG code of the coordinates of a file that does not name its CRS (`--srid N`): a
    /// GeoJSON without `crs`, CSV geometry without `srid`.
    pub srid: Option<i64>,
    /// Campaigns whose stored rows that the measurements file does not hold are deleted
    /// (`--replace-campaign NAME`); by default a re-imported campaign keeps them.
    pub replace_campaigns: Vec<String>,
}

/// At most this many problems are listed (the first, in file and line order); the others are
/// only counted ([`ImportReport::problems`]), so a file of garbage neither floods the terminal
/// nor holds its every message in memory.
pub const MAX_LISTED_PROBLEMS: usize = 1000;

/// The problems of one file as they are found: the first [`MAX_LISTED_PROBLEMS`] in (line,
/// column) order, and how many there are in all. Memory stays bounded whatever the file.
#[derive(Debug, Default)]
pub(super) struct Problems {
    kept: Vec<RowError>,
    total: usize,
}

impl Problems {
    /// Note one problem.
    pub fn push(&mut self, e: RowError) {
        self.total += 1;
        self.kept.push(e);
        if self.kept.len() >= 2 * MAX_LISTED_PROBLEMS {
            self.trim();
        }
    }

    /// Note several.
    pub fn append(&mut self, v: &mut Vec<RowError>) {
        for e in v.drain(..) {
            self.push(e);
        }
    }

    fn trim(&mut self) {
        self.kept
            .sort_by(|a, b| (a.line, &a.column).cmp(&(b.line, &b.column)));
        self.kept.truncate(MAX_LISTED_PROBLEMS);
    }

    /// The first problems in order, and the count of all.
    pub fn finish(mut self) -> (Vec<RowError>, usize) {
        self.trim();
        (self.kept, self.total)
    }
}

impl From<Vec<RowError>> for Problems {
    fn from(mut v: Vec<RowError>) -> Problems {
        let mut p = Problems::default();
        p.append(&mut v);
        p
    }
}

/// A column of an import file: 1-based position and name.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct ColumnRef {
    /// 1-based column number.
    pub index: usize,
    /// Column name (canonical for known columns, as written otherwise).
    pub name: String,
}

impl ColumnRef {
    /// From a 0-based field index.
    pub(crate) fn new(field: usize, name: &str) -> ColumnRef {
        ColumnRef {
            index: field + 1,
            name: name.to_string(),
        }
    }
}

/// One problem in an import file. Displays as `FILE:LINE:COL: column NAME: reason`, or
/// `FILE:LINE: reason` for a problem with the whole line or file; in a GIS layer as
/// `FILE: layer L: feature FID: field NAME: reason` (or without the feature or field).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RowError {
    /// The file, as named in the [`ImportSource`].
    pub file: String,
    /// The layer, for a GIS layer.
    pub layer: Option<String>,
    /// 1-based line (where the record starts); in a layer, the feature id (0: the layer as a
    /// whole).
    pub line: u64,
    /// The column, when the problem is in one cell or header name.
    pub column: Option<ColumnRef>,
    /// What is wrong and what was expected.
    pub message: String,
}

impl RowError {
    pub(crate) fn new(
        file: &str,
        line: u64,
        column: Option<ColumnRef>,
        message: impl Into<String>,
    ) -> RowError {
        RowError {
            file: file.to_string(),
            layer: None,
            line,
            column,
            message: message.into(),
        }
    }
}

impl fmt::Display for RowError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Everything shown may come from the file (its name, a header, a cell): control
        // characters are escaped.
        let mut out = String::new();
        if let Some(layer) = &self.layer {
            out.push_str(&format!("{}: layer {layer}: ", self.file));
            if self.line > 0 {
                out.push_str(&format!("feature {}: ", self.line));
            }
            if let Some(c) = &self.column {
                out.push_str(&format!("field {}: ", c.name));
            }
            out.push_str(&self.message);
        } else {
            match &self.column {
                Some(c) => out.push_str(&format!(
                    "{}:{}:{}: column {}: {}",
                    self.file, self.line, c.index, c.name, self.message
                )),
                None => out.push_str(&format!("{}:{}: {}", self.file, self.line, self.message)),
            }
        }
        f.write_str(&escape_controls(&out))
    }
}

impl std::error::Error for RowError {}

/// What an import did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ImportReport {
    /// True when nothing was written because of `errors` (without `skip_invalid`, any error;
    /// with it, a problem with a whole file).
    pub rejected: bool,
    /// True when a file as a whole is unusable (empty, no data rows, bad header): then the
    /// import is rejected even with `skip_invalid`.
    pub unusable_file: bool,
    /// New segments.
    pub segments_inserted: usize,
    /// Segments whose row changed.
    pub segments_updated: usize,
    /// Segments in the file whose row was already as given.
    pub segments_unchanged: usize,
    /// Measurement rows written (for segments whose set changed).
    pub measurements_written: usize,
    /// Segments whose stored measurements changed (a row added, updated or removed).
    pub segments_with_changed_measurements: usize,
    /// What the import did to each campaign it held rows of, by name.
    pub campaigns: std::collections::BTreeMap<String, CampaignCounts>,
    /// Segments whose `inputs_hash` changed: calibrate will (re)fit them.
    pub segments_with_changed_inputs: usize,
    /// The invalid rows, in file and line order: the first [`MAX_LISTED_PROBLEMS`] of each
    /// file.
    pub errors: Vec<RowError>,
    /// How many problems were found in all (`errors` lists the first of them).
    pub problems: usize,
    /// Things to tell the user that reject nothing: the columns ignored, one note per file.
    pub notes: Vec<String>,
}

/// What one import did to the rows of one campaign.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CampaignCounts {
    /// Rows at a frequency the campaign did not have for their segment.
    pub added: usize,
    /// Rows that replaced a stored row of the campaign at the same frequency.
    pub updated: usize,
    /// Stored rows of the campaign left as they were (unchanged, or not in the file).
    pub kept: usize,
    /// Stored rows of the campaign not in the file, deleted by `--replace-campaign`.
    pub removed: usize,
}

/// Import the given files into the database (see the module docs for the semantics). At least
/// one file should be given; with none, nothing happens. Row problems are returned in the
/// report, not as `Err`; `Err` means the database itself failed.
///
/// Memory does not grow with the files: a CSV is read a record at a time, and the checked rows
/// are staged in temporary tables (`staging`) that the checks and the writes then query in
/// order.
pub fn import(
    conn: &mut Connection,
    segments: Option<&ImportSource>,
    measurements: Option<&ImportSource>,
    options: ImportOptions,
) -> Result<ImportReport, DbError> {
    let conn: &Connection = conn;
    let staging = Staging::create(conn)?;
    // Read, check and stage both files. Only the temporary tables are written here, so the
    // database is not locked yet.
    let staged = Transaction::new_unchecked(conn, TransactionBehavior::Deferred)?;
    let segs = segments
        .map(|s| segments::parse(s, &options, &staging))
        .transpose()?;
    let meas = measurements
        .map(|m| measurements::parse(m, &options, &staging))
        .transpose()?;
    staged.commit()?;

    // IMMEDIATE: take the write lock now, so the segments we check against cannot change.
    let tx = Transaction::new_unchecked(conn, TransactionBehavior::Immediate)?;
    let mut report = ImportReport::default();
    let mut fatal = false;
    let mut seg_errors = Problems::default();
    let mut meas_errors = Problems::default();
    let mut segments_file_unusable = false;
    let mut absent = Vec::new();
    if let Some(mut p) = segs {
        absent = p.absent;
        report.notes.append(&mut p.notes);
        fatal |= p.fatal;
        segments_file_unusable = p.fatal;
        seg_errors = p.errors;
    }

    // Measurements: their segment must be in the database or among the valid file rows.
    if let Some(mut p) = meas {
        report.notes.append(&mut p.notes);
        fatal |= p.fatal;
        meas_errors = p.errors;
        let seg_file = segments.map_or("segments file", |s| s.name.as_str());
        // When the segments file is unusable as a whole, whether a measurement's segment
        // exists cannot be told; the import is rejected anyway, so do not add noise.
        if !segments_file_unusable {
            let mut unknown = Vec::new();
            staging.measurements_of_unknown_segments(|rowid, id, line| {
                let message = match staging.invalid_segment_line(&id)? {
                    Some(at) => format!(
                        "segment '{id}' cannot be imported: its row in {seg_file} (line {at}) is invalid"
                    ),
                    None => format!(
                        "segment '{id}' is not in the inventory (neither in the database nor in the segments file); import its segment row first"
                    ),
                };
                meas_errors.push(RowError::new(
                    &p.file,
                    line,
                    Some(ColumnRef::new(p.segment_id_column, "segment_id")),
                    message,
                ));
                unknown.push(rowid);
                Ok(())
            })?;
            for rowid in unknown {
                staging.invalidate_measurement(rowid)?;
            }
        }
    }
    let (mut seg_list, seg_total) = seg_errors.finish();
    let (mut meas_list, meas_total) = meas_errors.finish();
    report.problems = seg_total + meas_total;
    report.errors.append(&mut seg_list);
    report.errors.append(&mut meas_list);

    if fatal || (report.problems > 0 && !options.skip_invalid) {
        report.rejected = true;
        report.unusable_file = fatal;
        // Dropping the transaction rolls it back; nothing was written anyway.
        return Ok(report);
    }

    staging.valid_segments(|mut rec| {
        let old = inventory::load_segment(&tx, &rec.segment_id)?;
        if let Some(old) = &old {
            segments::keep_stored(&mut rec, old, &absent);
        }
        match old {
            None => {
                inventory::insert_segment(&tx, &rec)?;
                report.segments_inserted += 1;
            }
            Some(old) if !old.same_inventory(&rec) => {
                inventory::update_segment(&tx, &rec)?;
                report.segments_updated += 1;
            }
            Some(_) => report.segments_unchanged += 1,
        }
        Ok(())
    })?;
    let mut changed_segment: Option<String> = None;
    staging.measurement_sets(|id, campaign, set| {
        let replace = options.replace_campaigns.iter().any(|c| c == campaign);
        let w = inventory::store_campaign(
            &tx,
            id,
            campaign,
            &set,
            replace,
            measurements::same_frequency,
        )?;
        let counts = report.campaigns.entry(campaign.to_string()).or_default();
        counts.added += w.added;
        counts.updated += w.updated;
        counts.kept += w.kept;
        counts.removed += w.removed;
        let written = w.added + w.updated + w.removed;
        report.measurements_written += written;
        if written > 0 && changed_segment.as_deref() != Some(id) {
            report.segments_with_changed_measurements += 1;
            changed_segment = Some(id.to_string());
        }
        Ok(())
    })?;
    // A replaced campaign keeps only what the file holds: its rows on segments the file does
    // not name are deleted too.
    let mut elsewhere: Vec<String> = Vec::new();
    for campaign in &options.replace_campaigns {
        let ids: Vec<String> = tx
            .prepare(
                "SELECT DISTINCT segment_id FROM main.measurements WHERE campaign = ?1 \
                 AND segment_id NOT IN (SELECT segment_id FROM temp.import_measurements \
                 WHERE valid AND campaign = ?1) ORDER BY segment_id",
            )?
            .query_map([campaign], |r| r.get(0))?
            .collect::<Result<_, _>>()?;
        for id in &ids {
            let n = tx.execute(
                "DELETE FROM main.measurements WHERE campaign = ?1 AND segment_id = ?2",
                params![campaign, id],
            )?;
            report
                .campaigns
                .entry(campaign.clone())
                .or_default()
                .removed += n;
            report.measurements_written += n;
            report.segments_with_changed_measurements += 1;
        }
        elsewhere.extend(ids);
    }
    let mut refresh = |id: &str| -> Result<(), DbError> {
        if super::staleness::refresh_inputs_hash(&tx, id)? {
            report.segments_with_changed_inputs += 1;
        }
        Ok(())
    };
    staging.touched_segments(&mut refresh)?;
    elsewhere.sort();
    elsewhere.dedup();
    for id in &elsewhere {
        refresh(id)?;
    }
    tx.commit()?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::migrate;

    fn db() -> Connection {
        let mut conn = Connection::open_in_memory().unwrap();
        conn.pragma_update(None, "foreign_keys", true).unwrap();
        migrate::migrate(&mut conn, Path::new(":memory:")).unwrap();
        conn
    }

    const SEGS: &str =
        "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3\n\
                        A,di,170,6,1900\nB,PVC,110,5.3,1800\n";
    const MEAS: &str = "segment_id,frequency_hz,k_re_rad_per_m,attenuation_np_per_m\n\
                        A,100,0.5,0.01\nA,200,1.0,0.02\nB,100,0.9,0.05\n";

    fn run(conn: &mut Connection, s: Option<&str>, m: Option<&str>, skip: bool) -> ImportReport {
        let s = s.map(|t| ImportSource::from_bytes("segments.csv", t));
        let m = m.map(|t| ImportSource::from_bytes("measurements.csv", t));
        import(
            conn,
            s.as_ref(),
            m.as_ref(),
            ImportOptions {
                skip_invalid: skip,
                ..ImportOptions::default()
            },
        )
        .unwrap()
    }

    fn count(conn: &Connection, table: &str) -> i64 {
        conn.query_row(&format!("SELECT COUNT(*) FROM {table}"), [], |r| r.get(0))
            .unwrap()
    }

    #[test]
    fn good_import_then_identical_reimport_changes_nothing() {
        let mut conn = db();
        let r = run(&mut conn, Some(SEGS), Some(MEAS), false);
        assert!(!r.rejected && r.errors.is_empty(), "{r:?}");
        assert_eq!((r.segments_inserted, r.measurements_written), (2, 3));
        assert_eq!(r.segments_with_changed_inputs, 2);
        let a = inventory::load_segment(&conn, "A").unwrap().unwrap();
        assert_eq!(a.material, crate::physics::Material::DuctileIron);
        assert_eq!(
            Some(a.inputs_hash.clone()),
            crate::db::stored_inputs_hash(&conn, "A").unwrap()
        );
        assert!((a.measurements[1].omega_rad_s - 2.0 * std::f64::consts::PI * 200.0).abs() < 1e-12);
        let r2 = run(&mut conn, Some(SEGS), Some(MEAS), false);
        assert_eq!(
            r2,
            ImportReport {
                segments_unchanged: 2,
                campaigns: [(
                    "unnamed".to_string(),
                    CampaignCounts {
                        kept: 3,
                        ..CampaignCounts::default()
                    }
                )]
                .into(),
                ..ImportReport::default()
            }
        );
        let a2 = inventory::load_segment(&conn, "A").unwrap().unwrap();
        assert_eq!(a2, a);
    }

    #[test]
    fn excel_style_files_with_bom_crlf_and_mixed_case_headers_import() {
        let mut conn = db();
        let segs =
            format!("\u{feff}{}", SEGS.replace("segment_id", "Segment_ID")).replace('\n', "\r\n");
        let r = run(
            &mut conn,
            Some(&segs),
            Some(&MEAS.replace('\n', "\r\n")),
            false,
        );
        assert!(r.errors.is_empty(), "{:?}", r.errors);
        assert_eq!((r.segments_inserted, r.measurements_written), (2, 3));
    }

    #[test]
    fn a_header_without_rows_is_an_error_for_the_whole_file() {
        let mut conn = db();
        let head = SEGS.lines().next().unwrap();
        let r = run(&mut conn, Some(head), None, true);
        assert!(r.rejected && r.unusable_file);
        assert_eq!(
            r.errors[0].to_string(),
            "segments.csv:2: the file has a header but no data rows"
        );
    }

    #[test]
    fn one_bad_row_rejects_everything_unless_skipping() {
        let mut conn = db();
        let bad = format!("{SEGS}C,XX,100,5,1900\n");
        let r = run(&mut conn, Some(&bad), Some(MEAS), false);
        assert!(r.rejected && !r.unusable_file);
        assert_eq!(r.errors.len(), 1, "{:?}", r.errors);
        assert_eq!(
            r.errors[0].to_string(),
            "segments.csv:4:2: column material: unknown material 'XX' (expected one of CI, DI, ST, PVC, MDPE, HDPE, AC)"
        );
        assert_eq!(count(&conn, "segments"), 0);
        let r = run(&mut conn, Some(&bad), Some(MEAS), true);
        assert!(!r.rejected);
        assert_eq!((r.segments_inserted, r.errors.len()), (2, 1));
    }

    #[test]
    fn measurements_of_a_skipped_segment_are_skipped_with_a_pointer_to_its_row() {
        let mut conn = db();
        let segs = SEGS.replace("B,PVC,110,5.3,1800", "B,PVC,110,80,1800");
        let r = run(&mut conn, Some(&segs), Some(MEAS), true);
        assert_eq!(r.errors.len(), 2, "{:?}", r.errors);
        assert_eq!(r.errors[1].file, "measurements.csv");
        assert!(r.errors[1].message.contains("line 3"), "{}", r.errors[1]);
        assert_eq!((r.segments_inserted, r.measurements_written), (1, 2));
    }

    #[test]
    fn frequency_in_hz_and_rad_s_are_the_same_frequency() {
        let mut conn = db();
        let meas = "segment_id,frequency_hz,omega_rad_s,k_re_rad_per_m,attenuation_np_per_m\n\
                    A,100,,0.5,0.01\nA,,628.3185307179587,0.5,0.01\n";
        let r = run(&mut conn, Some(SEGS), Some(meas), false);
        assert!(r.rejected);
        assert_eq!(r.errors.len(), 2, "{:?}", r.errors);
        assert!(r
            .errors
            .iter()
            .all(|e| e.message.contains("at this frequency")));
    }

    /// A re-imported campaign keeps its stored rows that the file does not hold and adds the new
    /// one; only the segments in the file are touched.
    #[test]
    fn a_reimported_campaign_adds_and_keeps_for_the_segments_in_the_file_only() {
        let mut conn = db();
        run(&mut conn, Some(SEGS), Some(MEAS), false);
        let hb = inventory::load_segment(&conn, "B")
            .unwrap()
            .unwrap()
            .inputs_hash;
        let ha = inventory::load_segment(&conn, "A")
            .unwrap()
            .unwrap()
            .inputs_hash;
        let r = run(
            &mut conn,
            None,
            Some("segment_id,omega_rad_s,k_re_rad_per_m,attenuation_np_per_m\nA,1000,0.8,0\n"),
            false,
        );
        assert_eq!(
            (r.segments_with_changed_measurements, r.measurements_written),
            (1, 1)
        );
        let a = inventory::load_segment(&conn, "A").unwrap().unwrap();
        assert_eq!(a.measurements.len(), 3, "the two stored rows are kept");
        assert_ne!(a.inputs_hash, ha);
        let b = inventory::load_segment(&conn, "B").unwrap().unwrap();
        assert_eq!((b.measurements.len(), b.inputs_hash), (1, hb));
    }
}
