//! CSV writer: one row per segment, the columns of [`PROPERTIES`] (first `segment_id`, the key to
//! join onto an existing pipe layer), no geometry. Numbers in Rust's shortest round-trip form, so
//! they read back bit for bit; missing values are empty cells. Text cells are made safe to open in
//! a spreadsheet ([`spreadsheet`](super::spreadsheet)): quoted, with a leading `'` when they begin
//! like a formula.

use std::path::Path;

use super::record::{Value, PROPERTIES};
use super::spreadsheet::{spreadsheet_safe, writer};
use super::{write_file_atomically, ExportError, ExportSummary, SegmentExport};

/// The CSV text of `records`.
pub fn to_bytes(records: &[SegmentExport]) -> Result<Vec<u8>, csv::Error> {
    let mut w = writer(Vec::new());
    w.write_record(PROPERTIES.iter().map(|p| p.name))?;
    let mut row: Vec<String> = Vec::with_capacity(PROPERTIES.len());
    for rec in records {
        row.clear();
        row.extend(PROPERTIES.iter().map(|p| match (p.get)(rec) {
            Value::Null => String::new(),
            Value::Text(s) => spreadsheet_safe(s).into_owned(),
            Value::Real(x) => x.to_string(),
            Value::Integer(i) => i.to_string(),
        }));
        w.write_record(&row)?;
    }
    w.into_inner().map_err(|e| csv::Error::from(e.into_error()))
}

/// Write the CSV of `records` to `out`.
pub fn write(records: &[SegmentExport], out: &Path) -> Result<ExportSummary, ExportError> {
    let bytes = to_bytes(records).map_err(|e| ExportError::Encode {
        path: out.to_path_buf(),
        message: e.to_string(),
    })?;
    write_file_atomically(out, &bytes)?;
    Ok(ExportSummary {
        segments: records.len(),
        with_geometry: 0,
        fitted: records.iter().filter(|r| r.fit.is_some()).count(),
        warnings: Vec::new(),
    })
}
