//! `segments.csv`: the inventory, one row per pipe segment (docs/interface.md).

use std::collections::BTreeMap;

use super::aliases;
use super::table::{ColumnSpec, RowCheck, Table};
use super::{ImportOptions, ImportSource, RowError};
use crate::db::inventory::{SegmentRecord, SOIL_DENSITY_RANGE};
use crate::db::wkt::LineString;
use crate::physics::InputError;
use crate::units::short;

/// The columns of `segments.csv`.
pub(super) const COLUMNS: &[ColumnSpec] = &[
    ColumnSpec {
        name: "segment_id",
        required: true,
    },
    ColumnSpec {
        name: "material",
        required: true,
    },
    ColumnSpec {
        name: "outer_diameter_mm",
        required: true,
    },
    ColumnSpec {
        name: "wall_thickness_mm",
        required: true,
    },
    ColumnSpec {
        name: "soil_density_kg_m3",
        required: true,
    },
    ColumnSpec {
        name: "pipe_youngs_modulus_pa",
        required: false,
    },
    ColumnSpec {
        name: "pipe_poisson",
        required: false,
    },
    ColumnSpec {
        name: "pipe_density_kg_m3",
        required: false,
    },
    ColumnSpec {
        name: "pipe_loss_factor",
        required: false,
    },
    ColumnSpec {
        name: "fluid_density_kg_m3",
        required: false,
    },
    ColumnSpec {
        name: "fluid_bulk_modulus_pa",
        required: false,
    },
    ColumnSpec {
        name: "length_m",
        required: false,
    },
    ColumnSpec {
        name: "soil_type",
        required: false,
    },
    ColumnSpec {
        name: "install_year",
        required: false,
    },
    ColumnSpec {
        name: "soil_zone",
        required: false,
    },
    ColumnSpec {
        name: "geometry_wkt",
        required: false,
    },
    ColumnSpec {
        name: "srid",
        required: false,
    },
];

/// A valid-range check: (quantity for the message, low, high, range text).
type Range = (&'static str, f64, f64, &'static str);

// Valid ranges of spec §3.1 ("reject outside"), the same as the checked constructors in
// `physics::inputs`; checking each override here names the offending column. The pipe and the
// fluid are then built by those constructors, which remain the authority.
const PIPE_YOUNGS_MODULUS: Range = ("pipe Young's modulus (Pa)", 1e8, 3e11, "1e8 - 3e11");
const PIPE_POISSON: Range = ("pipe Poisson's ratio", 0.0, 0.49, "0 - 0.49");
const PIPE_DENSITY: Range = ("pipe density (kg/m3)", 500.0, 9000.0, "500 - 9000");
const PIPE_LOSS_FACTOR: Range = ("pipe loss factor", 0.0, 0.3, "0 - 0.3");
const FLUID_DENSITY: Range = ("fluid density (kg/m3)", 500.0, 1100.0, "500 - 1100");
const FLUID_BULK_MODULUS: Range = ("fluid bulk modulus (Pa)", 1e6, 2.5e9, "1e6 - 2.5e9");
const SOIL_DENSITY: Range = (
    "soil density (kg/m3)",
    SOIL_DENSITY_RANGE.0,
    SOIL_DENSITY_RANGE.1,
    "1000 - 2600",
);

/// One data row of the file.
#[derive(Debug)]
pub(super) struct SegmentRow {
    pub line: u64,
    /// The id, when the cell could be read.
    pub segment_id: Option<String>,
    /// The checked record (without measurements), when the whole row is valid.
    pub record: Option<SegmentRecord>,
}

/// The file, checked.
#[derive(Debug)]
pub(super) struct ParsedSegments {
    pub rows: Vec<SegmentRow>,
    pub errors: Vec<RowError>,
    pub fatal: bool,
    /// Things to tell the user that reject nothing (ignored columns).
    pub notes: Vec<String>,
}

/// Read and check `segments.csv`.
pub(super) fn parse(source: &ImportSource, options: &ImportOptions) -> ParsedSegments {
    let read = Table::read(source, COLUMNS, options);
    let mut errors = read.errors;
    let notes = read.notes;
    let Some(table) = read.table else {
        return ParsedSegments {
            rows: Vec::new(),
            errors,
            fatal: read.fatal,
            notes,
        };
    };
    let mut rows: Vec<SegmentRow> = table
        .rows
        .iter()
        .map(|raw| {
            let mut c = table.check(raw);
            let segment_id = c.text("segment_id").map(str::to_string);
            let record = check_row(&mut c);
            let ok = c.errors.is_empty();
            errors.append(&mut c.errors);
            SegmentRow {
                line: raw.line,
                segment_id,
                record: if ok { record } else { None },
            }
        })
        .collect();

    // Each segment once: every occurrence of a repeated id is an error, since we cannot tell
    // which one is meant.
    let mut lines_of: BTreeMap<String, Vec<u64>> = BTreeMap::new();
    for r in &rows {
        if let Some(id) = &r.segment_id {
            lines_of.entry(id.clone()).or_default().push(r.line);
        }
    }
    for r in &mut rows {
        let Some(id) = &r.segment_id else { continue };
        let Some(lines) = lines_of.get(id).filter(|l| l.len() > 1) else {
            continue;
        };
        let others: Vec<String> = lines
            .iter()
            .filter(|&&l| l != r.line)
            .map(u64::to_string)
            .collect();
        let raw = table.rows.iter().find(|raw| raw.line == r.line);
        if let Some(raw) = raw {
            let mut c = table.check(raw);
            c.err(
                "segment_id",
                format!(
                    "duplicate segment_id '{id}': it is also on line {}; each segment must appear once",
                    others.join(", ")
                ),
            );
            errors.append(&mut c.errors);
        }
        r.record = None;
    }
    ParsedSegments {
        rows,
        errors,
        fatal: false,
        notes,
    }
}

