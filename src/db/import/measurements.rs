//! `measurements.csv`: field wavenumbers, one row per segment and frequency (docs/interface.md).

use std::f64::consts::TAU;

use super::staging::{StagedMeasurement, Staging};
use super::table::{ColumnSpec, RowCheck, Table};
use super::{ImportOptions, ImportSource, Problems, RowError};
use crate::db::inventory::{MeasurementRecord, UNNAMED_CAMPAIGN};
use crate::db::DbError;
use crate::physics::inputs::{ATTENUATION_RANGE, K_RE_RANGE, MEASUREMENT_STD_RANGE, OMEGA_RANGE};
use crate::units::short;

/// The columns of `measurements.csv`. Exactly one of `frequency_hz` / `omega_rad_s` per row; the
/// header needs at least one of them (checked separately).
pub(super) const COLUMNS: &[ColumnSpec] = &[
    ColumnSpec {
        name: "segment_id",
        required: true,
    },
    ColumnSpec {
        name: "frequency_hz",
        required: false,
    },
    ColumnSpec {
        name: "omega_rad_s",
        required: false,
    },
    ColumnSpec {
        name: "k_re_rad_per_m",
        required: true,
    },
    ColumnSpec {
        name: "attenuation_np_per_m",
        required: true,
    },
    ColumnSpec {
        name: "k_re_std",
        required: false,
    },
    ColumnSpec {
        name: "attenuation_std",
        required: false,
    },
    ColumnSpec {
        name: "measured_on",
        required: false,
    },
    ColumnSpec {
        name: "campaign",
        required: false,
    },
    ColumnSpec {
        name: "note",
        required: false,
    },
];

/// Two measurements of one segment are at the same frequency when their ω differ by less than
/// this fraction. A frequency given in Hz becomes ω = 2πf with a rounding error near 1e-16, so
/// the same frequency written once in Hz and once in rad/s agrees to far better than 1e-9, while
/// field frequencies are never closer than about 1e-4 of each other.
pub const SAME_FREQUENCY_REL_TOL: f64 = 1e-9;

/// The file, checked (except that the segments exist: that needs the database); its valid rows
/// are staged ([`Staging::measurement`]).
#[derive(Debug)]
pub(super) struct ParsedMeasurements {
    pub file: String,
    pub errors: Problems,
    pub fatal: bool,
    /// Field index of `segment_id`, for errors raised later.
    pub segment_id_column: usize,
    /// Things to tell the user that reject nothing (ignored columns).
    pub notes: Vec<String>,
}

