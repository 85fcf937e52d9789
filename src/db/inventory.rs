//! The imported inventory: segments and their measurements, as stored, and as the checked physics
//! inputs the calibration needs.

use std::collections::BTreeSet;

use rusqlite::{params, Connection, OptionalExtension, Row};

use super::DbError;
use crate::physics::inputs::{SOIL_DENSITY_RANGE, WATER_BULK_MODULUS, WATER_DENSITY};
use crate::physics::{Fluid, InputError, Material, MaterialProps, Pipe};

/// Millimetres to metres.
pub const M_PER_MM: f64 = 1e-3;

/// One row of `segments`: the inventory of one pipe segment, in the units of `segments.csv`,
/// with its measurements.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentRecord {
    /// The utility's asset id.
    pub segment_id: String,
    /// Pipe material.
    pub material: Material,
    /// Outside diameter D_o, mm.
    pub outer_diameter_mm: f64,
    /// Wall thickness h, mm.
    pub wall_thickness_mm: f64,
    /// Soil density ρ_m, kg/m³.
    pub soil_density_kg_m3: f64,
    /// Override of the material's Young's modulus E_p, Pa.
    pub pipe_youngs_modulus_pa: Option<f64>,
    /// Override of the material's Poisson's ratio ν_p.
    pub pipe_poisson: Option<f64>,
    /// Override of the material's density ρ_p, kg/m³.
    pub pipe_density_kg_m3: Option<f64>,
    /// Override of the material's loss factor η_p.
    pub pipe_loss_factor: Option<f64>,
    /// Fluid density ρ_f, kg/m³ (None: water).
    pub fluid_density_kg_m3: Option<f64>,
    /// Fluid bulk modulus B_f, Pa (None: water).
    pub fluid_bulk_modulus_pa: Option<f64>,
    /// Length, m (informational).
    pub length_m: Option<f64>,
    /// Soil description (informational).
    pub soil_type: Option<String>,
    /// Year laid (informational).
    pub install_year: Option<i64>,
    /// The soil unit the segment lies in, from a geotechnical map or survey (informational for
    /// the segment's own fit; segments of one zone are also estimated together, model §7.11).
    pub soil_zone: Option<String>,
    /// How much the segment's speed error matters (finite, ≥ 0): `plan` weights its relative
    /// speed variance by it (P83) instead of by its length. Informational for its fit.
    pub risk_weight: Option<f64>,
    /// The soil class the engineer has checked for this segment: the field uses it as the
    /// segment's class without the neighbourhood's rejection test (model §7.12).
    /// Informational for its fit.
    pub soil_class_override: Option<String>,
    /// `LINESTRING (x y, ...)` in EPSG:`srid`, canonical form.
    pub geometry_wkt: Option<String>,
    /// EPSG code of the geometry.
    pub srid: Option<i64>,
    /// Hash of everything a fit depends on ([`super::staleness`]), as stored.
    pub inputs_hash: String,
    /// When the row was last inserted or changed by an import (UTC, ISO 8601).
    pub imported_at: String,
    /// The measurements, sorted by increasing ω.
    pub measurements: Vec<MeasurementRecord>,
}

/// One row of `measurements`: a field wavenumber at one frequency.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementRecord {
    /// Angular frequency ω, rad/s.
    pub omega_rad_s: f64,
    /// Frequency f = ω/2π, Hz.
    pub frequency_hz: f64,
    /// Re k, rad/m (> 0).
    pub k_re_rad_per_m: f64,
    /// Decay rate, Np/m (≥ 0; the model's Im k is its negative).
    pub attenuation_np_per_m: f64,
    /// One standard deviation of Re k, rad/m.
    pub k_re_std: Option<f64>,
    /// One standard deviation of the attenuation, Np/m.
    pub attenuation_std: Option<f64>,
    /// Date of measurement, `YYYY-MM-DD`.
    pub measured_on: Option<String>,
    /// Campaign name ([`UNNAMED_CAMPAIGN`] when the file gave none; `None` only in records
    /// not yet stored).
    pub campaign: Option<String>,
    /// What the wavenumber estimate says of the band (`reflection_suspected`, ...), if anything.
    pub note: Option<String>,
}

/// The campaign of measurements given without one: re-importing such a file updates its rows
/// and adds nothing.
pub const UNNAMED_CAMPAIGN: &str = "unnamed";

