//! Reading an import CSV into checked header + rows of trimmed text, and parsing cells, with every
//! problem reported as a [`RowError`] naming file, line and column.

use std::collections::HashMap;

use super::{ColumnRef, ImportSource, RowError};
use crate::physics::inputs::check_range;

/// A column an import file may have.
#[derive(Debug, Clone, Copy)]
pub(super) struct ColumnSpec {
    /// Canonical (lower-case) name, as in docs/interface.md.
    pub name: &'static str,
    /// Must the header have it?
    pub required: bool,
}

/// One data row: its line (where the record starts) and its trimmed cells, one per header column.
#[derive(Debug)]
pub(super) struct RawRow {
    pub line: u64,
    pub cells: Vec<String>,
}

/// A file whose header is good: known columns, each once, all required ones present.
#[derive(Debug)]
pub(super) struct Table {
    pub file: String,
    /// Canonical name of each known column -> its 0-based field index.
    index: HashMap<&'static str, usize>,
    pub rows: Vec<RawRow>,
}

/// The outcome of reading a file: the table if its header was usable, and every problem found.
/// `fatal` is set when the file as a whole is unusable (empty, bad header): then no row of it
/// may be imported, even with `skip_invalid`.
#[derive(Debug)]
pub(super) struct ReadOutcome {
    pub table: Option<Table>,
    pub errors: Vec<RowError>,
    pub fatal: bool,
}

const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

impl Table {
    /// Read and check `source` against `specs`.
    pub fn read(source: &ImportSource, specs: &[ColumnSpec]) -> ReadOutcome {
        let file = source.name.clone();
        let mut errors = Vec::new();
        let fail = |errors: Vec<RowError>| ReadOutcome {
            table: None,
            errors,
            fatal: true,
        };
        let data = source.data.strip_prefix(UTF8_BOM).unwrap_or(&source.data);
        if data.iter().all(u8::is_ascii_whitespace) {
            errors.push(RowError::new(
                &file,
                1,
                None,
                format!(
                    "the file is empty; expected a header line naming the columns, such as: {}",
                    required_names(specs)
                ),
            ));
            return fail(errors);
        }
        let mut rdr = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .from_reader(data);
        let mut records = rdr.byte_records();

        // Header.
        let header = match records.next() {
            Some(Ok(h)) => h,
            Some(Err(e)) => {
                errors.push(csv_error(&file, &e));
                return fail(errors);
            }
            None => {
                errors.push(RowError::new(&file, 1, None, "the file has no header line"));
                return fail(errors);
            }
        };
        let header_line = header.position().map_or(1, |p| p.line());
        let mut index: HashMap<&'static str, usize> = HashMap::new();
        for (i, raw) in header.iter().enumerate() {
            let Ok(name) = std::str::from_utf8(raw) else {
                errors.push(RowError::new(
                    &file,
                    header_line,
                    Some(ColumnRef::new(i, &String::from_utf8_lossy(raw))),
                    "the column name is not valid UTF-8 text; save the file as UTF-8",
                ));
                continue;
            };
            let name = name.trim();
            let col = Some(ColumnRef::new(i, name));
            if name.is_empty() {
                errors.push(RowError::new(
                    &file,
                    header_line,
                    col,
                    "this column has no name (a stray separator at the end of the header?)",
                ));
                continue;
            }
            match specs.iter().find(|s| s.name.eq_ignore_ascii_case(name)) {
                None => errors.push(RowError::new(
                    &file,
                    header_line,
                    col,
                    unknown_column_message(name, specs),
                )),
                Some(spec) => {
                    if let Some(&first) = index.get(spec.name) {
                        errors.push(RowError::new(
                            &file,
                            header_line,
                            Some(ColumnRef::new(i, spec.name)),
                            format!(
                                "duplicate column: '{}' is also column {}",
                                spec.name,
                                first + 1
                            ),
                        ));
                    } else {
                        index.insert(spec.name, i);
                    }
                }
            }
        }
        for spec in specs.iter().filter(|s| s.required) {
            if !index.contains_key(spec.name) {
                errors.push(RowError::new(
                    &file,
                    header_line,
                    None,
                    format!("missing required column '{}'", spec.name),
                ));
            }
        }
        if !errors.is_empty() {
            return fail(errors);
        }

        // Rows.
        let width = header.len();
        let mut rows = Vec::new();
        let mut n_records = 0usize;
        for rec in records {
            let rec = match rec {
                Ok(r) => r,
                Err(e) => {
                    errors.push(csv_error(&file, &e));
                    n_records += 1;
                    continue;
                }
            };
            n_records += 1;
            let line = rec.position().map_or(0, |p| p.line());
            if rec.len() != width {
                // Point at the first missing cell, or at the row when there are extra ones.
                let col = (rec.len() < width).then(|| {
                    let name = name_of(&index, rec.len()).unwrap_or("?");
                    ColumnRef::new(rec.len(), name)
                });
                errors.push(RowError::new(
                    &file,
                    line,
                    col,
                    format!(
                        "the row has {} values but the header has {width} columns",
                        rec.len()
                    ),
                ));
                continue;
            }
            let mut cells = Vec::with_capacity(width);
            let mut bad = false;
            for (i, raw) in rec.iter().enumerate() {
                match std::str::from_utf8(raw) {
                    Ok(s) => cells.push(s.trim().to_string()),
                    Err(_) => {
                        errors.push(RowError::new(
                            &file,
                            line,
                            Some(ColumnRef::new(i, name_of(&index, i).unwrap_or("?"))),
                            "the value is not valid UTF-8 text; save the file as UTF-8",
                        ));
                        bad = true;
                        break;
                    }
                }
            }
            if !bad {
                rows.push(RawRow { line, cells });
            }
        }
        if n_records == 0 {
            errors.push(RowError::new(
                &file,
                header_line + 1,
                None,
                "the file has a header but no data rows",
            ));
            return fail(errors);
        }
        ReadOutcome {
            table: Some(Table { file, index, rows }),
            errors,
            fatal: false,
        }
    }

