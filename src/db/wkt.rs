//! The one geometry the inventory accepts: a 2-D WKT `LINESTRING (x y, x y, ...)`.
//!
//! Deliberately small: no Z/M coordinates, no multi-part geometries, no EMPTY. A segment is one
//! polyline in the coordinate system of its `srid`.

use std::fmt::Write as _;

/// A 2-D polyline, at least two points, finite coordinates (in the units of its SRID).
#[derive(Debug, Clone, PartialEq)]
pub struct LineString {
    /// The vertices (x, y).
    pub points: Vec<(f64, f64)>,
}

impl LineString {
    /// Parse `LINESTRING (x y, x y, ...)` (keyword case-insensitive, space before `(` optional).
    /// The error says what was expected, for the import's row messages.
    pub fn parse_wkt(text: &str) -> Result<LineString, String> {
        let t = text.trim();
        let keyword = "LINESTRING";
        let head = t.get(..keyword.len()).unwrap_or("");
        if !head.eq_ignore_ascii_case(keyword) {
            return Err(format!(
                "'{}' is not a LINESTRING; expected LINESTRING (x y, x y, ...)",
                abbreviate(t)
            ));
        }
        let rest = t[keyword.len()..].trim_start();
        let Some(body) = rest.strip_prefix('(') else {
            let what = rest.split_whitespace().next().unwrap_or("");
            return Err(if what.eq_ignore_ascii_case("EMPTY") {
                "LINESTRING EMPTY has no points; leave geometry_wkt blank instead".to_string()
            } else if ["Z", "M", "ZM"]
                .iter()
                .any(|s| what.eq_ignore_ascii_case(s))
            {
                format!("LINESTRING {what} is not supported: give 2-D coordinates (x y)")
            } else {
                "expected '(' after LINESTRING".to_string()
            });
        };
        let Some(body) = body.trim_end().strip_suffix(')') else {
            return Err("missing the closing ')'".to_string());
        };
        let mut points = Vec::new();
        for (i, pair) in body.split(',').enumerate() {
            let coords: Vec<&str> = pair.split_whitespace().collect();
            if coords.len() != 2 {
                return Err(format!(
                    "point {} '{}' must be two numbers 'x y' (2-D only)",
                    i + 1,
                    pair.trim()
                ));
            }
            let mut xy = [0.0; 2];
            for (v, c) in xy.iter_mut().zip(&coords) {
                *v = match c.parse::<f64>() {
                    Ok(v) if v.is_finite() => v,
                    _ => return Err(format!("point {}: '{c}' is not a finite number", i + 1)),
                };
            }
            points.push((xy[0], xy[1]));
        }
        if points.len() < 2 {
            return Err(format!(
                "a LINESTRING needs at least 2 points, this one has {}",
                points.len()
            ));
        }
        Ok(LineString { points })
    }

    /// `Err` when every vertex is the same point: such a line has no length, so it can neither
    /// carry a chainage nor join the network at two ends. Any two distinct vertices give it one.
    pub fn check_length(&self) -> Result<(), String> {
        match self.points.split_first() {
            Some((first, rest)) if rest.iter().all(|p| p == first) => Err(format!(
                "the line has zero length: all its {} vertices are the point ({} {}); a segment \
                 needs two distinct points",
                self.points.len(),
                crate::units::short(first.0),
                crate::units::short(first.1)
            )),
            _ => Ok(()),
        }
    }

    /// The canonical WKT, `LINESTRING (x y, x y)`, with full-precision numbers.
    pub fn to_wkt(&self) -> String {
        let mut s = String::from("LINESTRING (");
        for (i, (x, y)) in self.points.iter().enumerate() {
            if i > 0 {
                s.push_str(", ");
            }
            let _ = write!(s, "{x} {y}");
        }
        s.push(')');
        s
    }
}

/// The start of a long text, for messages.
fn abbreviate(t: &str) -> String {
    const MAX: usize = 40;
    match t.char_indices().nth(MAX) {
        Some((i, _)) => format!("{}...", &t[..i]),
        None => t.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_usual_forms() {
        let l = LineString::parse_wkt("LINESTRING (0 0, 10.5 -2e3, 3 4)").unwrap();
        assert_eq!(l.points, vec![(0.0, 0.0), (10.5, -2000.0), (3.0, 4.0)]);
        let l = LineString::parse_wkt("  linestring(1 2,3 4)  ").unwrap();
        assert_eq!(l.points, vec![(1.0, 2.0), (3.0, 4.0)]);
        assert_eq!(l.to_wkt(), "LINESTRING (1 2, 3 4)");
    }

    #[test]
    fn canonical_form_round_trips_full_precision() {
        let text = "LINESTRING (531234.123456789 181234.000000001, 0.1 0.30000000000000004)";
        let l = LineString::parse_wkt(text).unwrap();
        assert_eq!(l.to_wkt(), text);
        assert_eq!(LineString::parse_wkt(&l.to_wkt()).unwrap(), l);
    }

    #[test]
    fn rejects_what_it_does_not_support_with_a_reason() {
        let cases = [
            ("POINT (1 2)", "not a LINESTRING"),
            ("LINESTRING (1 2)", "at least 2 points"),
            ("LINESTRING ()", "two numbers"),
            ("LINESTRING EMPTY", "EMPTY"),
            ("LINESTRING Z (1 2 3, 4 5 6)", "2-D"),
            ("LINESTRING (1 2 3, 4 5 6)", "2-D"),
            ("LINESTRING (1 2, 3 x)", "'x' is not a finite number"),
            ("LINESTRING (1 2, 3 inf)", "not a finite number"),
            ("LINESTRING (1 2, 3 4", "closing"),
            ("LINESTRING 1 2, 3 4)", "expected '('"),
            ("", "not a LINESTRING"),
            ("MULTILINESTRING ((1 2, 3 4))", "not a LINESTRING"),
        ];
        for (text, reason) in cases {
            let err = LineString::parse_wkt(text).unwrap_err();
            assert!(err.contains(reason), "{text:?}: {err}");
        }
    }

    #[test]
    fn a_line_of_one_repeated_point_has_no_length() {
        let l = LineString::parse_wkt("LINESTRING (5 6, 5 6, 5 6)").unwrap();
        let e = l.check_length().unwrap_err();
        assert!(e.contains("zero length") && e.contains("(5 6)"), "{e}");
        let l = LineString::parse_wkt("LINESTRING (5 6, 5 6, 5 7)").unwrap();
        assert!(l.check_length().is_ok());
    }

    #[test]
    fn non_ascii_text_does_not_panic() {
        assert!(LineString::parse_wkt("LINESTRINÉ (1 2, 3 4)").is_err());
        assert!(LineString::parse_wkt("é").is_err());
        assert!(LineString::parse_wkt(&"é".repeat(100)).is_err());
    }
}
