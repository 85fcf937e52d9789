//! `segments.csv`: the inventory, one row per pipe segment (docs/interface.md).

use super::aliases;
use super::staging::Staging;
use super::table::{ColumnSpec, RowCheck, Table};
use super::{ImportOptions, ImportSource, Problems};
use crate::db::crs;
use crate::db::inventory::SegmentRecord;
use crate::db::wkt::LineString;
use crate::db::DbError;
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
        name: "risk_weight",
        required: false,
    },
    ColumnSpec {
        name: "soil_class_override",
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

// Valid ranges of model §3.1, from `physics::inputs` (their one place); checking each override
// here names the offending column. The pipe and the fluid are then built by the checked
// constructors, which remain the authority.
use crate::physics::inputs::{
    FLUID_BULK_MODULUS_RANGE as FLUID_BULK_MODULUS, FLUID_DENSITY_RANGE as FLUID_DENSITY,
    MEAN_RADIUS_RANGE, PIPE_DENSITY_RANGE as PIPE_DENSITY,
    PIPE_LOSS_FACTOR_RANGE as PIPE_LOSS_FACTOR, PIPE_POISSON_RANGE as PIPE_POISSON,
    PIPE_YOUNGS_MODULUS_RANGE as PIPE_YOUNGS_MODULUS, SOIL_DENSITY_RANGE as SOIL_DENSITY,
};

/// Smallest wall thickness to mean radius ratio h/a accepted (the largest is the thin-shell
/// limit [`crate::physics::inputs::MAX_WALL_RATIO`], 0.25). The thinnest walls of buried water
/// pipes are those of large welded steel mains, D/h up to about 290 (AWWA M11's handling
/// limit, h/a ≈ 0.007), and of thin plastic pipe, SDR 41 (h/a ≈ 0.05). Below h/a = 0.005
/// (D/h ≈ 400) a buried pipe could not keep its shape under its own backfill (ring stiffness
/// grows as (h/D)³), so such a wall is a unit or typing error (a wall given in metres,
/// 1e-300), and the model's hoop stiffness E_p h/a² (P50) would vanish against the fluid's
/// 2B_f/a, leaving the fit without a pipe.
pub const MIN_WALL_RATIO: f64 = 0.005;

/// Longest segment accepted, m. A segment is one stretch of uniform pipe between fittings or
/// changes of material; even transmission mains are split at valves every few kilometres, and
/// leak-noise correlation spans at most about 1 km. 100 km also bounds every sum of lengths
/// (plan's weights, P83) far from overflow.
pub const MAX_LENGTH_M: f64 = 1e5;

/// Largest risk_weight: the longest segment ([`MAX_LENGTH_M`]) times a consequence factor of
/// 10^4, on the scale of metres of pipe the weight is given in (docs/interface.md).
pub const MAX_RISK_WEIGHT: f64 = 1e9;

/// Years a pipe in service can have been laid: from the oldest cast-iron mains still in use
/// (Versailles, 1664) to planned works well ahead; a date, a serial number or a two-digit year
/// falls outside.
pub const INSTALL_YEARS: std::ops::RangeInclusive<i64> = 1600..=2100;

/// The file, checked; its rows are staged ([`Staging::segment`]).
#[derive(Debug)]
pub(super) struct ParsedSegments {
    pub errors: Problems,
    pub fatal: bool,
    /// Things to tell the user that reject nothing (ignored columns).
    pub notes: Vec<String>,
    /// The optional columns the file does not have: a stored segment keeps its values of
    /// these ([`keep_stored`]).
    pub absent: Vec<&'static str>,
}

/// Read and check `segments.csv` a row at a time, staging every row whose id can be read (with
/// its record when the whole row is valid). `Err`: the staging tables failed.
pub(super) fn parse(
    source: &ImportSource,
    options: &ImportOptions,
    staging: &Staging<'_>,
) -> Result<ParsedSegments, DbError> {
    let read = Table::read(source, COLUMNS, options);
    let mut errors = Problems::from(read.errors);
    let notes = read.notes;
    let Some(mut table) = read.table else {
        return Ok(ParsedSegments {
            errors,
            fatal: read.fatal,
            notes,
            absent: Vec::new(),
        });
    };
    let absent: Vec<&'static str> = COLUMNS
        .iter()
        .filter(|c| !c.required && !table.has(c.name))
        .map(|c| c.name)
        .collect();
    for raw in table.take_rows() {
        let raw = match raw {
            Ok(raw) => raw,
            Err(e) => {
                errors.push(e);
                continue;
            }
        };
        let mut c = table.check(&raw);
        let record = check_row(&mut c, options.srid);
        let ok = c.errors.is_empty();
        if let Some(id) = c.text("segment_id") {
            staging.segment(raw.line, id, record.as_ref().filter(|_| ok))?;
        }
        errors.append(&mut c.errors);
    }
    staging.index_segments()?;

    // Each segment once: every occurrence of a repeated id is an error, since we cannot tell
    // which one is meant.
    let mut repeated: Vec<(String, Vec<u64>)> = Vec::new();
    staging.repeated_segment_ids(|id, line| match repeated.last_mut() {
        Some((last, lines)) if last == id => lines.push(line),
        _ => repeated.push((id.to_string(), vec![line])),
    })?;
    for (id, lines) in repeated {
        for &line in &lines {
            let others: Vec<String> = lines
                .iter()
                .filter(|&&l| l != line)
                .map(u64::to_string)
                .collect();
            errors.push(table.error(
                line,
                "segment_id",
                format!(
                    "duplicate segment_id '{id}': it is also on line {}; each segment must appear once",
                    others.join(", ")
                ),
            ));
        }
        staging.invalidate_segment(&id)?;
    }
    Ok(ParsedSegments {
        errors,
        fatal: false,
        notes,
        absent,
    })
}

/// Check one row; `Some` only if every cell is valid (the caller also looks at `c.errors`).
fn check_row(c: &mut RowCheck<'_>, default_srid: Option<i64>) -> Option<SegmentRecord> {
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
    let length_m = match length_m {
        Some(l) if l > MAX_LENGTH_M => {
            c.err(
                "length_m",
                format!(
                    "{} m is longer than a segment can be (at most {} m: one pipe between two \
                     fittings, not a whole main)",
                    short(l),
                    short(MAX_LENGTH_M)
                ),
            );
            None
        }
        l => l,
    };
    let soil_type = c.owned_text("soil_type");
    let install_year = match c.integer("install_year") {
        Some(y) if !INSTALL_YEARS.contains(&y) => {
            c.err(
                "install_year",
                format!(
                    "{y} is not a year a pipe in service was laid ({} to {}); give the year \
                     alone, such as 1947",
                    INSTALL_YEARS.start(),
                    INSTALL_YEARS.end()
                ),
            );
            None
        }
        y => y,
    };
    let soil_zone = c.owned_text("soil_zone");
    // A weight of P83's sum: any finite value from 0 (the segment's error does not matter) to
    // MAX_RISK_WEIGHT.
    let risk_weight = match c.number("risk_weight") {
        Some(w) if w < 0.0 => {
            c.err(
                "risk_weight",
                format!(
                    "must be 0 or more (a weight of the segment's speed error), got {}",
                    short(w)
                ),
            );
            None
        }
        Some(w) if w > MAX_RISK_WEIGHT => {
            c.err(
                "risk_weight",
                format!(
                    "{} is more than {} (the longest segment, {} m, times a consequence factor \
                     of 10^4); give weights on the scale of metres of pipe",
                    short(w),
                    short(MAX_RISK_WEIGHT),
                    short(MAX_LENGTH_M)
                ),
            );
            None
        }
        w => w,
    };
    let soil_class_override = c.owned_text("soil_class_override");

    let line = c.text("geometry_wkt").and_then(|t| {
        LineString::parse_wkt(t)
            .map_err(|e| c.err("geometry_wkt", e))
            .ok()
    });
    let srid = c.integer("srid");
    let srid = match srid {
        Some(s) if s <= 0 => {
            c.err("srid", format!("must be a positive EPSG code, got {s}"));
            None
        }
        Some(s) if crs::lookup(s).is_none() => {
            c.err(
                "srid",
                format!(
                    "{}: give an EPSG code of the registry, such as 27700 or 4326",
                    crs::CrsError::Unknown(s)
                ),
            );
            None
        }
        s => s,
    };
    let srid = match (srid, default_srid) {
        (None, Some(d)) if c.text("srid").is_none() && c.text("geometry_wkt").is_some() => Some(d),
        (s, _) => s,
    };
    // The line in its system (a --srid is checked here too, on the geometry it applies to).
    let geometry_wkt = match (line, srid) {
        (Some(l), Some(s)) => match crs::check_line(s, &l) {
            Ok(()) => Some(l.to_wkt()),
            Err(e) => {
                c.err("geometry_wkt", e);
                None
            }
        },
        (l, _) => l.map(|l| l.to_wkt()),
    };
    if c.text("geometry_wkt").is_some() && c.text("srid").is_none() && default_srid.is_none() {
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
        risk_weight,
        soil_class_override,
        geometry_wkt,
        srid,
        inputs_hash: String::new(),
        imported_at: String::new(),
        measurements: Vec::new(),
    };
    // The checked constructors are the final word: the thin-shell limit h/a <= 0.25 and the
    // mean-radius range are only known once the pipe is built.
    if let Err(e) = record.pipe() {
        c.err(pipe_error_column(&e), in_the_users_terms(&e, &record));
        return None;
    }
    // The lower limit of h/a, with the mean radius a = (D_o − h)/2 (model P6), once the
    // diameter and the upper limit are known to be good (a wrong diameter is named as such).
    let (h, d) = (record.wall_thickness_mm, record.outer_diameter_mm);
    let ratio = h / ((d - h) / 2.0);
    if ratio < MIN_WALL_RATIO {
        c.err(
            "wall_thickness_mm",
            format!(
                "{} mm is too thin a wall for a {} mm pipe: h/a = {} with the mean radius \
                 a = (D - h)/2 = {} mm, below {MIN_WALL_RATIO} (D/h of about 400), thinner than \
                 any water pipe is made; the shell model (model.md §3.2) needs a wall with \
                 0.005 <= h/a <= 0.25",
                short(h),
                short(d),
                short(ratio),
                short((d - h) / 2.0)
            ),
        );
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

/// Give `rec` the stored values of the optional columns the file does not have: a file without
/// a column says nothing about it, while an empty cell clears the value. The geometry and its
/// `srid` go together, kept when the file has no `geometry_wkt`.
pub(super) fn keep_stored(rec: &mut SegmentRecord, old: &SegmentRecord, absent: &[&str]) {
    for &col in absent {
        match col {
            "pipe_youngs_modulus_pa" => rec.pipe_youngs_modulus_pa = old.pipe_youngs_modulus_pa,
            "pipe_poisson" => rec.pipe_poisson = old.pipe_poisson,
            "pipe_density_kg_m3" => rec.pipe_density_kg_m3 = old.pipe_density_kg_m3,
            "pipe_loss_factor" => rec.pipe_loss_factor = old.pipe_loss_factor,
            "fluid_density_kg_m3" => rec.fluid_density_kg_m3 = old.fluid_density_kg_m3,
            "fluid_bulk_modulus_pa" => rec.fluid_bulk_modulus_pa = old.fluid_bulk_modulus_pa,
            "length_m" => rec.length_m = old.length_m,
            "soil_type" => rec.soil_type.clone_from(&old.soil_type),
            "install_year" => rec.install_year = old.install_year,
            "soil_zone" => rec.soil_zone.clone_from(&old.soil_zone),
            "risk_weight" => rec.risk_weight = old.risk_weight,
            "soil_class_override" => rec.soil_class_override.clone_from(&old.soil_class_override),
            "geometry_wkt" => {
                rec.geometry_wkt.clone_from(&old.geometry_wkt);
                rec.srid = old.srid;
            }
            _ => {}
        }
    }
}

/// The constructor's refusal in the terms of the file: a mean radius out of range is reported
/// as the outer diameter and wall the row gives, in mm, with the diameters the model takes.
fn in_the_users_terms(e: &InputError, record: &SegmentRecord) -> String {
    match e {
        InputError::OutOfRange { name, .. } | InputError::NotFinite { name, .. }
            if *name == MEAN_RADIUS_RANGE.name =>
        {
            let (d, h) = (record.outer_diameter_mm, record.wall_thickness_mm);
            let (lo, hi) = (MEAN_RADIUS_RANGE.lo * 1e3, MEAN_RADIUS_RANGE.hi * 1e3);
            format!(
                "an outer diameter of {} mm with a wall of {} mm is outside what the model takes: \
                 its mean radius (D - h)/2 = {} mm must be {} - {} mm (an outer diameter of \
                 about {} mm to {} m); is the diameter given in mm?",
                short(d),
                short(h),
                short((d - h) / 2.0),
                short(lo),
                short(hi),
                short(2.0 * lo),
                short(2.0 * hi / 1e3)
            )
        }
        _ => e.to_string(),
    }
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