impl SegmentRecord {
    /// A segment of the given pipe and soil density with the material's typical properties,
    /// water, no informational columns, no geometry and no measurements (set those by struct
    /// update).
    pub fn new(
        segment_id: &str,
        material: Material,
        outer_diameter_mm: f64,
        wall_thickness_mm: f64,
        soil_density_kg_m3: f64,
    ) -> SegmentRecord {
        SegmentRecord {
            segment_id: segment_id.to_string(),
            material,
            outer_diameter_mm,
            wall_thickness_mm,
            soil_density_kg_m3,
            pipe_youngs_modulus_pa: None,
            pipe_poisson: None,
            pipe_density_kg_m3: None,
            pipe_loss_factor: None,
            fluid_density_kg_m3: None,
            fluid_bulk_modulus_pa: None,
            length_m: None,
            soil_type: None,
            install_year: None,
            soil_zone: None,
            risk_weight: None,
            soil_class_override: None,
            geometry_wkt: None,
            srid: None,
            inputs_hash: String::new(),
            imported_at: String::new(),
            measurements: Vec::new(),
        }
    }

    /// The material's typical properties (model §3.3) with this row's overrides.
    pub fn pipe_props(&self) -> MaterialProps {
        let mut p = self.material.typical();
        if let Some(v) = self.pipe_youngs_modulus_pa {
            p.youngs_modulus = v;
        }
        if let Some(v) = self.pipe_poisson {
            p.poisson = v;
        }
        if let Some(v) = self.pipe_density_kg_m3 {
            p.density = v;
        }
        if let Some(v) = self.pipe_loss_factor {
            p.loss_factor = v;
        }
        p
    }

    /// The checked pipe: mean radius a = (D_o − h)/2 (eq. P6), converted from mm to m.
    pub fn pipe(&self) -> Result<Pipe, InputError> {
        Pipe::from_outside_diameter(
            self.pipe_props(),
            self.outer_diameter_mm * M_PER_MM,
            self.wall_thickness_mm * M_PER_MM,
        )
    }

    /// The checked fluid: the row's values, water where blank.
    pub fn fluid(&self) -> Result<Fluid, InputError> {
        Fluid::new(
            self.fluid_density_kg_m3.unwrap_or(WATER_DENSITY),
            self.fluid_bulk_modulus_pa.unwrap_or(WATER_BULK_MODULUS),
        )
    }

    /// The soil density ρ_m, kg/m³, checked against model §3.1.
    pub fn soil_density(&self) -> Result<f64, InputError> {
        SOIL_DENSITY_RANGE.check(self.soil_density_kg_m3)
    }

    /// True when the inventory columns (everything but measurements, hash and import time)
    /// equal those of `other`.
    pub(crate) fn same_inventory(&self, other: &SegmentRecord) -> bool {
        self.segment_id == other.segment_id
            && self.material == other.material
            && self.outer_diameter_mm == other.outer_diameter_mm
            && self.wall_thickness_mm == other.wall_thickness_mm
            && self.soil_density_kg_m3 == other.soil_density_kg_m3
            && self.pipe_youngs_modulus_pa == other.pipe_youngs_modulus_pa
            && self.pipe_poisson == other.pipe_poisson
            && self.pipe_density_kg_m3 == other.pipe_density_kg_m3
            && self.pipe_loss_factor == other.pipe_loss_factor
            && self.fluid_density_kg_m3 == other.fluid_density_kg_m3
            && self.fluid_bulk_modulus_pa == other.fluid_bulk_modulus_pa
            && self.length_m == other.length_m
            && self.soil_type == other.soil_type
            && self.install_year == other.install_year
            && self.soil_zone == other.soil_zone
            && self.risk_weight == other.risk_weight
            && self.soil_class_override == other.soil_class_override
            && self.geometry_wkt == other.geometry_wkt
            && self.srid == other.srid
    }
}

pub(crate) const SEGMENT_COLUMNS: &str =
    "segment_id, material, outer_diameter_mm, wall_thickness_mm, \
    soil_density_kg_m3, pipe_youngs_modulus_pa, pipe_poisson, pipe_density_kg_m3, \
    pipe_loss_factor, fluid_density_kg_m3, fluid_bulk_modulus_pa, length_m, soil_type, \
    install_year, geometry_wkt, srid, inputs_hash, imported_at, soil_zone, risk_weight, \
    soil_class_override";

pub(crate) const MEASUREMENT_COLUMNS: &str = "omega_rad_s, frequency_hz, k_re_rad_per_m, \
    attenuation_np_per_m, k_re_std, attenuation_std, measured_on, campaign, note";
