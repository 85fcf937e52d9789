//! `pipewave forward`: evaluate the forward model for a table of cases (docs/interface.md, "forward
//! input and output"). One output row per input row; a malformed row is reported with its line
//! and column and gets an `invalid_input` status, without stopping the other rows.

use std::path::{Path, PathBuf};

use crate::physics::solver::{solve_curve, Continuation};
use crate::physics::{ContactMode, Fluid, InputError, Model, Pipe, Soil, System};
use crate::spreadsheet::{self, spreadsheet_safe};
use crate::units::np_to_db;

/// The input columns, in the interface's order.
pub const INPUT_COLUMNS: [&str; 17] = [
    "case_id",
    "omega_rad_s",
    "fluid_density_kg_m3",
    "fluid_bulk_modulus_pa",
    "pipe_youngs_modulus_pa",
    "pipe_poisson",
    "pipe_density_kg_m3",
    "pipe_loss_factor",
    "mean_radius_m",
    "wall_thickness_m",
    "soil_youngs_modulus_pa",
    "soil_poisson",
    "soil_density_kg_m3",
    "soil_loss_factor",
    "contact",
    "model",
    "contact_mode",
];

/// The output columns: the interface's six, then `flags` (warnings on a root that was found).
pub const OUTPUT_COLUMNS: [&str; 7] = [
    "case_id",
    "k_re_rad_per_m",
    "k_im_np_per_m",
    "phase_speed_m_per_s",
    "attenuation_db_per_m",
    "status",
    "flags",
];

/// Errors that stop the whole command (the file cannot be read or written at all).
#[derive(Debug, thiserror::Error)]
pub enum ForwardError {
    /// The input could not be opened or read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: csv::Error,
    },
    /// The output could not be written.
    #[error("{path}: cannot write: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: csv::Error,
    },
    /// Required columns are missing from the header.
    #[error("{path}:1: missing column(s) {missing}; expected {expected}")]
    MissingColumns {
        /// The file.
        path: PathBuf,
        /// Comma-separated missing names.
        missing: String,
        /// Comma-separated expected names.
        expected: String,
    },
    /// The input has no header line.
    #[error("{path}: the file is empty (expected a header line with {expected})")]
    Empty {
        /// The file.
        path: PathBuf,
        /// Expected header.
        expected: String,
    },
}

/// What a forward run did.
#[derive(Debug, Default, Clone)]
pub struct ForwardReport {
    /// Rows read.
    pub rows: usize,
    /// Rows with a root (status `ok` or `growing_wave`).
    pub solved: usize,
    /// Rows whose root was not found.
    pub failed: usize,
    /// Malformed rows.
    pub invalid: usize,
    /// One message per malformed row: `FILE:LINE:COL: column NAME: reason`.
    pub messages: Vec<String>,
}

/// A cell that could not be used, for the message.
struct CellError {
    column: usize,
    message: String,
}