/// Check one row; `Some` only if every cell is valid (the caller also looks at `c.errors`).
fn check_row(c: &mut RowCheck<'_>) -> Option<SegmentRecord> {
    let segment_id = c.required_text("segment_id").map(str::to_string);
    let material = c.required_text("material").and_then(|t| {
        aliases::material(t)
            .map_err(|e| c.err("material", e.to_string()))
            .ok()
    });
    let od = c.required_number("outer_diameter_mm");
    let od = c.positive("outer_diameter_mm", od, " mm");
    let wall = c.required_number("wall_thickness_mm");
    let wall = c.positive("wall_thickness_mm", wall, " mm");
    let wall = match (wall, od) {
        (Some(h), Some(d)) if h >= d / 2.0 => {
            c.err(
                "wall_thickness_mm",
                format!(
                    "must be less than half the outer diameter ({} mm / 2), got {} mm",
                    short(d),
                    short(h)
                ),
            );
            None
        }
        _ => wall,
    };
    let soil = c.required_number("soil_density_kg_m3");
    let soil_density = c.in_range("soil_density_kg_m3", soil, SOIL_DENSITY);

    let v = c.number("pipe_youngs_modulus_pa");
    let pipe_youngs_modulus_pa = c.in_range("pipe_youngs_modulus_pa", v, PIPE_YOUNGS_MODULUS);
    let v = c.number("pipe_poisson");
    let pipe_poisson = c.in_range("pipe_poisson", v, PIPE_POISSON);
    let v = c.number("pipe_density_kg_m3");
    let pipe_density_kg_m3 = c.in_range("pipe_density_kg_m3", v, PIPE_DENSITY);
    let v = c.number("pipe_loss_factor");
    let pipe_loss_factor = c.in_range("pipe_loss_factor", v, PIPE_LOSS_FACTOR);
    let v = c.number("fluid_density_kg_m3");
    let fluid_density_kg_m3 = c.in_range("fluid_density_kg_m3", v, FLUID_DENSITY);
    let v = c.number("fluid_bulk_modulus_pa");
    let fluid_bulk_modulus_pa = c.in_range("fluid_bulk_modulus_pa", v, FLUID_BULK_MODULUS);

    let v = c.number("length_m");
    let length_m = c.positive("length_m", v, " m");
    let soil_type = c.owned_text("soil_type");
    let install_year = c.integer("install_year");
    let soil_zone = c.owned_text("soil_zone");

    let geometry_wkt = c.text("geometry_wkt").and_then(|t| {
        LineString::parse_wkt(t)
            .map(|l| l.to_wkt())
            .map_err(|e| c.err("geometry_wkt", e))
            .ok()
    });
    let srid = c.integer("srid");
    let srid = match srid {
        Some(s) if s <= 0 => {
            c.err("srid", format!("must be a positive EPSG code, got {s}"));
            None
        }
        s => s,
    };
    if c.text("geometry_wkt").is_some() && c.text("srid").is_none() {
        if c.has("srid") {
            c.err(
                "srid",
                "geometry_wkt is given, so srid (its EPSG code, such as 27700 or 4326) is required",
            );
        } else {
            c.err(
                "geometry_wkt",
                "a geometry needs its coordinate system: add a column srid with its EPSG code \
                 (such as 27700 or 4326)",
            );
        }
    }

    if !c.errors.is_empty() {
        return None;
    }
    let record = SegmentRecord {
        segment_id: segment_id?,
        material: material?,
        outer_diameter_mm: od?,
        wall_thickness_mm: wall?,
        soil_density_kg_m3: soil_density?,
        pipe_youngs_modulus_pa,
        pipe_poisson,
        pipe_density_kg_m3,
        pipe_loss_factor,
        fluid_density_kg_m3,
        fluid_bulk_modulus_pa,
        length_m,
        soil_type,
        install_year,
        soil_zone,
        geometry_wkt,
        srid,
        inputs_hash: String::new(),
        imported_at: String::new(),
        measurements: Vec::new(),
    };
    // The checked constructors are the final word: the thin-shell limit h/a <= 0.25 and the
    // mean-radius range are only known once the pipe is built.
    if let Err(e) = record.pipe() {
        c.err(pipe_error_column(&e), e.to_string());
        return None;
    }
    if let Err(e) = record.fluid() {
        let col = match &e {
            InputError::OutOfRange { name, .. } | InputError::NotFinite { name, .. }
                if name.contains("density") =>
            {
                "fluid_density_kg_m3"
            }
            _ => "fluid_bulk_modulus_pa",
        };
        c.err(col, e.to_string());
        return None;
    }
    Some(record)
}

/// The column to blame for a pipe the constructor refused.
fn pipe_error_column(e: &InputError) -> &'static str {
    let name = match e {
        InputError::WallTooThick { .. } => return "wall_thickness_mm",
        InputError::OutOfRange { name, .. } | InputError::NotFinite { name, .. } => *name,
        InputError::Unknown { .. } => return "material",
    };
    if name.contains("wall") {
        "wall_thickness_mm"
    } else if name.contains("radius") || name.contains("diameter") {
        "outer_diameter_mm"
    } else if name.contains("Young") {
        "pipe_youngs_modulus_pa"
    } else if name.contains("Poisson") {
        "pipe_poisson"
    } else if name.contains("density") {
        "pipe_density_kg_m3"
    } else if name.contains("loss") {
        "pipe_loss_factor"
    } else {
        "material"
    }
}