/// Read and check `measurements.csv` a row at a time, staging the valid rows. `Err`: the
/// staging tables failed.
pub(super) fn parse(
    source: &ImportSource,
    options: &ImportOptions,
    staging: &Staging<'_>,
) -> Result<ParsedMeasurements, DbError> {
    let read = Table::read(source, COLUMNS, options);
    let mut errors = Problems::from(read.errors);
    let mut out = ParsedMeasurements {
        file: source.name.clone(),
        errors: Problems::default(),
        fatal: read.fatal,
        segment_id_column: 0,
        notes: read.notes,
    };
    let Some(mut table) = read.table else {
        out.errors = errors;
        return Ok(out);
    };
    if !table.has("frequency_hz") && !table.has("omega_rad_s") {
        errors.push(RowError::new(
            &out.file,
            1,
            None,
            "missing the frequency column: the header needs frequency_hz or omega_rad_s",
        ));
        out.errors = errors;
        out.fatal = true;
        return Ok(out);
    }
    out.segment_id_column = table.index_of("segment_id").unwrap_or(0);
    for raw in table.take_rows() {
        let raw = match raw {
            Ok(raw) => raw,
            Err(e) => {
                errors.push(e);
                continue;
            }
        };
        let mut c = table.check(&raw);
        let record = check_row(&mut c);
        if let (Some(id), Some(m), true) = (c.text("segment_id"), &record, c.errors.is_empty()) {
            staging.measurement(raw.line, id, c.text("omega_rad_s").is_some(), m)?;
        }
        errors.append(&mut c.errors);
    }
    staging.index_measurements()?;

    // One measurement per segment, campaign and frequency: every member of a group of rows at
    // the same frequency is an error (we cannot tell which one is meant). The rows come by
    // segment, campaign and ω, so a group is a run of neighbours each at the same frequency as
    // the one before.
    let mut group: Vec<StagedMeasurement> = Vec::new();
    let mut duplicates: Vec<StagedMeasurement> = Vec::new();
    let mut close = |group: &mut Vec<StagedMeasurement>| {
        if group.len() > 1 {
            for m in group.iter() {
                let lines: Vec<String> = group
                    .iter()
                    .filter(|o| o.rowid != m.rowid)
                    .map(|o| o.line.to_string())
                    .collect();
                let col = if m.omega_given {
                    "omega_rad_s"
                } else {
                    "frequency_hz"
                };
                errors.push(table.error(
                    m.line,
                    col,
                    format!(
                        "segment '{}' already has a measurement at this frequency on line {} (campaign '{}'); give one row per segment, campaign and frequency (a later survey of the same pipe is another campaign: name it in the campaign column)",
                        m.segment_id,
                        lines.join(", "),
                        m.campaign
                    ),
                ));
            }
            duplicates.append(group);
        }
        group.clear();
    };
    staging.measurements_by_frequency(|m| {
        let joins = group.last().is_some_and(|prev| {
            prev.segment_id == m.segment_id
                && prev.campaign == m.campaign
                && same_frequency(prev.omega_rad_s, m.omega_rad_s)
        });
        if !joins {
            close(&mut group);
        }
        group.push(m);
        Ok(())
    })?;
    close(&mut group);
    for m in &duplicates {
        staging.invalidate_measurement(m.rowid)?;
    }
    out.errors = errors;
    Ok(out)
}

/// Same frequency within [`SAME_FREQUENCY_REL_TOL`].
pub(super) fn same_frequency(w1: f64, w2: f64) -> bool {
    (w1 - w2).abs() <= SAME_FREQUENCY_REL_TOL * w1.abs().max(w2.abs())
}

/// Smallest standard deviation of either part of a measured wavenumber, as a fraction of its
/// k_re. Both parts come from one complex wavenumber (P5), so their errors are of one absolute
/// size; field wavenumbers are good to 0.1–10 % of k_re, and a deviation a million times smaller
/// than k_re is a unit or typing error. A vanishing one would also weight its residual by
/// 1/σ² beyond any floating-point number (σ = 1e-300 leaves the fit no finite objective).
pub const MIN_RELATIVE_STD: f64 = 1e-6;

/// Keep `std` only if it is at least [`MIN_RELATIVE_STD`] of `k_re` (when both are known).
fn at_least_resolvable(
    c: &mut RowCheck<'_>,
    col: &'static str,
    std: Option<f64>,
    k_re: Option<f64>,
) -> Option<f64> {
    match (std, k_re) {
        (Some(s), Some(k)) if s < MIN_RELATIVE_STD * k => {
            c.err(
                col,
                format!(
                    "{} is less than {MIN_RELATIVE_STD:e} of k_re ({} rad/m): no field \
                     wavenumber is known that well; give one standard deviation in the same \
                     units as the value",
                    short(s),
                    short(k)
                ),
            );
            None
        }
        (s, _) => s,
    }
}

