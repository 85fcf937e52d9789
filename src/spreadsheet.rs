//! CSV files that are safe to open in a spreadsheet.
//!
//! Excel, LibreOffice Calc and Google Sheets read a cell that begins with `=`, `+`, `-`, `@`, a
//! tab or a carriage return as a formula ("CSV injection", OWASP). A segment id of
//! `=HYPERLINK("http://x")` in the inventory would become a live link in the export. OWASP's
//! remedy, applied to every CSV pipewave writes:
//!
//! - a **text** cell that begins with one of [`FORMULA_LEADS`] gets a leading `'`
//!   ([`spreadsheet_safe`], or [`SafeText`] for serde rows); spreadsheets show the text as typed
//!   and hide the `'`;
//! - the writer ([`writer`], [`writer_from_path`]) quotes every cell that is not a number
//!   ([`csv::QuoteStyle::NonNumeric`]), so the neutralised cell is quoted;
//! - **numeric** cells are written as they are and never passed through [`spreadsheet_safe`]:
//!   `-0.5` in a number column stays `-0.5`, unquoted, and reads as a number.
//!
//! The neutralisation is visible to programs that read the file: an id `+1` reads back as `'+1`.

use crate::outfile::{Contents, OutFile};
use std::borrow::Cow;
use std::io;
use std::path::Path;

/// First characters that make a spreadsheet read a cell as a formula (OWASP "CSV Injection").
pub const FORMULA_LEADS: [char; 6] = ['=', '+', '-', '@', '\t', '\r'];

/// The prefix that makes a spreadsheet take a cell as text.
pub const TEXT_PREFIX: char = '\'';

/// A text cell made safe to open in a spreadsheet: `s` with a leading `'` when it begins with one
/// of [`FORMULA_LEADS`], otherwise `s` unchanged (borrowed). For text cells only: a number
/// column is written as it is.
///
/// ```
/// use pipewave::spreadsheet::spreadsheet_safe;
/// assert_eq!(spreadsheet_safe("=HYPERLINK(\"http://x\")"), "'=HYPERLINK(\"http://x\")");
/// assert_eq!(spreadsheet_safe("HYD-1003"), "HYD-1003");
/// ```
pub fn spreadsheet_safe(s: &str) -> Cow<'_, str> {
    if needs_prefix(s) {
        let mut t = String::with_capacity(s.len() + 1);
        t.push(TEXT_PREFIX);
        t.push_str(s);
        Cow::Owned(t)
    } else {
        Cow::Borrowed(s)
    }
}

/// A text cell on one line: the lines of `s` (split at `\n`, `\r\n` or `\r`, blank ones
/// dropped) joined with `; `, so that a list in one cell neither breaks a row for `head` or
/// `grep` nor opens as a tall cell in a spreadsheet; `s` itself (borrowed) when it is one line.
///
/// ```
/// use pipewave::spreadsheet::one_line;
/// assert_eq!(one_line("high_misfit: chi2 40\nspeed_uncertain: 3 %\n"), "high_misfit: chi2 40; speed_uncertain: 3 %");
/// assert_eq!(one_line("one line"), "one line");
/// ```
pub fn one_line(s: &str) -> Cow<'_, str> {
    if !s.contains(['\n', '\r']) {
        return Cow::Borrowed(s);
    }
    let parts: Vec<&str> = s
        .split(['\n', '\r'])
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect();
    Cow::Owned(parts.join("; "))
}

/// The inverse of [`spreadsheet_safe`], as a spreadsheet reads the cell: a leading `'` that
/// is followed by one of [`FORMULA_LEADS`] is dropped; any other text is returned unchanged. The
/// CSV import reads every cell through this, so pipewave's own CSV output (e.g. the
/// `wavenumbers` measurements of a segment id `+1`, written `'+1`) imports as the id it was
/// written for. A spreadsheet saving such a cell writes it without the `'` too. Text that
/// itself begins with `'` and a formula lead is written with one more `'` (`'=1` as `''=1`,
/// which a spreadsheet shows as `'=1`), so it survives the round trip as well.
///
/// ```
/// use pipewave::spreadsheet::{spreadsheet_safe, unneutralise};
/// assert_eq!(unneutralise(&spreadsheet_safe("+1")), "+1");
/// assert_eq!(unneutralise("'quoted'"), "'quoted'");
/// assert_eq!(unneutralise(&spreadsheet_safe("'-")), "'-");
/// ```
pub fn unneutralise(s: &str) -> &str {
    match s.strip_prefix(TEXT_PREFIX) {
        Some(rest) if needs_prefix(rest) => rest,
        _ => s,
    }
}

/// Whether [`spreadsheet_safe`] prefixes `s`: it begins, after any run of `'`, with one of
/// [`FORMULA_LEADS`]. Text that itself begins with `'` and a formula lead (`'-`) is prefixed
/// too (`''-`), so that [`unneutralise`], which drops exactly one `'`, gives it back.
fn needs_prefix(s: &str) -> bool {
    s.trim_start_matches(TEXT_PREFIX).starts_with(FORMULA_LEADS)
}

/// A text cell for rows written with `csv::Writer::serialize`: serialises as
/// [`spreadsheet_safe`] of the text. Number fields of the same row stay plain `f64`/`i64`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SafeText<'a>(pub &'a str);

impl serde::Serialize for SafeText<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(&spreadsheet_safe(self.0))
    }
}