/// How many columns [`MEASUREMENT_COLUMNS`] names.
pub(crate) const MEASUREMENT_WIDTH: usize = 9;

/// A segment row without its measurements; the material is parsed afterwards.
pub(crate) fn segment_from_row(r: &Row<'_>) -> rusqlite::Result<(SegmentRecord, String)> {
    let material: String = r.get(1)?;
    Ok((
        SegmentRecord {
            segment_id: r.get(0)?,
            // Placeholder until the text is checked by the caller (no panics on odd data).
            material: Material::CastIron,
            outer_diameter_mm: r.get(2)?,
            wall_thickness_mm: r.get(3)?,
            soil_density_kg_m3: r.get(4)?,
            pipe_youngs_modulus_pa: r.get(5)?,
            pipe_poisson: r.get(6)?,
            pipe_density_kg_m3: r.get(7)?,
            pipe_loss_factor: r.get(8)?,
            fluid_density_kg_m3: r.get(9)?,
            fluid_bulk_modulus_pa: r.get(10)?,
            length_m: r.get(11)?,
            soil_type: r.get(12)?,
            install_year: r.get(13)?,
            geometry_wkt: r.get(14)?,
            srid: r.get(15)?,
            inputs_hash: r.get(16)?,
            imported_at: r.get(17)?,
            soil_zone: r.get(18)?,
            risk_weight: r.get(19)?,
            soil_class_override: r.get(20)?,
            measurements: Vec::new(),
        },
        material,
    ))
}

pub(crate) fn measurement_from_row(r: &Row<'_>) -> rusqlite::Result<MeasurementRecord> {
    Ok(MeasurementRecord {
        omega_rad_s: r.get(0)?,
        frequency_hz: r.get(1)?,
        k_re_rad_per_m: r.get(2)?,
        attenuation_np_per_m: r.get(3)?,
        k_re_std: r.get(4)?,
        attenuation_std: r.get(5)?,
        measured_on: r.get(6)?,
        campaign: r.get(7)?,
        note: r.get(8)?,
    })
}

/// Parse the material of a row read by [`segment_from_row`] and attach its measurements.
pub(crate) fn finish_segment(
    conn: &Connection,
    (mut seg, material): (SegmentRecord, String),
) -> Result<SegmentRecord, DbError> {
    seg.material = material
        .parse()
        .map_err(|e: InputError| DbError::BadStoredValue {
            what: format!("segment {}: {e}", seg.segment_id),
        })?;
    seg.measurements = load_measurements(conn, &seg.segment_id)?;
    Ok(seg)
}

/// The measurements of one segment's current state, sorted by ω: those of its latest
/// campaign ([`campaigns_of`]). A fit uses these; the earlier campaigns stay stored.
pub fn load_measurements(
    conn: &Connection,
    segment_id: &str,
) -> Result<Vec<MeasurementRecord>, DbError> {
    let Some(latest) = campaigns_of(conn, segment_id)?.pop() else {
        return Ok(Vec::new());
    };
    load_campaign(conn, segment_id, &latest.name)
}

/// The measurements of one segment in one campaign, sorted by ω.
pub fn load_campaign(
    conn: &Connection,
    segment_id: &str,
    campaign: &str,
) -> Result<Vec<MeasurementRecord>, DbError> {
    let mut stmt = conn.prepare_cached(&format!(
        "SELECT {MEASUREMENT_COLUMNS} FROM measurements WHERE segment_id = ?1 AND campaign = ?2 \
         ORDER BY omega_rad_s"
    ))?;
    let rows = stmt.query_map(params![segment_id, campaign], measurement_from_row)?;
    Ok(rows.collect::<Result<_, _>>()?)
}

/// Every stored measurement of one segment, of every campaign, by campaign (in
/// [`campaigns_of`]'s order) and ω.
pub fn load_all_measurements(
    conn: &Connection,
    segment_id: &str,
) -> Result<Vec<MeasurementRecord>, DbError> {
    let mut out = Vec::new();
    for c in campaigns_of(conn, segment_id)? {
        out.extend(load_campaign(conn, segment_id, &c.name)?);
    }
    Ok(out)
}

/// One campaign of one segment, as [`campaigns_of`] orders them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CampaignOfSegment {
    /// The campaign's name.
    pub name: String,
    /// Its newest `measured_on` on this segment, if any row has one.
    pub newest_measured_on: Option<String>,
    /// Its rows on this segment.
    pub rows: usize,
    /// Its smallest row id on this segment: rows keep their id when a campaign is imported
    /// again, so this is the order in which the segment's campaigns were first imported.
    pub first_row_id: i64,
}