fn check_row(c: &mut RowCheck<'_>) -> Option<MeasurementRecord> {
    c.required_text("segment_id");
    let f = c.number("frequency_hz");
    let f = c.positive("frequency_hz", f, " Hz");
    let w = c.number("omega_rad_s");
    let w = c.positive("omega_rad_s", w, " rad/s");
    let has_f = c.text("frequency_hz").is_some();
    let has_w = c.text("omega_rad_s").is_some();
    let (omega, freq) = match (has_f, has_w) {
        (true, true) => {
            c.err(
                "omega_rad_s",
                "give the frequency once: either frequency_hz or omega_rad_s, not both",
            );
            (None, None)
        }
        (false, false) => {
            let col = if c.has("frequency_hz") {
                "frequency_hz"
            } else {
                "omega_rad_s"
            };
            c.err(
                col,
                "the frequency is missing: give frequency_hz or omega_rad_s",
            );
            (None, None)
        }
        // ω = 2πf.
        (true, false) => (f.map(|f| TAU * f), f),
        (false, true) => (w, w.map(|w| w / TAU)),
    };
    // The fitter's ranges (a value it would refuse is refused here, naming its cell); ω is
    // checked whichever way it was given, so an f whose 2πf overflows is named as such.
    let omega = match (omega, has_f) {
        (Some(w), true) if !OMEGA_RANGE.contains(w) => {
            c.err(
                "frequency_hz",
                format!(
                    "{} Hz is outside the range the fit accepts, {} - {} Hz (ω = 2πf {} - {} rad/s)",
                    short(freq.unwrap_or(w / TAU)),
                    short(OMEGA_RANGE.lo / TAU),
                    short(OMEGA_RANGE.hi / TAU),
                    OMEGA_RANGE.lo,
                    short(OMEGA_RANGE.hi)
                ),
            );
            None
        }
        (Some(w), false) => c.in_range("omega_rad_s", Some(w), OMEGA_RANGE),
        (w, _) => w,
    };
    let k = c.required_number("k_re_rad_per_m");
    let k = c.positive("k_re_rad_per_m", k, " rad/m");
    let k = c.in_range("k_re_rad_per_m", k, K_RE_RANGE);
    let att = c.required_number("attenuation_np_per_m");
    let att = match att {
        Some(a) if a < 0.0 => {
            c.err(
                "attenuation_np_per_m",
                format!(
                    "must be 0 or more (the decay rate is written positive), got {}",
                    short(a)
                ),
            );
            None
        }
        a => c.in_range("attenuation_np_per_m", a, ATTENUATION_RANGE),
    };
    let v = c.number("k_re_std");
    let k_re_std = c.positive("k_re_std", v, " rad/m");
    let k_re_std = c.in_range("k_re_std", k_re_std, MEASUREMENT_STD_RANGE);
    let k_re_std = at_least_resolvable(c, "k_re_std", k_re_std, k);
    let v = c.number("attenuation_std");
    let attenuation_std = c.positive("attenuation_std", v, " Np/m");
    let attenuation_std = c.in_range("attenuation_std", attenuation_std, MEASUREMENT_STD_RANGE);
    let attenuation_std = at_least_resolvable(c, "attenuation_std", attenuation_std, k);
    let measured_on = c.date("measured_on");
    // A blank campaign is the one fixed campaign `unnamed`: the nightly re-import of a file
    // without the column updates its rows and adds none.
    let campaign = Some(
        c.owned_text("campaign")
            .unwrap_or_else(|| UNNAMED_CAMPAIGN.to_string()),
    );
    let note = c.owned_text("note");
    if !c.errors.is_empty() {
        return None;
    }
    Some(MeasurementRecord {
        omega_rad_s: omega?,
        frequency_hz: freq?,
        k_re_rad_per_m: k?,
        attenuation_np_per_m: att?,
        k_re_std,
        attenuation_std,
        measured_on,
        campaign,
        note,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_frequency_uses_a_relative_tolerance() {
        let w = TAU * 250.0;
        assert!(same_frequency(w, 1_570.796_326_794_896_6));
        assert!(same_frequency(w, w * (1.0 + 0.5e-9)));
        assert!(!same_frequency(w, w * (1.0 + 2e-9)));
        assert!(!same_frequency(1.0, 2.0));
    }
}
