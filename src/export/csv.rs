//! CSV writer: one row per segment, the columns of [`super::PROPERTIES`] in the order of
//! [`columns`] (first `segment_id`, the key to join onto an existing pipe layer, then the
//! leak-band speed and its error), no geometry. Numbers as [`Precision`] says: rounded for
//! people by default, or in Rust's shortest round-trip form (read back bit for bit) with
//! `Precision::Full`; missing values are empty cells. pipewave's own lists (the reasons) are on
//! one line, joined with `; ` ([`crate::spreadsheet::one_line`], applied when the record is
//! built); the inventory's text is written as given. Text cells are made safe to open in
//! a spreadsheet ([`spreadsheet`](crate::spreadsheet)): quoted, with a leading `'` when they begin
//! like a formula.

use std::path::Path;

use super::numbers::{columns, Cell, Precision};
use super::record::Records;
use super::{write_streamed, ExportError, SegmentExport, Tally};
use crate::spreadsheet::{spreadsheet_safe, writer};

/// Write the header row.
fn header<W: std::io::Write>(w: &mut csv::Writer<W>) -> Result<(), csv::Error> {
    w.write_record(columns().properties.iter().map(|p| p.name))
}

/// Write one record's row (`row`: a buffer reused between rows).
fn row<W: std::io::Write>(
    w: &mut csv::Writer<W>,
    rec: &SegmentExport,
    precision: Precision,
    row: &mut Vec<String>,
) -> Result<(), csv::Error> {
    row.clear();
    row.extend(
        columns()
            .cells(rec, precision)
            .into_iter()
            .map(|c| match c {
                Cell::Null => String::new(),
                Cell::Text(s) => spreadsheet_safe(s).into_owned(),
                Cell::Number(n) => n,
            }),
    );
    w.write_record(row.iter())
}

/// The CSV text of `records`, numbers printed at `precision`.
pub fn to_bytes(records: &[SegmentExport], precision: Precision) -> Result<Vec<u8>, csv::Error> {
    let mut w = writer(Vec::new());
    header(&mut w)?;
    let mut buf: Vec<String> = Vec::new();
    for rec in records {
        row(&mut w, rec, precision, &mut buf)?;
    }
    w.into_inner().map_err(|e| csv::Error::from(e.into_error()))
}

/// Write the CSV of the records to `out`, each row as it is read.
pub(crate) fn write(
    records: &Records<'_>,
    out: &Path,
    precision: Precision,
) -> Result<Tally, ExportError> {
    let encode = |e: csv::Error| {
        let message = e.to_string();
        match e.into_kind() {
            csv::ErrorKind::Io(source) => ExportError::Write {
                path: out.to_path_buf(),
                source,
            },
            _ => ExportError::Encode {
                path: out.to_path_buf(),
                message,
            },
        }
    };
    write_streamed(out, |file| {
        let mut tally = Tally::default();
        let mut w = writer(file);
        header(&mut w).map_err(encode)?;
        let mut buf: Vec<String> = Vec::new();
        let mut warnings = Vec::new();
        records.for_each(&mut warnings, |rec| {
            tally.add(&rec);
            // The CSV has no geometry column: it counts the segments the GIS exports would
            // draw (a readable line in a known system), so that their counts agree.
            tally.summary.with_geometry +=
                usize::from(rec.geometry.is_some() && rec.segment.srid.is_some());
            row(&mut w, &rec, precision, &mut buf).map_err(encode)
        })?;
        w.flush().map_err(|source| ExportError::Write {
            path: out.to_path_buf(),
            source,
        })?;
        tally.summary.warnings = warnings;
        Ok(tally)
    })
}
