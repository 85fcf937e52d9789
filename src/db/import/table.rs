//! Reading an import CSV into checked header + rows of trimmed text, and parsing cells, with every
//! problem reported as a [`RowError`] naming file, line and column.

use std::cell::RefCell;
use std::collections::{HashMap, VecDeque};
use std::io::{Cursor, Read};
use std::rc::Rc;

use super::{ColumnRef, ImportOptions, ImportSource, RowError, SourceKind};
use crate::physics::inputs::ValidRange;
use crate::units::short;

/// A column an import file may have.
#[derive(Debug, Clone, Copy)]
pub(super) struct ColumnSpec {
    /// Canonical (lower-case) name, as in docs/interface.md.
    pub name: &'static str,
    /// Must the header have it?
    pub required: bool,
}

/// One data row: its line (where the record starts; for a layer, the feature id) and its
/// trimmed cells, one per header column. `errors` holds problems the reader already found in
/// the row (a layer's geometry): the row is invalid whatever its cells say.
#[derive(Debug, Default)]
pub(super) struct RawRow {
    pub line: u64,
    pub cells: Vec<String>,
    pub errors: Vec<RowError>,
    /// Cells whose text is not UTF-8 in a GIS layer (read as blank): an error in the columns
    /// pipewave uses, nothing in the others.
    pub not_utf8: Vec<usize>,
}

/// The data rows of a file, handed out one at a time.
pub(super) enum Rows {
    /// Rows read whole (a GIS layer's features).
    Loaded(std::vec::IntoIter<RawRow>),
    /// A CSV, read a record at a time: a file is never whole in memory.
    Csv(Box<CsvRows>),
}

impl Default for Rows {
    fn default() -> Self {
        Rows::Loaded(Vec::new().into_iter())
    }
}

impl std::fmt::Debug for Rows {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Rows::Loaded(rows) => write!(f, "Rows::Loaded({} rows)", rows.len()),
            Rows::Csv(c) => write!(f, "Rows::Csv({})", c.file),
        }
    }
}

impl Iterator for Rows {
    /// A row, or a problem with a record that makes it no row (wrong number of cells, bytes that
    /// are not UTF-8, a record the CSV reader cannot read).
    type Item = Result<RawRow, RowError>;

    fn next(&mut self) -> Option<Self::Item> {
        match self {
            Rows::Loaded(rows) => rows.next().map(Ok),
            Rows::Csv(c) => c.next_row(),
        }
    }
}

/// The records of a CSV after its header.
pub(super) struct CsvRows {
    file: String,
    /// The header's names, for messages.
    names: Vec<String>,
    /// The first record, read ahead to tell a file without data rows.
    first: Option<Result<csv::ByteRecord, csv::Error>>,
    records: csv::ByteRecordsIntoIter<Tracked<Box<dyn Read>>>,
    /// The line breaks read so far, to place each record on its line.
    lines: Rc<RefCell<LineBreaks>>,
}

impl CsvRows {
    fn next_row(&mut self) -> Option<Result<RawRow, RowError>> {
        let rec = match self.first.take() {
            Some(r) => r,
            None => self.records.next()?,
        };
        let line = |pos: Option<&csv::Position>| {
            pos.map_or(0, |p| self.lines.borrow_mut().line_at(p.byte()))
        };
        Some(match rec {
            Ok(rec) => self.row(&rec, line(rec.position())),
            Err(e) => Err(csv_error(&self.file, line(e.position()), &e)),
        })
    }

    /// One record as a row of trimmed cells.
    fn row(&self, rec: &csv::ByteRecord, line: u64) -> Result<RawRow, RowError> {
        let file = &self.file;
        let width = self.names.len();
        let name = |i: usize| self.names.get(i).map_or("?", String::as_str).to_string();
        if rec.len() != width {
            // Point at the first missing cell, or at the row when there are extra ones.
            let col = (rec.len() < width).then(|| ColumnRef::new(rec.len(), &name(rec.len())));
            return Err(RowError::new(
                file,
                line,
                col,
                format!(
                    "the row has {} values but the header has {width} columns",
                    rec.len()
                ),
            ));
        }
        let mut cells = Vec::with_capacity(width);
        for (i, raw) in rec.iter().enumerate() {
            match std::str::from_utf8(raw) {
                // Our own CSV output neutralises formula-like text with a `'`:
                // read it back as written.
                Ok(s) => cells.push(crate::spreadsheet::unneutralise(s.trim()).to_string()),
                Err(_) => {
                    return Err(RowError::new(
                        file,
                        line,
                        Some(ColumnRef::new(i, &name(i))),
                        "the value is not valid UTF-8 text; save the file as UTF-8",
                    ));
                }
            }
        }
        Ok(RawRow {
            line,
            cells,
            errors: Vec::new(),
            not_utf8: Vec::new(),
        })
    }
}

