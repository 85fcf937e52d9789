//! CSV writer: one row per segment, the columns of [`PROPERTIES`] (first `segment_id`, the key to
//! join onto an existing pipe layer), no geometry. Numbers in Rust's shortest round-trip form, so
//! they read back bit for bit; missing values are empty cells. Text cells are made safe to open in
//! a spreadsheet ([`spreadsheet`](super::spreadsheet)): quoted, with a leading `'` when they begin
//! like a formula.

use std::path::Path;

use super::record::{Records, Value, PROPERTIES};
use super::spreadsheet::{spreadsheet_safe, writer};
use super::{write_streamed, ExportError, SegmentExport, Tally};

/// Write the header row.
fn header<W: std::io::Write>(w: &mut csv::Writer<W>) -> Result<(), csv::Error> {
    w.write_record(PROPERTIES.iter().map(|p| p.name))
}

/// Write one record's row (`row`: a buffer reused between rows).
fn row<W: std::io::Write>(
    w: &mut csv::Writer<W>,
    rec: &SegmentExport,
    row: &mut Vec<String>,
) -> Result<(), csv::Error> {
    row.clear();
    row.extend(PROPERTIES.iter().map(|p| match (p.get)(rec) {
        Value::Null => String::new(),
        Value::Text(s) => spreadsheet_safe(s).into_owned(),
        Value::Real(x) => x.to_string(),
        Value::Integer(i) => i.to_string(),
    }));
    w.write_record(row.iter())
}

/// The CSV text of `records`.
pub fn to_bytes(records: &[SegmentExport]) -> Result<Vec<u8>, csv::Error> {
    let mut w = writer(Vec::new());
    header(&mut w)?;
    let mut buf: Vec<String> = Vec::with_capacity(PROPERTIES.len());
    for rec in records {
        row(&mut w, rec, &mut buf)?;
    }
    w.into_inner().map_err(|e| csv::Error::from(e.into_error()))
}

/// Write the CSV of the records to `out`, each row as it is read.
pub(crate) fn write(records: &Records<'_>, out: &Path) -> Result<Tally, ExportError> {
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
        let mut buf: Vec<String> = Vec::with_capacity(PROPERTIES.len());
        let mut warnings = Vec::new();
        records.for_each(&mut warnings, |rec| {
            tally.add(&rec);
            row(&mut w, &rec, &mut buf).map_err(encode)
        })?;
        w.flush().map_err(|source| ExportError::Write {
            path: out.to_path_buf(),
            source,
        })?;
        tally.summary.warnings = warnings;
        Ok(tally)
    })
}