/// The campaigns a segment was measured in, oldest first, so the last is its latest. When every
/// one of them has a date the order is that of their newest `measured_on` (then of import);
/// otherwise it is the order in which they were first imported. A segment whose rows are dated
/// in one campaign and not in another is therefore ordered by import, which never reorders a
/// history as dates are filled in one campaign at a time.
pub fn campaigns_of(
    conn: &Connection,
    segment_id: &str,
) -> Result<Vec<CampaignOfSegment>, DbError> {
    let mut stmt = conn.prepare_cached(
        "SELECT campaign, MAX(measured_on), COUNT(*), MIN(id) FROM measurements \
         WHERE segment_id = ?1 GROUP BY campaign",
    )?;
    let mut out: Vec<CampaignOfSegment> = stmt
        .query_map([segment_id], |r| {
            Ok(CampaignOfSegment {
                name: r.get(0)?,
                newest_measured_on: r.get(1)?,
                rows: usize::try_from(r.get::<_, i64>(2)?).unwrap_or(usize::MAX),
                first_row_id: r.get(3)?,
            })
        })?
        .collect::<Result<_, _>>()?;
    if out.iter().all(|c| c.newest_measured_on.is_some()) {
        out.sort_by(|a, b| {
            a.newest_measured_on
                .cmp(&b.newest_measured_on)
                .then(a.first_row_id.cmp(&b.first_row_id))
        });
    } else {
        out.sort_by_key(|c| c.first_row_id);
    }
    Ok(out)
}

/// One segment with its measurements, or `None` if it is not in the inventory.
pub fn load_segment(conn: &Connection, segment_id: &str) -> Result<Option<SegmentRecord>, DbError> {
    let row = conn
        .prepare_cached(&format!(
            "SELECT {SEGMENT_COLUMNS} FROM segments WHERE segment_id = ?1"
        ))?
        .query_row([segment_id], segment_from_row)
        .optional()?;
    row.map(|r| finish_segment(conn, r)).transpose()
}

/// Segments with their measurements, sorted by id: all of them (`ids = None`) or those listed.
/// Listing an id that is not in the inventory is an error naming every such id.
pub fn load_segments(
    conn: &Connection,
    ids: Option<&[String]>,
) -> Result<Vec<SegmentRecord>, DbError> {
    match ids {
        None => {
            let mut stmt = conn.prepare(&format!(
                "SELECT {SEGMENT_COLUMNS} FROM segments ORDER BY segment_id"
            ))?;
            let rows: Vec<_> = stmt
                .query_map([], segment_from_row)?
                .collect::<Result<_, _>>()?;
            rows.into_iter().map(|r| finish_segment(conn, r)).collect()
        }
        Some(ids) => {
            let wanted: BTreeSet<&String> = ids.iter().collect();
            let mut out = Vec::with_capacity(wanted.len());
            let mut missing = Vec::new();
            for id in wanted {
                match load_segment(conn, id)? {
                    Some(s) => out.push(s),
                    None => missing.push(id.as_str()),
                }
            }
            if !missing.is_empty() {
                return Err(DbError::UnknownSegments {
                    ids: missing.join(", "),
                });
            }
            Ok(out)
        }
    }
}

/// The segments that may lie in a soil zone (`soil_zone` holds more than spaces), with their
/// measurements, sorted by id. Reads only those: asking costs nothing on a network without
/// zones.
pub fn load_zoned_segments(conn: &Connection) -> Result<Vec<SegmentRecord>, DbError> {
    let mut stmt = conn.prepare(&format!(
        "SELECT {SEGMENT_COLUMNS} FROM segments WHERE trim(soil_zone) != '' \
         ORDER BY segment_id"
    ))?;
    let rows: Vec<_> = stmt
        .query_map([], segment_from_row)?
        .collect::<Result<_, _>>()?;
    rows.into_iter().map(|r| finish_segment(conn, r)).collect()
}