/// The line breaks a CSV reader has been given, so that each record can be placed on the line
/// where it starts. The `csv` crate counts only LF bytes, and a record's position is where the
/// reader resumed (on the previous record's terminator or a blank line before it), so with CRLF
/// endings it reports the line before, and with CR-only endings always line 1. Here a CR, an LF
/// and a CRLF each end one line, and a record's line is that of its first byte.
#[derive(Debug, Default)]
struct LineBreaks {
    /// Runs of consecutive CR/LF bytes not yet passed by a record: (offset of the run's first
    /// byte, line breaks in it). The last one may still be growing.
    runs: VecDeque<(u64, u64)>,
    /// Line breaks in the runs already passed.
    passed: u64,
    /// Offset of the next byte.
    offset: u64,
    /// The previous byte was a CR: an LF now ends the same line.
    after_cr: bool,
    /// The previous byte was a CR or an LF: the last run is open.
    in_run: bool,
}

impl LineBreaks {
    fn scan(&mut self, bytes: &[u8]) {
        for &b in bytes {
            if b == b'\r' || b == b'\n' {
                if !self.in_run {
                    self.runs.push_back((self.offset, 0));
                    self.in_run = true;
                }
                let ends_line = b == b'\r' || !self.after_cr;
                if let (true, Some(run)) = (ends_line, self.runs.back_mut()) {
                    run.1 += 1;
                }
                self.after_cr = b == b'\r';
            } else {
                self.in_run = false;
                self.after_cr = false;
            }
            self.offset += 1;
        }
    }

    /// The 1-based line of a record the reader placed at `byte`. A record's first byte is the
    /// first one at or after `byte` that is not a CR or an LF, so a run of breaks that starts
    /// at or before `byte` lies before the record. Queries come in increasing order.
    fn line_at(&mut self, byte: u64) -> u64 {
        while let Some(&(start, n)) = self.runs.front() {
            if start > byte {
                break;
            }
            self.passed += n;
            self.runs.pop_front();
        }
        1 + self.passed
    }
}

/// A reader that shows every byte it hands out to a [`LineBreaks`].
struct Tracked<R> {
    inner: R,
    breaks: Rc<RefCell<LineBreaks>>,
}

impl<R: Read> Read for Tracked<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.breaks.borrow_mut().scan(&buf[..n]);
        Ok(n)
    }
}

/// A file as read, before its header is checked: a CSV, or a GIS layer whose attributes and
/// geometry (as `geometry_wkt` and `srid` cells) were turned into text cells.
#[derive(Debug, Default)]
pub(super) struct RawTable {
    pub file: String,
    /// The layer, for a GIS layer: messages then name the layer, feature and field.
    pub layer: Option<String>,
    /// Line of the header (0 for a layer: its problems are the layer's).
    pub header_line: u64,
    /// The column or field names, as written.
    pub header: Vec<String>,
    pub rows: Rows,
}

/// How to match a header against the known columns.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct HeaderOptions<'a> {
    /// `(pipewave column, the file's field)` pairs of `--map COLUMN=FIELD`.
    pub map: &'a [(String, String)],
    /// Reject unknown columns instead of ignoring them with a note.
    pub strict: bool,
}

/// A file whose header is good: known columns, each once, all required ones present.
#[derive(Debug)]
pub(super) struct Table {
    pub file: String,
    /// The layer, for a GIS layer.
    pub layer: Option<String>,
    /// Canonical name of each known column -> its 0-based field index.
    index: HashMap<&'static str, usize>,
    /// Canonical name -> the name to show in messages (`DIAM_MM (outer_diameter_mm)` when the
    /// file's field is mapped or named otherwise).
    labels: HashMap<&'static str, String>,
    /// The data rows, taken once ([`Table::take_rows`]).
    rows: Rows,
}

