//! The imported inventory: segments and their measurements, as stored, and as the checked physics
//! inputs the calibration needs.

use std::collections::BTreeSet;

use rusqlite::{params, Connection, OptionalExtension, Row};

use super::hash::Canonical;
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
    /// Hash of everything a fit depends on ([`SegmentRecord::compute_inputs_hash`]), as stored.
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
    /// Campaign name.
    pub campaign: Option<String>,
}

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

    /// The canonical text of everything a fit of this segment depends on: the id, the pipe,
    /// fluid and soil columns, and each measurement's ω, Re k, attenuation and standard
    /// deviations in order of ω. Informational columns (length, soil type, install year,
    /// geometry, dates, campaign) are left out, so correcting them does not trigger a refit.
    pub fn canonical_inputs(&self) -> String {
        let mut c = Canonical::new("pipewave-inputs-v1");
        c.text("segment_id", Some(&self.segment_id))
            .text("material", Some(self.material.code()))
            .num("outer_diameter_mm", Some(self.outer_diameter_mm))
            .num("wall_thickness_mm", Some(self.wall_thickness_mm))
            .num("soil_density_kg_m3", Some(self.soil_density_kg_m3))
            .num("pipe_youngs_modulus_pa", self.pipe_youngs_modulus_pa)
            .num("pipe_poisson", self.pipe_poisson)
            .num("pipe_density_kg_m3", self.pipe_density_kg_m3)
            .num("pipe_loss_factor", self.pipe_loss_factor)
            .num("fluid_density_kg_m3", self.fluid_density_kg_m3)
            .num("fluid_bulk_modulus_pa", self.fluid_bulk_modulus_pa)
            .int(
                "measurements",
                Some(i64::try_from(self.measurements.len()).unwrap_or(i64::MAX)),
            );
        let mut ms: Vec<&MeasurementRecord> = self.measurements.iter().collect();
        ms.sort_by(|a, b| a.omega_rad_s.total_cmp(&b.omega_rad_s));
        for m in ms {
            c.num("omega_rad_s", Some(m.omega_rad_s))
                .num("k_re_rad_per_m", Some(m.k_re_rad_per_m))
                .num("attenuation_np_per_m", Some(m.attenuation_np_per_m))
                .num("k_re_std", m.k_re_std)
                .num("attenuation_std", m.attenuation_std);
        }
        c.as_str().to_string()
    }

    /// FNV-1a 64 of [`SegmentRecord::canonical_inputs`], 16 hex digits.
    pub fn compute_inputs_hash(&self) -> String {
        super::hash::fnv1a64_hex(&self.canonical_inputs())
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
    attenuation_np_per_m, k_re_std, attenuation_std, measured_on, campaign";

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

/// The measurements of one segment, sorted by ω.
pub fn load_measurements(
    conn: &Connection,
    segment_id: &str,
) -> Result<Vec<MeasurementRecord>, DbError> {
    let mut stmt = conn.prepare_cached(&format!(
        "SELECT {MEASUREMENT_COLUMNS} FROM measurements WHERE segment_id = ?1 ORDER BY omega_rad_s"
    ))?;
    let rows = stmt.query_map([segment_id], measurement_from_row)?;
    Ok(rows.collect::<Result<_, _>>()?)
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

/// Replace the measurement set of a segment.
pub(crate) fn replace_measurements(
    conn: &Connection,
    segment_id: &str,
    ms: &[MeasurementRecord],
) -> Result<(), DbError> {
    conn.prepare_cached("DELETE FROM measurements WHERE segment_id = ?1")?
        .execute([segment_id])?;
    let mut ins = conn.prepare_cached(
        "INSERT INTO measurements (segment_id, omega_rad_s, frequency_hz, k_re_rad_per_m, \
         attenuation_np_per_m, k_re_std, attenuation_std, measured_on, campaign) \
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)",
    )?;
    for m in ms {
        ins.execute(params![
            segment_id,
            m.omega_rad_s,
            m.frequency_hz,
            m.k_re_rad_per_m,
            m.attenuation_np_per_m,
            m.k_re_std,
            m.attenuation_std,
            m.measured_on,
            m.campaign,
        ])?;
    }
    Ok(())
}

/// Recompute and store a segment's `inputs_hash` from what is in the database now. Returns true
/// when the stored hash changed.
pub(crate) fn refresh_inputs_hash(conn: &Connection, segment_id: &str) -> Result<bool, DbError> {
    let Some(seg) = load_segment(conn, segment_id)? else {
        return Ok(false);
    };
    let hash = seg.compute_inputs_hash();
    if hash == seg.inputs_hash {
        return Ok(false);
    }
    conn.prepare_cached("UPDATE segments SET inputs_hash = ?2 WHERE segment_id = ?1")?
        .execute(params![segment_id, hash])?;
    Ok(true)
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

    #[test]
    fn inputs_hash_ignores_informational_columns_but_not_inputs() {
        let s = sample();
        let h = s.compute_inputs_hash();
        assert_eq!(h.len(), 16);
        let mut info = s.clone();
        info.length_m = Some(99.0);
        info.soil_type = None;
        info.measurements[0].campaign = Some("spring".into());
        assert_eq!(info.compute_inputs_hash(), h);
        let mut k = s.clone();
        k.measurements[0].k_re_rad_per_m = 0.5000000001;
        assert_ne!(k.compute_inputs_hash(), h);
        let mut std = s.clone();
        std.measurements[0].attenuation_std = Some(0.001);
        assert_ne!(std.compute_inputs_hash(), h);
        let mut wall = s;
        wall.wall_thickness_mm = 6.5;
        assert_ne!(wall.compute_inputs_hash(), h);
    }

    /// The stored hashes must not change between program versions, or every segment would be
    /// refitted after an upgrade. Value computed once from the canonical text (and checked
    /// independently with a 5-line Python FNV-1a); change it only with a new version tag.
    #[test]
    fn inputs_hash_is_pinned() {
        let s = sample();
        assert!(s
            .canonical_inputs()
            .contains("\nomega_rad_s=f:6.283185307179587e2\nk_re_rad_per_m=f:5e-1\n"));
        assert_eq!(s.compute_inputs_hash(), "0287f9d1471f32b9");
    }

    #[test]
    fn inputs_hash_does_not_depend_on_measurement_order() {
        let mut s = sample();
        let mut m2 = s.measurements[0].clone();
        m2.omega_rad_s *= 2.0;
        m2.frequency_hz *= 2.0;
        s.measurements.push(m2);
        let h = s.compute_inputs_hash();
        s.measurements.reverse();
        assert_eq!(s.compute_inputs_hash(), h);
    }
}