/// Insert a new segment row (without measurements; `inputs_hash` as given).
pub(crate) fn insert_segment(conn: &Connection, s: &SegmentRecord) -> Result<(), DbError> {
    conn.prepare_cached(
        "INSERT INTO segments (segment_id, material, outer_diameter_mm, wall_thickness_mm, \
         soil_density_kg_m3, pipe_youngs_modulus_pa, pipe_poisson, pipe_density_kg_m3, \
         pipe_loss_factor, fluid_density_kg_m3, fluid_bulk_modulus_pa, length_m, soil_type, \
         install_year, geometry_wkt, srid, inputs_hash, soil_zone, risk_weight, \
         soil_class_override) \
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, ?18, \
         ?19, ?20)",
    )?
    .execute(params![
        s.segment_id,
        s.material.code(),
        s.outer_diameter_mm,
        s.wall_thickness_mm,
        s.soil_density_kg_m3,
        s.pipe_youngs_modulus_pa,
        s.pipe_poisson,
        s.pipe_density_kg_m3,
        s.pipe_loss_factor,
        s.fluid_density_kg_m3,
        s.fluid_bulk_modulus_pa,
        s.length_m,
        s.soil_type,
        s.install_year,
        s.geometry_wkt,
        s.srid,
        s.inputs_hash,
        s.soil_zone,
        s.risk_weight,
        s.soil_class_override,
    ])?;
    Ok(())
}

/// The inventory columns of `s` as SQL values: segment id, material, outside diameter, wall,
/// soil density, the pipe and water overrides, length, soil type, install year, geometry, SRID,
/// soil zone, risk weight and soil class override (the order of [`update_segment`]'s parameters
/// ?1–?19 and of the import's staging table).
pub(crate) fn inventory_values(s: &SegmentRecord) -> [rusqlite::types::Value; 19] {
    use rusqlite::types::Value;
    [
        Value::from(s.segment_id.clone()),
        Value::from(s.material.code().to_string()),
        Value::from(s.outer_diameter_mm),
        Value::from(s.wall_thickness_mm),
        Value::from(s.soil_density_kg_m3),
        Value::from(s.pipe_youngs_modulus_pa),
        Value::from(s.pipe_poisson),
        Value::from(s.pipe_density_kg_m3),
        Value::from(s.pipe_loss_factor),
        Value::from(s.fluid_density_kg_m3),
        Value::from(s.fluid_bulk_modulus_pa),
        Value::from(s.length_m),
        Value::from(s.soil_type.clone()),
        Value::from(s.install_year),
        Value::from(s.geometry_wkt.clone()),
        Value::from(s.srid),
        Value::from(s.soil_zone.clone()),
        Value::from(s.risk_weight),
        Value::from(s.soil_class_override.clone()),
    ]
}

/// Overwrite the inventory columns of an existing segment and stamp `imported_at`.
pub(crate) fn update_segment(conn: &Connection, s: &SegmentRecord) -> Result<(), DbError> {
    conn.prepare_cached(
        "UPDATE segments SET material = ?2, outer_diameter_mm = ?3, wall_thickness_mm = ?4, \
         soil_density_kg_m3 = ?5, pipe_youngs_modulus_pa = ?6, pipe_poisson = ?7, \
         pipe_density_kg_m3 = ?8, pipe_loss_factor = ?9, fluid_density_kg_m3 = ?10, \
         fluid_bulk_modulus_pa = ?11, length_m = ?12, soil_type = ?13, install_year = ?14, \
         geometry_wkt = ?15, srid = ?16, soil_zone = ?17, risk_weight = ?18, \
         soil_class_override = ?19, \
         imported_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now') \
         WHERE segment_id = ?1",
    )?
    .execute(rusqlite::params_from_iter(inventory_values(s)))?;
    Ok(())
}

/// What storing one segment's rows of one campaign did ([`store_campaign`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct CampaignWrite {
    /// Rows at a frequency the campaign did not have for the segment.
    pub added: usize,
    /// Rows at a frequency it had, with other values.
    pub updated: usize,
    /// Rows it had that are unchanged, or not in the file and kept.
    pub kept: usize,
    /// Rows it had that are not in the file and were removed (`replace`).
    pub removed: usize,
}