/// The outcome of reading a file: the table if its header was usable, and every problem found.
/// `fatal` is set when the file as a whole is unusable (empty, bad header): then no row of it
/// may be imported, even with `skip_invalid`. `notes` are things to tell the user that reject
/// nothing (ignored columns).
#[derive(Debug, Default)]
pub(super) struct ReadOutcome {
    pub table: Option<Table>,
    pub errors: Vec<RowError>,
    pub fatal: bool,
    pub notes: Vec<String>,
}

const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// A RowError in `raw`'s file and layer.
fn raw_error(
    raw: &RawTable,
    line: u64,
    column: Option<ColumnRef>,
    msg: impl Into<String>,
) -> RowError {
    let mut e = RowError::new(&raw.file, line, column, msg);
    e.layer.clone_from(&raw.layer);
    e
}

impl Table {
    /// Read and check `source` against `specs`: a CSV, or the GIS layer it holds.
    pub fn read(
        source: &ImportSource,
        specs: &[ColumnSpec],
        options: &ImportOptions,
    ) -> ReadOutcome {
        let raw = match &source.kind {
            SourceKind::Csv => read_csv(
                &source.name,
                Box::new(Cursor::new(source.data.clone())),
                specs,
            ),
            SourceKind::CsvFile(path) => match std::fs::File::open(path) {
                Ok(f) => read_csv(&source.name, Box::new(std::io::BufReader::new(f)), specs),
                Err(e) => Err(vec![RowError::new(
                    &source.name,
                    0,
                    None,
                    format!("the file cannot be read: {e}"),
                )]),
            },
            _ => super::layer::read(source, options.layer.as_deref(), options.srid),
        };
        let (raw, mut errors) = match raw {
            Ok(r) => r,
            Err(errors) => {
                return ReadOutcome {
                    errors,
                    fatal: true,
                    ..ReadOutcome::default()
                }
            }
        };
        let header = HeaderOptions {
            map: &options.map,
            strict: options.strict,
        };
        let mut out = Table::from_raw(raw, specs, header);
        errors.append(&mut out.errors);
        out.errors = errors;
        out
    }

