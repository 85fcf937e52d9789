//! The ranges of the numeric options, stated once and shared by every command: a value outside
//! its range is refused by clap, with the range in the message and exit code 2, before the
//! command does anything. Each option's `--help` text and docs/interface.md state the same
//! range. Where the library owns a range (a band, a delay, a recording's length) the parser
//! calls the library's check, so the command line and the jobs files agree.

use clap::builder::{RangedI64ValueParser, RangedU64ValueParser};
use pipewave::units::short;

/// Most worker threads of any command (`--jobs`). One worker per hardware thread is all a fit
/// can use (the largest two-socket servers have 512); beyond that, idle rayon workers spin and
/// contend for the cores: 4,096 workers on two cores took 113 s to calibrate 20 segments that
/// one worker per core fits in 0.3 s.
pub const MAX_JOBS: u32 = 512;

/// Most segments of a synthetic network, and most segments a plan may choose: a large
/// utility's whole network is a few hundred thousand segments.
pub const MAX_SEGMENTS: u32 = 1_000_000;

/// `--jobs N`: 1 – [`MAX_JOBS`] worker threads.
pub fn jobs() -> RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(1..=i64::from(MAX_JOBS))
}

/// `--srid N`: an EPSG code, 1 – 2147483647 (a positive 32-bit integer, as a GeoPackage's
/// `srs_id`; EPSG's codes are below 1,000,000).
pub fn srid() -> RangedI64ValueParser<i64> {
    clap::value_parser!(i64).range(1..=i64::from(i32::MAX))
}

/// A count of `lo` – `hi` (a u32 option).
pub fn count(lo: u32, hi: u32) -> RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(i64::from(lo)..=i64::from(hi))
}

/// A size of `lo` – `hi` (a usize option).
pub fn size(lo: u64, hi: u64) -> RangedU64ValueParser<usize> {
    RangedU64ValueParser::<usize>::new().range(lo..=hi)
}

/// A finite real number in `lo` – `hi` (inclusive), in `unit` (for the message). `-0` reads
/// as 0.
pub fn real(
    lo: f64,
    hi: f64,
    unit: &'static str,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |s: &str| {
        let v: f64 = s
            .trim()
            .parse()
            .map_err(|_| format!("'{s}' is not a number{}", with_unit(unit)))?;
        if v.is_finite() && (lo..=hi).contains(&v) {
            Ok(v + 0.0)
        } else {
            Err(format!(
                "{} is outside {} – {}{}",
                short(v),
                short(lo),
                short(hi),
                with_unit(unit)
            ))
        }
    }
}

/// A fraction, 0 – 1.
pub fn fraction() -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    real(0.0, 1.0, "")
}

fn with_unit(unit: &str) -> String {
    if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    }
}

/// `--band LO,HI` of `locate`: the library's range and least width
/// ([`pipewave::locate::check_band`]), which the jobs file's band columns get too.
pub fn band(s: &str) -> Result<(f64, f64), String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}': expected LO,HI in Hz"))?;
    match v[..] {
        [lo, hi] => {
            pipewave::locate::check_band((lo, hi)).map_err(|e| e.to_string())?;
            Ok((lo + 0.0, hi))
        }
        _ => Err(format!("'{s}': expected two numbers LO,HI in Hz")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn real_refuses_what_is_not_a_finite_number_in_range() {
        let p = real(0.0, 0.5, "m");
        assert_eq!(p("0.25"), Ok(0.25));
        assert_eq!(p("-0").map(f64::is_sign_positive), Ok(true));
        for bad in ["nan", "inf", "-inf", "0.6", "-1e-300", "1e308", "x", ""] {
            assert!(p(bad).is_err(), "{bad}");
        }
        assert_eq!(p("1e308").unwrap_err(), "1e308 is outside 0 – 0.5 m");
    }

    #[test]
    fn a_band_needs_its_least_width() {
        assert_eq!(band("100, 800"), Ok((100.0, 800.0)));
        for bad in [
            "100,100.0000001",
            "100",
            "0,100",
            "800,100",
            "100,1e9",
            "a,b",
            "1,2,3",
        ] {
            assert!(band(bad).is_err(), "{bad}");
        }
    }
}
