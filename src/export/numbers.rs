//! Numbers for people: the order of the exported columns and how the CSV and GeoJSON print
//! their values.
//!
//! - Order ([`columns`]): what a leak-correlator operator types in first (the segment, its
//!   leak-band speed and that speed's error, whether to trust it), then the rest of
//!   [`PROPERTIES`] in their own order. Every format uses it, the GeoPackage too.
//! - Rounding ([`Precision::People`], the default of the CSV and GeoJSON): a one-sigma error is
//!   printed to 2 significant digits, and the value it belongs to, with that value's 95 %
//!   interval ends, to the same decimal place (`1323.2 ± 1.4`, not `1323.156273100555 ±
//!   1.3588752771777628`); a value without an error keeps 6 significant digits. The pairing
//!   is by name, not by a list: an error column is a value's name with a `std` word inserted
//!   (`leak_band_speed_m_per_s` / `leak_band_speed_std_m_per_s`, `soil_poisson` /
//!   `soil_poisson_std`), an interval end one with a `lo` or `hi` word
//!   (`soil_youngs_modulus_lo_pa`), so a column added later in that form is rounded by its
//!   error with no change here. [`Precision::Full`] (`export --precision full`) prints every
//!   digit (Rust's shortest round-trip form); the database and the GeoPackage always keep full
//!   precision.

use std::collections::HashMap;
use std::sync::OnceLock;

use super::record::{Property, SegmentExport, Value, PROPERTIES};

/// How the CSV and GeoJSON print their numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Precision {
    /// Errors to 2 significant digits, their values to the same decimal place, other values
    /// to [`PLAIN_DIGITS`] significant digits.
    #[default]
    People,
    /// Every digit: the shortest text that reads back to the same float.
    Full,
}

/// Significant digits of an error.
pub const ERROR_DIGITS: i32 = 2;
/// Significant digits of a value that has no error.
pub const PLAIN_DIGITS: i32 = 6;

/// The columns that lead every export, in this order: the join key, the speed to type into a
/// correlator and its error, whether to trust it, and what the pipe is.
pub const LEADING: [&str; 8] = [
    "segment_id",
    "leak_band_speed_m_per_s",
    "leak_band_speed_std_m_per_s",
    "status",
    "flags",
    "material",
    "outer_diameter_mm",
    "wall_thickness_mm",
];

/// The exported properties in output order, each with the index (in this order) of the
/// error column that sets its decimals, if any.
pub struct Layout {
    /// The properties, [`LEADING`] first.
    pub properties: Vec<&'static Property>,
    /// For each property, the position of its error column (itself for an error column).
    error_of: Vec<Option<usize>>,
}

/// The name's `_`-separated words.
fn words(name: &str) -> Vec<&str> {
    name.split('_').collect()
}

/// The value column an error or interval column belongs to: the name without its `std`, `lo`
/// or `hi` word, and that word. `None` for a name without one.
fn base_of(name: &str) -> Option<(String, &'static str)> {
    let w = words(name);
    for tag in ["std", "lo", "hi"] {
        if let Some(i) = w.iter().position(|x| *x == tag) {
            let mut base = w.clone();
            base.remove(i);
            return Some((base.join("_"), tag));
        }
    }
    None
}

impl Layout {
    fn new() -> Self {
        let mut properties: Vec<&'static Property> = LEADING
            .iter()
            .filter_map(|n| PROPERTIES.iter().find(|p| p.name == *n))
            .collect();
        properties.extend(PROPERTIES.iter().filter(|p| !LEADING.contains(&p.name)));
        let position: HashMap<&str, usize> = properties
            .iter()
            .enumerate()
            .map(|(i, p)| (p.name, i))
            .collect();
        // value name -> position of its error column.
        let mut std_of: HashMap<String, usize> = HashMap::new();
        for (i, p) in properties.iter().enumerate() {
            if let Some((base, "std")) = base_of(p.name) {
                if position.contains_key(base.as_str()) {
                    std_of.insert(base, i);
                }
            }
        }
        let error_of = properties
            .iter()
            .enumerate()
            .map(|(i, p)| match base_of(p.name) {
                Some((base, "std")) => std_of.get(&base).map(|_| i),
                Some((base, _)) => std_of.get(&base).copied(),
                None => std_of.get(p.name).copied(),
            })
            .collect();
        Layout {
            properties,
            error_of,
        }
    }