/// Evaluate every case of `input` and write `output`.
pub fn run(input: &Path, output: &Path) -> Result<ForwardReport, ForwardError> {
    let read_err = |source| ForwardError::Read {
        path: input.to_path_buf(),
        source,
    };
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .flexible(true)
        .from_path(input)
        .map_err(read_err)?;
    let headers = rdr.headers().map_err(read_err)?.clone();
    if headers.is_empty() || (headers.len() == 1 && headers[0].is_empty()) {
        return Err(ForwardError::Empty {
            path: input.to_path_buf(),
            expected: INPUT_COLUMNS.join(","),
        });
    }
    let mut idx = [0usize; 17];
    let mut missing = Vec::new();
    for (j, name) in INPUT_COLUMNS.iter().enumerate() {
        match headers.iter().position(|h| h == *name) {
            Some(p) => idx[j] = p,
            None => missing.push(*name),
        }
    }
    if !missing.is_empty() {
        return Err(ForwardError::MissingColumns {
            path: input.to_path_buf(),
            missing: missing.join(", "),
            expected: INPUT_COLUMNS.join(","),
        });
    }
    let write_err = |source| ForwardError::Write {
        path: output.to_path_buf(),
        source,
    };
    // Safe to open in a spreadsheet: text quoted, a formula-like case id prefixed with `'`.
    let mut wtr = spreadsheet::writer_from_path(output).map_err(write_err)?;
    wtr.write_record(OUTPUT_COLUMNS).map_err(write_err)?;
    let mut report = ForwardReport::default();
    for rec in rdr.records() {
        let rec = rec.map_err(read_err)?;
        report.rows += 1;
        let line = rec.position().map(|p| p.line()).unwrap_or(0);
        let case_id = spreadsheet_safe(rec.get(idx[0]).unwrap_or("")).into_owned();
        let row = match parse_case(&rec, &idx) {
            Ok((sys, omega)) => {
                let r = solve_curve(&sys, &[omega], Continuation::default())
                    .pop()
                    .expect("one result per frequency");
                match r {
                    Ok(root) => {
                        report.solved += 1;
                        let status = if root.flags.growing_wave {
                            "growing_wave"
                        } else {
                            "ok"
                        };
                        [
                            case_id,
                            root.k1.re.to_string(),
                            root.k1.im.to_string(),
                            root.phase_speed().to_string(),
                            np_to_db(-root.k1.im).to_string(),
                            status.to_string(),
                            root.flags.codes(),
                        ]
                    }
                    Err(e) => {
                        report.failed += 1;
                        [
                            case_id,
                            String::new(),
                            String::new(),
                            String::new(),
                            String::new(),
                            e.code().to_string(),
                            String::new(),
                        ]
                    }
                }
            }
            Err(e) => {
                report.invalid += 1;
                let name = headers.get(e.column).unwrap_or("?");
                report.messages.push(format!(
                    "{}:{}:{}: column {}: {}",
                    input.display(),
                    line,
                    e.column + 1,
                    name,
                    e.message
                ));
                [
                    case_id,
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    "invalid_input".to_string(),
                    String::new(),
                ]
            }
        };
        wtr.write_record(&row).map_err(write_err)?;
    }
    spreadsheet::finish(wtr).map_err(write_err)?;
    Ok(report)
}

fn parse_case(rec: &csv::StringRecord, idx: &[usize; 17]) -> Result<(System, f64), CellError> {
    let num = |j: usize| -> Result<f64, CellError> {
        let col = idx[j];
        let text = rec.get(col).unwrap_or("");
        text.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| CellError {
                column: col,
                message: if text.is_empty() {
                    "missing value (expected a number)".to_string()
                } else {
                    format!("'{text}' is not a finite number")
                },
            })
    };
    // Map a checked-constructor error to the column it came from.
    let at = |j: usize| {
        move |e: InputError| CellError {
            column: idx[j],
            message: e.to_string(),
        }
    };
    let omega = num(1)?;
    if omega <= 0.0 {
        return Err(CellError {
            column: idx[1],
            message: format!("angular frequency {omega} must be > 0"),
        });
    }
    let fluid = Fluid::new(num(2)?, num(3)?).map_err(|e| {
        let j = if matches!(&e, InputError::OutOfRange { name, .. } if name.contains("density")) {
            2
        } else {
            3
        };
        at(j)(e)
    })?;
    let pipe = Pipe::new(num(4)?, num(5)?, num(6)?, num(7)?, num(8)?, num(9)?).map_err(|e| {
        let j = match &e {
            InputError::OutOfRange { name, .. } | InputError::NotFinite { name, .. } => {
                if name.contains("Young") {
                    4
                } else if name.contains("Poisson") {
                    5
                } else if name.contains("density") {
                    6
                } else if name.contains("loss") {
                    7
                } else if name.contains("radius") {
                    8
                } else {
                    9
                }
            }
            _ => 9,
        };
        at(j)(e)
    })?;
    let em = num(10)?;
    let soil = if em == 0.0 {
        Soil::none()
    } else {
        Soil::new_unbounded(em, num(11)?, num(12)?, num(13)?).map_err(|e| {
            let j = match &e {
                InputError::OutOfRange { name, .. } if name.contains("Poisson") => 11,
                InputError::OutOfRange { name, .. } if name.contains("density") => 12,
                InputError::OutOfRange { name, .. } if name.contains("loss") => 13,
                _ => 10,
            };
            at(j)(e)
        })?
    };
    let contact = num(14)?;
    let model: Model = rec.get(idx[15]).unwrap_or("").parse().map_err(at(15))?;
    let mode: ContactMode = rec.get(idx[16]).unwrap_or("").parse().map_err(at(16))?;
    let sys = System::new(fluid, pipe, soil, contact, model, mode).map_err(at(14))?;
    Ok((sys, omega))
}