/// The CSV writer for every CSV pipewave writes: quotes every cell that is not a number, so a
/// neutralised text cell (`'=…`) is quoted and numbers stay bare.
pub fn writer<W: io::Write>(w: W) -> csv::Writer<W> {
    csv::WriterBuilder::new()
        .quote_style(csv::QuoteStyle::NonNumeric)
        .from_writer(w)
}

/// [`writer`] to the output `path`, through the output guard ([`crate::outfile`]): the file is
/// checked now and replaced only by [`finish`]; a writer dropped before that leaves it as it
/// was.
pub fn writer_from_path(path: &Path) -> Result<csv::Writer<OutFile>, csv::Error> {
    let file = OutFile::create(path, Contents::Plain).map_err(io::Error::other)?;
    Ok(writer(file))
}

/// Flush a writer of [`writer_from_path`] and move its file over the output.
pub fn finish(w: csv::Writer<OutFile>) -> Result<(), csv::Error> {
    let file = w
        .into_inner()
        .map_err(|e| io::Error::other(e.to_string()))?;
    file.commit().map_err(io::Error::other)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text(bytes: Vec<u8>) -> String {
        String::from_utf8(bytes).unwrap()
    }

    #[test]
    fn every_formula_lead_gets_the_text_prefix() {
        for (raw, safe) in [
            ("=HYPERLINK(\"http://x\")", "'=HYPERLINK(\"http://x\")"),
            ("+1", "'+1"),
            ("'=already text", "''=already text"),
            ("'-", "''-"),
            ("-2+3", "'-2+3"),
            ("@SUM(A1)", "'@SUM(A1)"),
            ("\tx", "'\tx"),
            ("\rx", "'\rx"),
            ("=", "'="),
        ] {
            let got = spreadsheet_safe(raw);
            assert!(matches!(got, Cow::Owned(_)), "{raw:?}");
            assert_eq!(got, safe);
        }
        assert_eq!(FORMULA_LEADS.len(), 6);
        for c in FORMULA_LEADS {
            assert_eq!(spreadsheet_safe(&c.to_string()), format!("'{c}"));
        }
    }

    #[test]
    fn unneutralise_inverts_spreadsheet_safe_and_nothing_else() {
        for t in [
            "=1+1", "+1", "-2", "@A1", "\t=x", "\r@y", "WM10003", "'", "'x", "''=1", "'-", "'=1",
        ] {
            assert_eq!(unneutralise(&spreadsheet_safe(t)), t, "{t:?}");
        }
        // A `'` not followed by a formula lead is text the user wrote.
        assert_eq!(unneutralise("'x"), "'x");
        assert_eq!(unneutralise("O'Brien"), "O'Brien");
        assert_eq!(unneutralise("'=1"), "=1");
    }

    #[test]
    fn safe_text_is_unchanged_and_borrowed() {
        for s in [
            "",
            "WM10003",
            "clay",
            "a=b",
            "x-1",
            " =padded",
            "<script>alert(1)</script>",
            "0.5",
            "ÿ=",
        ] {
            let got = spreadsheet_safe(s);
            assert!(matches!(got, Cow::Borrowed(_)), "{s:?}");
            assert_eq!(got, s);
        }
    }

    #[test]
    fn numbers_stay_bare_and_neutralised_text_is_quoted() {
        let mut w = writer(Vec::new());
        w.write_record(["segment_id", "k_im_np_per_m", "install_year", "note"])
            .unwrap();
        // A negative number in a number column is written as it is, without the prefix.
        w.write_record([
            spreadsheet_safe("-2+3").as_ref(),
            &(-0.5f64).to_string(),
            &1931.to_string(),
            "",
        ])
        .unwrap();
        w.write_record([spreadsheet_safe("WM1").as_ref(), "1e-7", "-3", "a,b"])
            .unwrap();
        let out = text(w.into_inner().unwrap());
        assert_eq!(
            out,
            "\"segment_id\",\"k_im_np_per_m\",\"install_year\",\"note\"\n\
             \"'-2+3\",-0.5,1931,\"\"\n\
             \"WM1\",1e-7,-3,\"a,b\"\n"
        );
        // And it reads back: text with its prefix, numbers as numbers.
        let mut r = csv::Reader::from_reader(out.as_bytes());
        let rows: Vec<csv::StringRecord> = r.records().map(Result::unwrap).collect();
        assert_eq!(&rows[0][0], "'-2+3");
        assert_eq!(rows[0][1].parse::<f64>().unwrap(), -0.5);
        assert_eq!(rows[1][2].parse::<i64>().unwrap(), -3);
    }

    #[test]
    fn safe_text_serialises_neutralised() {
        #[derive(serde::Serialize)]
        struct Row<'a> {
            segment_id: SafeText<'a>,
            attenuation_np_per_m: f64,
            campaign: Option<SafeText<'a>>,
        }
        let mut w = writer(Vec::new());
        w.serialize(Row {
            segment_id: SafeText("@SUM(A1)"),
            attenuation_np_per_m: -0.25,
            campaign: Some(SafeText("2024")),
        })
        .unwrap();
        w.serialize(Row {
            segment_id: SafeText("WM2"),
            attenuation_np_per_m: 0.5,
            campaign: None,
        })
        .unwrap();
        assert_eq!(
            text(w.into_inner().unwrap()),
            "\"segment_id\",\"attenuation_np_per_m\",\"campaign\"\n\
             \"'@SUM(A1)\",-0.25,2024\n\
             \"WM2\",0.5,\"\"\n"
        );
    }
}