    /// The error column setting property `i`'s decimals, if any (`Some(i)` for an error).
    pub fn error_of(&self, i: usize) -> Option<usize> {
        self.error_of[i]
    }

    /// The values of one record, in order, as printed at `precision`: `None` for a missing
    /// value, the printed number or text otherwise.
    pub fn cells<'a>(&self, rec: &'a SegmentExport, precision: Precision) -> Vec<Cell<'a>> {
        let values: Vec<Value<'a>> = self.properties.iter().map(|p| (p.get)(rec)).collect();
        values
            .iter()
            .enumerate()
            .map(|(i, v)| match v {
                Value::Null => Cell::Null,
                Value::Text(s) => Cell::Text(s),
                Value::Integer(n) => Cell::Number(n.to_string()),
                Value::Real(x) => Cell::Number(match precision {
                    Precision::Full => x.to_string(),
                    Precision::People => {
                        let error = self.error_of[i].and_then(|j| match values[j] {
                            Value::Real(e) if e.is_finite() && e > 0.0 => Some(e),
                            _ => None,
                        });
                        match error {
                            Some(e) => fixed(*x, error_place(e)),
                            None => significant(*x, PLAIN_DIGITS),
                        }
                    }
                }),
            })
            .collect()
    }
}

/// One printed value.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Cell<'a> {
    /// Missing.
    Null,
    /// Text, as stored.
    Text(&'a str),
    /// A number, as printed (a JSON number, a CSV cell).
    Number(String),
}

/// The export layout, built once.
pub fn columns() -> &'static Layout {
    static LAYOUT: OnceLock<Layout> = OnceLock::new();
    LAYOUT.get_or_init(Layout::new)
}

/// The decimal exponent of the last digit kept when `e > 0` is printed to [`ERROR_DIGITS`]
/// significant digits (0: units, -1: tenths, 1: tens), after rounding (0.996 is 1.0, one
/// decimal, not 1.00).
pub fn error_place(e: f64) -> i32 {
    let exp = e.abs().log10().floor() as i32;
    let place = exp - (ERROR_DIGITS - 1);
    let rounded = round_at(e, place);
    if rounded >= 10f64.powi(exp + 1) {
        place + 1
    } else {
        place
    }
}

/// `x` rounded to a multiple of 10^place.
fn round_at(x: f64, place: i32) -> f64 {
    if place >= 0 {
        let k = 10f64.powi(place);
        (x / k).round() * k
    } else {
        let k = 10f64.powi(-place);
        (x * k).round() / k
    }
}

/// `x` printed to the decimal place 10^place, in plain notation (trailing zeros kept: they are
/// significant next to the error); `-0` printed as `0`.
pub fn fixed(x: f64, place: i32) -> String {
    let s = if place >= 0 {
        format!("{:.0}", round_at(x, place))
    } else {
        format!("{x:.prec$}", prec = (-place) as usize)
    };
    if s.starts_with('-') && s[1..].bytes().all(|b| b == b'0' || b == b'.') {
        s[1..].to_string()
    } else {
        s
    }
}