    /// Check the header of `raw` against `specs` (with the `--map` pairs and strictness).
    pub fn from_raw(
        raw: RawTable,
        specs: &[ColumnSpec],
        options: HeaderOptions<'_>,
    ) -> ReadOutcome {
        let mut errors = Vec::new();
        let mut index: HashMap<&'static str, usize> = HashMap::new();
        let mut labels: HashMap<&'static str, String> = HashMap::new();
        let mut unknown: Vec<(usize, String)> = Vec::new();
        let what = if raw.layer.is_some() {
            "field"
        } else {
            "column"
        };
        for (i, name) in raw.header.iter().enumerate() {
            let name = name.trim();
            let col = Some(ColumnRef::new(i, name));
            if name.is_empty() {
                errors.push(raw_error(
                    &raw,
                    raw.header_line,
                    col,
                    format!(
                        "this {what} has no name (a stray separator at the end of the header?)"
                    ),
                ));
                continue;
            }
            // A mapped field takes the column it is mapped to; a column mapped to another field
            // is not matched by its own name.
            let mapped = options
                .map
                .iter()
                .find(|(_, field)| field.trim().eq_ignore_ascii_case(name))
                .and_then(|(c, _)| specs.iter().find(|s| s.name.eq_ignore_ascii_case(c.trim())));
            let in_header = |f: &str| {
                raw.header
                    .iter()
                    .any(|h| h.trim().eq_ignore_ascii_case(f.trim()))
            };
            let direct = specs.iter().find(|s| {
                s.name.eq_ignore_ascii_case(name)
                    && !options.map.iter().any(|(c, f)| {
                        c.trim().eq_ignore_ascii_case(s.name)
                            && !f.trim().eq_ignore_ascii_case(name)
                            && in_header(f)
                    })
            });
            let Some(spec) = mapped.or(direct) else {
                // A field mapped to a column of the other file is not unknown there.
                if !options
                    .map
                    .iter()
                    .any(|(_, f)| f.trim().eq_ignore_ascii_case(name))
                {
                    unknown.push((i, name.to_string()));
                }
                continue;
            };
            if let Some(&first) = index.get(spec.name) {
                errors.push(raw_error(
                    &raw,
                    raw.header_line,
                    Some(ColumnRef::new(i, spec.name)),
                    format!(
                        "duplicate {what}: '{}' is also {what} {} ({})",
                        spec.name,
                        first + 1,
                        raw.header[first].trim()
                    ),
                ));
            } else {
                index.insert(spec.name, i);
                let label = if name == spec.name {
                    spec.name.to_string()
                } else if name.eq_ignore_ascii_case(spec.name) {
                    name.to_string()
                } else {
                    format!("{name} ({})", spec.name)
                };
                labels.insert(spec.name, label);
            }
        }
        let mut notes = Vec::new();
        if options.strict {
            for (i, name) in &unknown {
                errors.push(raw_error(
                    &raw,
                    raw.header_line,
                    Some(ColumnRef::new(*i, name)),
                    unknown_column_message(name, specs),
                ));
            }
        } else if !unknown.is_empty() {
            let names: Vec<&str> = unknown.iter().map(|(_, n)| n.as_str()).collect();
            let place = match &raw.layer {
                Some(l) => format!("{}: layer {l}", raw.file),
                None => raw.file.clone(),
            };
            notes.push(format!(
                "{place}: ignored {} {what}{} pipewave does not use: {} (--map COLUMN=FIELD uses \
                 one; --strict rejects them)",
                names.len(),
                if names.len() == 1 { "" } else { "s" },
                names.join(", ")
            ));
        }
        for spec in specs.iter().filter(|s| s.required) {
            if !index.contains_key(spec.name) {
                let lower = spec.name.to_ascii_lowercase();
                let near = unknown
                    .iter()
                    .map(|(_, n)| (edit_distance(&n.to_ascii_lowercase(), &lower), n))
                    .filter(|(d, _)| *d <= 3)
                    .min();
                let hint = match near {
                    Some((_, n)) => {
                        format!(" (the file has '{n}': a typo? or --map {}={n})", spec.name)
                    }
                    None => format!(
                        "; if the file names it otherwise, use --map {}=FIELD",
                        spec.name
                    ),
                };
                errors.push(raw_error(
                    &raw,
                    raw.header_line,
                    None,
                    format!("missing required {what} '{}'{hint}", spec.name),
                ));
            }
        }
        if !errors.is_empty() {
            return ReadOutcome {
                errors,
                fatal: true,
                notes,
                ..ReadOutcome::default()
            };
        }
        if raw.layer.is_some() && matches!(&raw.rows, Rows::Loaded(r) if r.len() == 0) {
            errors.push(raw_error(
                &raw,
                raw.header_line + 1,
                None,
                "the layer has no features",
            ));
            return ReadOutcome {
                errors,
                fatal: true,
                notes,
                ..ReadOutcome::default()
            };
        }
        ReadOutcome {
            table: Some(Table {
                file: raw.file,
                layer: raw.layer,
                index,
                labels,
                rows: raw.rows,
            }),
            errors,
            fatal: false,
            notes,
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

    /// The data rows, in file order (taken once; empty after).
    pub fn take_rows(&mut self) -> Rows {
        std::mem::take(&mut self.rows)
    }

    /// A problem with column `col` of the row at `line` (a feature id in a layer).
    pub fn error(&self, line: u64, col: &'static str, message: impl Into<String>) -> RowError {
        let column = self.index.get(col).map(|&i| {
            let label = self.labels.get(col).map_or(col, String::as_str);
            ColumnRef::new(i, label)
        });
        let mut e = RowError::new(&self.file, line, column, message);
        e.layer.clone_from(&self.layer);
        e
    }

    /// A checker for one row.
    pub fn check<'t>(&'t self, row: &'t RawRow) -> RowCheck<'t> {
        let mut errors = row.errors.clone();
        for (&col, &i) in &self.index {
            if row.not_utf8.contains(&i) {
                errors.push(self.error(
                    row.line,
                    col,
                    "not UTF-8 text; save the layer with the UTF-8 encoding",
                ));
            }
        }
        errors.sort_by(|a, b| a.column.cmp(&b.column));
        RowCheck {
            table: self,
            row,
            errors,
        }
    }
}

/// The input without a leading UTF-8 byte-order mark, or `None` when it holds nothing but
/// whitespace. Reads ahead only the leading whitespace.
fn content(mut input: Box<dyn Read>) -> std::io::Result<Option<Box<dyn Read>>> {
    let mut head = Vec::new();
    (&mut input)
        .take(UTF8_BOM.len() as u64)
        .read_to_end(&mut head)?;
    if head == UTF8_BOM {
        head.clear();
    }
    let mut checked = 0;
    while head[checked..].iter().all(u8::is_ascii_whitespace) {
        checked = head.len();
        if (&mut input).take(4096).read_to_end(&mut head)? == 0 {
            return Ok(None);
        }
    }
    Ok(Some(Box::new(Cursor::new(head).chain(input))))
}

/// Read a CSV's header into a [`RawTable`] whose rows are read as they are taken, or the
/// errors that make the file unusable. The first record is read ahead, to tell a file without
/// data rows.
#[allow(clippy::type_complexity)]
fn read_csv(
    file: &str,
    input: Box<dyn Read>,
    specs: &[ColumnSpec],
) -> Result<(RawTable, Vec<RowError>), Vec<RowError>> {
    let file = file.to_string();
    let mut errors = Vec::new();
    let data = match content(input) {
        Ok(Some(data)) => data,
        Ok(None) => {
            return Err(vec![RowError::new(
                &file,
                1,
                None,
                format!(
                    "the file is empty; expected a header line naming the columns, such as: {}",
                    required_names(specs)
                ),
            )])
        }
        Err(e) => {
            return Err(vec![RowError::new(
                &file,
                0,
                None,
                format!("the file cannot be read: {e}"),
            )])
        }
    };
    let lines = Rc::new(RefCell::new(LineBreaks::default()));
    let rdr = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(Tracked {
            inner: data,
            breaks: Rc::clone(&lines),
        });
    let mut records = rdr.into_byte_records();
    let line_of =
        |pos: Option<&csv::Position>| pos.map_or(0, |p| lines.borrow_mut().line_at(p.byte()));
    let header = match records.next() {
        Some(Ok(h)) => h,
        Some(Err(e)) => return Err(vec![csv_error(&file, line_of(e.position()), &e)]),
        None => {
            return Err(vec![RowError::new(
                &file,
                1,
                None,
                "the file has no header line",
            )])
        }
    };
    let header_line = line_of(header.position()).max(1);
    let mut names = Vec::with_capacity(header.len());
    for (i, raw) in header.iter().enumerate() {
        match std::str::from_utf8(raw) {
            Ok(n) => names.push(n.trim().to_string()),
            Err(_) => {
                errors.push(RowError::new(
                    &file,
                    header_line,
                    Some(ColumnRef::new(i, &String::from_utf8_lossy(raw))),
                    "the column name is not valid UTF-8 text; save the file as UTF-8",
                ));
                names.push(String::from_utf8_lossy(raw).trim().to_string());
            }
        }
    }
    if !errors.is_empty() {
        return Err(errors);
    }
    let Some(first) = records.next() else {
        return Err(vec![RowError::new(
            &file,
            header_line + 1,
            None,
            "the file has a header but no data rows",
        )]);
    };
    let rows = Rows::Csv(Box::new(CsvRows {
        file: file.clone(),
        names: names.clone(),
        first: Some(first),
        records,
        lines,
    }));
    Ok((
        RawTable {
            file,
            layer: None,
            header_line,
            header: names,
            rows,
        },
        errors,
    ))
}

/// The header an empty file's message suggests: the required columns and, of the frequency
/// columns (the header needs one of `frequency_hz` and `omega_rad_s`), `frequency_hz`, in the
/// order of `specs`.
fn required_names(specs: &[ColumnSpec]) -> String {
    specs
        .iter()
        .filter(|s| s.required || s.name == "frequency_hz")
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

fn csv_error(file: &str, line: u64, e: &csv::Error) -> RowError {
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
        let e = self.table.error(self.row.line, col, message);
        self.errors.push(e);
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
            self.err(
                col,
                format!("must be greater than 0{unit}, got {}", short(v)),
            );
            None
        }
    }

    /// Keep `v` only if it is within `range` (model §3.1 ranges).
    pub fn in_range(
        &mut self,
        col: &'static str,
        v: Option<f64>,
        range: ValidRange,
    ) -> Option<f64> {
        let v = v?;
        match range.check(v) {
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
