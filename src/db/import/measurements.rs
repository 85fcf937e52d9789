//! `measurements.csv`: field wavenumbers, one row per segment and frequency (docs/interface.md).

use std::collections::BTreeMap;
use std::f64::consts::TAU;

use super::table::{ColumnSpec, RowCheck, Table};
use super::{ImportOptions, ImportSource, RowError};
use crate::db::inventory::MeasurementRecord;

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
];

/// Two measurements of one segment are at the same frequency when their ω differ by less than
/// this fraction. A frequency given in Hz becomes ω = 2πf with a rounding error near 1e-16, so
/// the same frequency written once in Hz and once in rad/s agrees to far better than 1e-9, while
/// field frequencies are never closer than about 1e-4 of each other.
pub const SAME_FREQUENCY_REL_TOL: f64 = 1e-9;

/// One data row of the file.
#[derive(Debug)]
pub(super) struct MeasurementRow {
    pub line: u64,
    /// The segment id, when the cell could be read.
    pub segment_id: Option<String>,
    /// The checked record, when the whole row is valid.
    pub record: Option<MeasurementRecord>,
}

/// The file, checked (except that the segments exist: that needs the database).
#[derive(Debug)]
pub(super) struct ParsedMeasurements {
    pub file: String,
    pub rows: Vec<MeasurementRow>,
    pub errors: Vec<RowError>,
    pub fatal: bool,
    /// Field index of `segment_id`, for errors raised later.
    pub segment_id_column: usize,
    /// Things to tell the user that reject nothing (ignored columns).
    pub notes: Vec<String>,
}

/// Read and check `measurements.csv`.
pub(super) fn parse(source: &ImportSource, options: &ImportOptions) -> ParsedMeasurements {
    let read = Table::read(source, COLUMNS, options);
    let mut errors = read.errors;
    let mut out = ParsedMeasurements {
        file: source.name.clone(),
        rows: Vec::new(),
        errors: Vec::new(),
        fatal: read.fatal,
        segment_id_column: 0,
        notes: read.notes,
    };
    let Some(table) = read.table else {
        out.errors = errors;
        return out;
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
        return out;
    }
    out.segment_id_column = table.index_of("segment_id").unwrap_or(0);
    let mut rows: Vec<MeasurementRow> = table
        .rows
        .iter()
        .map(|raw| {
            let mut c = table.check(raw);
            let segment_id = c.text("segment_id").map(str::to_string);
            let record = check_row(&mut c);
            let ok = c.errors.is_empty();
            errors.append(&mut c.errors);
            MeasurementRow {
                line: raw.line,
                segment_id,
                record: if ok { record } else { None },
            }
        })
        .collect();

    // One measurement per segment and frequency: every member of a group of rows at the same
    // frequency is an error (we cannot tell which one is meant).
    let mut by_segment: BTreeMap<&str, Vec<(f64, usize)>> = BTreeMap::new();
    for (i, r) in rows.iter().enumerate() {
        if let (Some(id), Some(m)) = (&r.segment_id, &r.record) {
            by_segment.entry(id).or_default().push((m.omega_rad_s, i));
        }
    }
    let mut duplicates: Vec<(usize, Vec<u64>)> = Vec::new();
    for list in by_segment.values_mut() {
        list.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut start = 0;
        while start < list.len() {
            let mut end = start + 1;
            while end < list.len() && same_frequency(list[end - 1].0, list[end].0) {
                end += 1;
            }
            if end - start > 1 {
                let group = &list[start..end];
                for &(_, i) in group {
                    let others = group
                        .iter()
                        .filter(|&&(_, j)| j != i)
                        .map(|&(_, j)| rows[j].line)
                        .collect();
                    duplicates.push((i, others));
                }
            }
            start = end;
        }
    }
    for (i, others) in duplicates {
        let Some(raw) = table.rows.iter().find(|raw| raw.line == rows[i].line) else {
            continue;
        };
        let mut c = table.check(raw);
        let col = if c.text("omega_rad_s").is_some() {
            "omega_rad_s"
        } else {
            "frequency_hz"
        };
        let lines: Vec<String> = others.iter().map(u64::to_string).collect();
        c.err(
            col,
            format!(
                "segment '{}' already has a measurement at this frequency on line {}; give one row per segment and frequency",
                rows[i].segment_id.as_deref().unwrap_or(""),
                lines.join(", ")
            ),
        );
        errors.append(&mut c.errors);
        rows[i].record = None;
    }
    out.rows = rows;
    out.errors = errors;
    out
}

/// Same frequency within [`SAME_FREQUENCY_REL_TOL`].
pub(super) fn same_frequency(w1: f64, w2: f64) -> bool {
    (w1 - w2).abs() <= SAME_FREQUENCY_REL_TOL * w1.abs().max(w2.abs())
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
    let k = c.required_number("k_re_rad_per_m");
    let k = c.positive("k_re_rad_per_m", k, " rad/m");
    let att = c.required_number("attenuation_np_per_m");
    let att = match att {
        Some(a) if a < 0.0 => {
            c.err(
                "attenuation_np_per_m",
                format!(
                    "must be 0 or more (the decay rate is written positive), got {}",
                    crate::units::short(a)
                ),
            );
            None
        }
        a => a,
    };
    let v = c.number("k_re_std");
    let k_re_std = c.positive("k_re_std", v, " rad/m");
    let v = c.number("attenuation_std");
    let attenuation_std = c.positive("attenuation_std", v, " Np/m");
    let measured_on = c.date("measured_on");
    let campaign = c.owned_text("campaign");
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