/// `x` to `digits` significant digits, trailing zeros of the decimals dropped; plain notation
/// unless the magnitude is below 1e-6 or at least 1e15 (then `1.23457e-9`).
pub fn significant(x: f64, digits: i32) -> String {
    if x == 0.0 {
        return "0".to_string();
    }
    let exp = x.abs().log10().floor() as i32;
    if !(-6..15).contains(&exp) {
        let s = format!("{x:.prec$e}", prec = (digits - 1) as usize);
        return match s.split_once('e') {
            Some((m, e)) if m.contains('.') => {
                format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
            }
            _ => s,
        };
    }
    let s = fixed(x, exp - (digits - 1));
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_take_two_digits_and_values_their_decimal_place() {
        // The case of the issue: 1323.156273100555 ± 1.3588752771777628.
        let p = error_place(1.358_875_277_177_762_8);
        assert_eq!(
            (
                fixed(1.358_875_277_177_762_8, p),
                fixed(1_323.156_273_100_555, p)
            ),
            ("1.4".into(), "1323.2".into())
        );
        // 371 ± 382: tens.
        let p = error_place(382.4);
        assert_eq!(
            (fixed(382.4, p), fixed(371.2, p)),
            ("380".into(), "370".into())
        );
        // Rounding that carries: 0.996 is 1.0 (two digits), so the value gets one decimal.
        let p = error_place(0.996);
        assert_eq!(
            (fixed(0.996, p), fixed(12.345, p)),
            ("1.0".into(), "12.3".into())
        );
        // Small errors: 0.000_123_4 -> 0.00012.
        let p = error_place(0.000_123_4);
        assert_eq!(
            (fixed(0.000_123_4, p), fixed(0.028_766, p)),
            ("0.00012".into(), "0.02877".into())
        );
        // Trailing zeros stay: they are significant beside the error.
        assert_eq!(fixed(1323.0, error_place(1.4)), "1323.0");
        assert_eq!(fixed(-0.02, 0), "0");
    }

    #[test]
    fn plain_values_keep_six_significant_digits() {
        assert_eq!(significant(1_323.156_273_100_555, 6), "1323.16");
        assert_eq!(significant(118.0, 6), "118");
        assert_eq!(significant(52_345_678.9, 6), "52345700");
        assert_eq!(significant(0.000_123_456_789, 6), "0.000123457");
        assert_eq!(significant(1.5e-9, 6), "1.5e-9");
        assert_eq!(significant(-2.25e9, 6), "-2250000000");
        assert_eq!(significant(0.0, 6), "0");
    }

    #[test]
    fn the_correlator_columns_lead_and_errors_pair_by_name() {
        let l = columns();
        let names: Vec<&str> = l.properties.iter().map(|p| p.name).collect();
        assert_eq!(&names[..LEADING.len()], &LEADING[..]);
        assert_eq!(names.len(), PROPERTIES.len());
        let at = |n: &str| names.iter().position(|x| *x == n).unwrap();
        let speed_std = at("leak_band_speed_std_m_per_s");
        assert_eq!(l.error_of(at("leak_band_speed_m_per_s")), Some(speed_std));
        assert_eq!(l.error_of(speed_std), Some(speed_std));
        let e_std = at("soil_youngs_modulus_std_pa");
        for n in [
            "soil_youngs_modulus_pa",
            "soil_youngs_modulus_lo_pa",
            "soil_youngs_modulus_hi_pa",
        ] {
            assert_eq!(l.error_of(at(n)), Some(e_std), "{n}");
        }
        assert_eq!(
            l.error_of(at("soil_poisson_hi")),
            Some(at("soil_poisson_std"))
        );
        assert_eq!(l.error_of(at("contact")), Some(at("contact_std")));
        assert_eq!(
            l.error_of(at("soil_p_wave_speed_m_per_s")),
            Some(at("soil_p_wave_speed_std_m_per_s"))
        );
        // No error column: plain.
        assert_eq!(l.error_of(at("speed_100hz_m_per_s")), None);
        assert_eq!(l.error_of(at("misfit")), None);
        // A zone's interval has no error column of its own.
        assert_eq!(l.error_of(at("zone_soil_youngs_modulus_lo_pa")), None);
        assert_eq!(
            base_of("field_leak_band_speed_std_m_per_s"),
            Some(("field_leak_band_speed_m_per_s".into(), "std"))
        );
    }
}