    /// Does the header have this column?
    pub fn has(&self, name: &str) -> bool {
        self.index.contains_key(name)
    }

    /// The 0-based field index of a known column.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.index.get(name).copied()
    }

    /// A checker for one row.
    pub fn check<'t>(&'t self, row: &'t RawRow) -> RowCheck<'t> {
        RowCheck {
            table: self,
            row,
            errors: Vec::new(),
        }
    }
}

/// The canonical name of the column at field index `i`.
fn name_of(index: &HashMap<&'static str, usize>, i: usize) -> Option<&'static str> {
    index.iter().find(|(_, &j)| j == i).map(|(n, _)| *n)
}

fn required_names(specs: &[ColumnSpec]) -> String {
    specs
        .iter()
        .filter(|s| s.required)
        .map(|s| s.name)
        .collect::<Vec<_>>()
        .join(",")
}

fn unknown_column_message(name: &str, specs: &[ColumnSpec]) -> String {
    let lower = name.to_ascii_lowercase();
    let closest = specs
        .iter()
        .map(|s| (edit_distance(&lower, s.name), s.name))
        .min();
    let hint = match closest {
        // A few typos away: name it.
        Some((d, n)) if d <= 3 => format!(" (did you mean '{n}'?)"),
        _ => String::new(),
    };
    let allowed: Vec<&str> = specs.iter().map(|s| s.name).collect();
    format!(
        "unknown column '{name}'{hint}; the allowed columns are: {}",
        allowed.join(", ")
    )
}

/// Levenshtein distance, for the "did you mean" hint.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, &cb) in b.iter().enumerate() {
            let subst = prev[j] + usize::from(ca != cb);
            cur[j + 1] = subst.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

fn csv_error(file: &str, e: &csv::Error) -> RowError {
    let line = e.position().map_or(0, |p| p.line());
    RowError::new(
        file,
        line,
        None,
        format!("the CSV cannot be read here: {e}"),
    )
}

/// The checker of one row: reads cells by column name, parses them, and collects every problem.
pub(super) struct RowCheck<'t> {
    table: &'t Table,
    row: &'t RawRow,
    pub errors: Vec<RowError>,
}

impl<'t> RowCheck<'t> {
    /// Does the header have this column?
    pub fn has(&self, col: &str) -> bool {
        self.table.has(col)
    }

    /// Record a problem with column `col`.
    pub fn err(&mut self, col: &'static str, message: impl Into<String>) {
        let column = self.table.index.get(col).map(|&i| ColumnRef::new(i, col));
        self.errors.push(RowError::new(
            &self.table.file,
            self.row.line,
            column,
            message,
        ));
    }

