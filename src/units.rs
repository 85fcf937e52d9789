//! Unit conversions at the edges (spec C2, C6, C7). SI inside the library.

use std::f64::consts::{LN_10, PI};

/// Decibels per neper: 20/ln 10 = 8.685889638065035 (spec P2).
pub const DB_PER_NP: f64 = 20.0 / LN_10;

/// Attenuation in dB/m from Np/m, eq. P2.
#[inline]
pub fn np_to_db(att_np: f64) -> f64 {
    DB_PER_NP * att_np
}

/// Attenuation in Np/m from dB/m, eq. P5.
#[inline]
pub fn db_to_np(att_db: f64) -> f64 {
    att_db / DB_PER_NP
}

/// Angular frequency ω (rad/s) from a frequency in Hz.
#[inline]
pub fn hz_to_omega(f_hz: f64) -> f64 {
    2.0 * PI * f_hz
}

/// Frequency in Hz from an angular frequency ω (rad/s).
#[inline]
pub fn omega_to_hz(omega: f64) -> f64 {
    omega / (2.0 * PI)
}

/// Millimetres to metres.
#[inline]
pub fn mm_to_m(mm: f64) -> f64 {
    mm * 1e-3
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Spec T14: att_dB = −8.685889638065035·Im k1 exactly, and the mapping P5.
    #[test]
    fn db_conversion_constant_and_round_trip() {
        assert_eq!(DB_PER_NP, 8.685889638065035);
        // Paper Table 2 row 1: 0.00544 Np/m is 0.047 dB/m.
        assert!((np_to_db(0.00544) - 0.0472512).abs() < 1e-6);
        assert!((db_to_np(np_to_db(0.0596)) - 0.0596).abs() < 1e-17);
        assert!((omega_to_hz(hz_to_omega(496.9)) - 496.9).abs() < 1e-12);
    }
}

/// `s` with every control character (C0, DEL, C1) written as a Rust escape (`\u{1b}`, `\0`,
/// `\n`), so that text echoed from an input file can neither recolour a terminal, set its
/// title, nor break a message into lines. Borrowed when there is nothing to escape.
pub fn escape_controls(s: &str) -> std::borrow::Cow<'_, str> {
    if !s.chars().any(char::is_control) {
        return std::borrow::Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 8);
    for c in s.chars() {
        if c.is_control() {
            out.extend(c.escape_debug());
        } else {
            out.push(c);
        }
    }
    std::borrow::Cow::Owned(out)
}

/// `x` in short form for messages: the shortest digits that read back to the same `f64`, in
/// plain notation from 1e-4 up to 1e15 and in scientific notation outside (`1e308`, not 309
/// digits; `2.5e-7`, not `0.00000025`). `0.0542` stays `0.0542`.
pub fn short(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || !x.is_finite() || (1e-4..1e15).contains(&a) {
        // Display of -0.0 is "-0"; a message means 0.
        if x == 0.0 {
            return "0".to_string();
        }
        x.to_string()
    } else {
        format!("{x:e}")
    }
}

/// `x` with `digits` significant digits, in plain or scientific notation as fits (for
/// messages and reports).
pub fn sig(x: f64, digits: usize) -> String {
    if !x.is_finite() {
        return x.to_string();
    }
    if x == 0.0 {
        return "0".to_string();
    }
    let e = x.abs().log10().floor() as i32;
    if (-3..6).contains(&e) {
        let decimals = (digits as i32 - 1 - e).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.prec$e}", prec = digits.saturating_sub(1))
    }
}

#[cfg(test)]
mod sig_tests {
    use super::{escape_controls, short, sig};

    #[test]
    fn control_characters_are_escaped_and_other_text_kept() {
        assert_eq!(escape_controls("Müller straße 5"), "Müller straße 5");
        assert_eq!(
            escape_controls("a\x1b]0;t\x07b\0\n\u{9b}"),
            "a\\u{1b}]0;t\\u{7}b\\0\\n\\u{9b}"
        );
    }

    #[test]
    fn short_numbers_for_messages() {
        assert_eq!(short(1e308), "1e308");
        assert_eq!(short(-1.5e300), "-1.5e300");
        assert_eq!(short(0.0542), "0.0542");
        assert_eq!(short(2.5e-7), "2.5e-7");
        assert_eq!(short(170.0), "170");
        assert_eq!(short(5.3), "5.3");
        assert_eq!(short(-0.0), "0");
        assert_eq!(short(f64::MIN_POSITIVE), "2.2250738585072014e-308");
        assert_eq!(short(123456789012345.0), "123456789012345");
        assert!(short(f64::MAX).len() < 30);
    }

    #[test]
    fn significant_digits() {
        assert_eq!(sig(4.79e7, 3), "4.79e7");
        assert_eq!(sig(0.3326, 3), "0.333");
        assert_eq!(sig(1283.846, 5), "1283.8");
        assert_eq!(sig(0.0, 3), "0");
    }
}