/// Store one segment's rows of one campaign: a row at a frequency (within `same_frequency`) the
/// campaign already has for the segment updates that row in place, keeping its id; another row
/// is added. The campaign's stored rows missing from `ms` are kept, or removed with `replace`.
/// Other campaigns are never touched.
pub(crate) fn store_campaign(
    conn: &Connection,
    segment_id: &str,
    campaign: &str,
    ms: &[MeasurementRecord],
    replace: bool,
    same_frequency: impl Fn(f64, f64) -> bool,
) -> Result<CampaignWrite, DbError> {
    let stored: Vec<(i64, MeasurementRecord)> = {
        let mut stmt = conn.prepare_cached(&format!(
            "SELECT {MEASUREMENT_COLUMNS}, id FROM measurements WHERE segment_id = ?1 \
             AND campaign = ?2 ORDER BY omega_rad_s"
        ))?;
        let rows = stmt.query_map(params![segment_id, campaign], |r| {
            Ok((r.get(MEASUREMENT_WIDTH)?, measurement_from_row(r)?))
        })?;
        rows.collect::<Result<_, _>>()?
    };
    let mut w = CampaignWrite::default();
    let mut matched = vec![false; stored.len()];
    for m in ms {
        let at = stored
            .iter()
            .position(|(_, s)| same_frequency(s.omega_rad_s, m.omega_rad_s));
        match at {
            Some(i) => {
                matched[i] = true;
                let (id, old) = &stored[i];
                let mut new = m.clone();
                new.campaign = Some(campaign.to_string());
                if *old == new {
                    w.kept += 1;
                    continue;
                }
                conn.prepare_cached(
                    "UPDATE measurements SET omega_rad_s = ?2, frequency_hz = ?3, \
                     k_re_rad_per_m = ?4, attenuation_np_per_m = ?5, k_re_std = ?6, \
                     attenuation_std = ?7, measured_on = ?8, note = ?9 WHERE id = ?1",
                )?
                .execute(params![
                    id,
                    m.omega_rad_s,
                    m.frequency_hz,
                    m.k_re_rad_per_m,
                    m.attenuation_np_per_m,
                    m.k_re_std,
                    m.attenuation_std,
                    m.measured_on,
                    m.note,
                ])?;
                w.updated += 1;
            }
            None => {
                conn.prepare_cached(
                    "INSERT INTO measurements (segment_id, campaign, omega_rad_s, frequency_hz, \
                     k_re_rad_per_m, attenuation_np_per_m, k_re_std, attenuation_std, \
                     measured_on, note) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10)",
                )?
                .execute(params![
                    segment_id,
                    campaign,
                    m.omega_rad_s,
                    m.frequency_hz,
                    m.k_re_rad_per_m,
                    m.attenuation_np_per_m,
                    m.k_re_std,
                    m.attenuation_std,
                    m.measured_on,
                    m.note,
                ])?;
                w.added += 1;
            }
        }
    }
    for ((id, _), hit) in stored.iter().zip(&matched) {
        if *hit {
            continue;
        }
        if replace {
            conn.prepare_cached("DELETE FROM measurements WHERE id = ?1")?
                .execute([id])?;
            w.removed += 1;
        } else {
            w.kept += 1;
        }
    }
    Ok(w)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> SegmentRecord {
        SegmentRecord {
            length_m: Some(120.0),
            soil_type: Some("clay".into()),
            install_year: Some(1975),
            soil_zone: Some("Z1".into()),
            measurements: vec![MeasurementRecord {
                omega_rad_s: 2.0 * std::f64::consts::PI * 100.0,
                frequency_hz: 100.0,
                k_re_rad_per_m: 0.5,
                attenuation_np_per_m: 0.01,
                k_re_std: Some(0.01),
                attenuation_std: None,
                measured_on: Some("2024-05-01".into()),
                campaign: None,
                note: None,
            }],
            ..SegmentRecord::new("P-1", Material::DuctileIron, 170.0, 6.0, 1900.0)
        }
    }

    #[test]
    fn pipe_uses_mean_radius_in_metres_and_material_defaults_eq_p6() {
        let s = sample();
        let p = s.pipe().unwrap();
        assert!((p.mean_radius - 0.082).abs() < 1e-12, "{}", p.mean_radius);
        assert!((p.wall_thickness - 0.006).abs() < 1e-15);
        assert_eq!(
            p.youngs_modulus,
            Material::DuctileIron.typical().youngs_modulus
        );
        let mut o = s.clone();
        o.pipe_youngs_modulus_pa = Some(1.6e11);
        o.pipe_loss_factor = Some(0.02);
        let p = o.pipe().unwrap();
        assert_eq!((p.youngs_modulus, p.loss_factor), (1.6e11, 0.02));
        assert_eq!(s.fluid().unwrap(), Fluid::water());
        assert_eq!(s.soil_density().unwrap(), 1900.0);
        o.soil_density_kg_m3 = 900.0;
        assert!(o.soil_density().is_err());
    }
}