    /// The trimmed text of a cell; `None` when the column is absent or the cell blank.
    pub fn text(&self, col: &'static str) -> Option<&'t str> {
        let i = *self.table.index.get(col)?;
        let s = self.row.cells.get(i)?.as_str();
        (!s.is_empty()).then_some(s)
    }

    /// A required text.
    pub fn required_text(&mut self, col: &'static str) -> Option<&'t str> {
        let t = self.text(col);
        if t.is_none() {
            self.err(col, "a value is required here, the cell is blank");
        }
        t
    }

    /// An optional number (blank: `None`). Rejects text, NaN and infinities; `-0` reads as 0.
    pub fn number(&mut self, col: &'static str) -> Option<f64> {
        let t = self.text(col)?;
        match t.parse::<f64>() {
            Ok(v) if v.is_finite() => Some(if v == 0.0 { 0.0 } else { v }),
            Ok(_) => {
                self.err(col, format!("'{t}' is not a finite number"));
                None
            }
            Err(_) => {
                self.err(col, format!("expected a number, found '{t}'"));
                None
            }
        }
    }

    /// A required number.
    pub fn required_number(&mut self, col: &'static str) -> Option<f64> {
        if self.text(col).is_none() {
            self.err(col, "a number is required here, the cell is blank");
            return None;
        }
        self.number(col)
    }

    /// An optional whole number.
    pub fn integer(&mut self, col: &'static str) -> Option<i64> {
        let t = self.text(col)?;
        match t.parse::<i64>() {
            Ok(v) => Some(v),
            Err(_) => {
                self.err(col, format!("expected a whole number, found '{t}'"));
                None
            }
        }
    }

    /// Keep `v` only if it is > 0.
    pub fn positive(&mut self, col: &'static str, v: Option<f64>, unit: &str) -> Option<f64> {
        let v = v?;
        if v > 0.0 {
            Some(v)
        } else {
            self.err(col, format!("must be greater than 0{unit}, got {v}"));
            None
        }
    }

    /// Keep `v` only if it is within `[lo, hi]` (spec §3.1 ranges).
    pub fn in_range(
        &mut self,
        col: &'static str,
        v: Option<f64>,
        (name, lo, hi, range): (&'static str, f64, f64, &'static str),
    ) -> Option<f64> {
        let v = v?;
        match check_range(name, v, lo, hi, range) {
            Ok(v) => Some(v),
            Err(e) => {
                self.err(col, e.to_string());
                None
            }
        }
    }

    /// An optional ISO date `YYYY-MM-DD` (a real calendar date).
    pub fn date(&mut self, col: &'static str) -> Option<String> {
        let t = self.text(col)?;
        if is_iso_date(t) {
            Some(t.to_string())
        } else {
            self.err(
                col,
                format!("expected a date written YYYY-MM-DD (such as 2024-05-31), found '{t}'"),
            );
            None
        }
    }

    /// An optional free text.
    pub fn owned_text(&self, col: &'static str) -> Option<String> {
        self.text(col).map(str::to_string)
    }
}

/// Is `t` a valid calendar date written `YYYY-MM-DD`?
pub(super) fn is_iso_date(t: &str) -> bool {
    let b = t.as_bytes();
    if b.len() != 10 || b[4] != b'-' || b[7] != b'-' {
        return false;
    }
    let digits = |r: std::ops::Range<usize>| -> Option<u32> {
        let s = t.get(r)?;
        if s.bytes().all(|c| c.is_ascii_digit()) {
            s.parse().ok()
        } else {
            None
        }
    };
    let (Some(y), Some(m), Some(d)) = (digits(0..4), digits(5..7), digits(8..10)) else {
        return false;
    };
    let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    let days = match m {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if leap => 29,
        2 => 28,
        _ => return false,
    };
    (1..=days).contains(&d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso_dates_are_checked_against_the_calendar() {
        for ok in ["2024-02-29", "2000-02-29", "1999-12-31", "2023-01-01"] {
            assert!(is_iso_date(ok), "{ok}");
        }
        for bad in [
            "2023-02-29",
            "1900-02-29",
            "2024-13-01",
            "2024-00-10",
            "2024-04-31",
            "24-04-30",
            "2024/04/30",
            "2024-4-30",
            "2024-04-3x",
            "2024-04-30T10:00",
            "+024-04-30",
            "éééé-04-30",
        ] {
            assert!(!is_iso_date(bad), "{bad}");
        }
    }

    #[test]
    fn edit_distance_for_hints() {
        assert_eq!(edit_distance("outer_diamter_mm", "outer_diameter_mm"), 1);
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(edit_distance("abc", "abc"), 0);
    }
}
