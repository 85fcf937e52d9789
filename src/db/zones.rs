//! Soil-zone estimates (`zone_fits`, `zone_members`, migration 0005; model §7.11): insert and
//! read by column name.

use rusqlite::{params, Connection, OptionalExtension, Row};

use super::DbError;

/// One row of `zone_fits`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ZoneFitRow {
    /// Row id (`None` before insertion).
    pub id: Option<i64>,
    /// The zone.
    pub soil_zone: String,
    /// The calibrate run that made it (`None`: made outside a run).
    pub run_id: Option<i64>,
    /// Members with a fit (outliers included).
    pub n_segments: i64,
    /// Members left out as inconsistent with the zone.
    pub n_outliers: i64,
    /// Zone E_m, Pa, and its 95 % interval.
    pub soil_youngs_modulus_pa: Option<f64>,
    /// Lower end.
    pub soil_youngs_modulus_lo_pa: Option<f64>,
    /// Upper end.
    pub soil_youngs_modulus_hi_pa: Option<f64>,
    /// Zone ν_m and its 95 % interval.
    pub soil_poisson: Option<f64>,
    /// Lower end.
    pub soil_poisson_lo: Option<f64>,
    /// Upper end.
    pub soil_poisson_hi: Option<f64>,
    /// The members' mean soil density, kg/m³ (the speeds are given at it).
    pub soil_density_kg_m3: Option<f64>,
    /// Zone c_P, m/s, and its 95 % interval.
    pub soil_p_wave_speed_m_per_s: Option<f64>,
    /// Lower end.
    pub soil_p_wave_speed_lo_m_per_s: Option<f64>,
    /// Upper end.
    pub soil_p_wave_speed_hi_m_per_s: Option<f64>,
    /// Zone c_S, m/s, and its 95 % interval.
    pub soil_s_wave_speed_m_per_s: Option<f64>,
    /// Lower end.
    pub soil_s_wave_speed_lo_m_per_s: Option<f64>,
    /// Upper end.
    pub soil_s_wave_speed_hi_m_per_s: Option<f64>,
    /// Scatter of log10 E_m between members, decades.
    pub scatter_youngs_modulus_decades: f64,
    /// Scatter of ν_m between members.
    pub scatter_poisson: f64,
    /// `fixed` or `estimated`.
    pub scatter_source: String,
    /// The zone's χ²/dof.
    pub chi2_per_dof: Option<f64>,
    /// Comma-separated flag codes.
    pub flags: String,
    /// Comma-separated ids of the segments that disagree with the zone.
    pub outliers: String,
    /// One line per outlier: its evidence.
    pub outlier_reasons: String,
    /// Hash of the member fits (`segment_id:fit_id`, sorted).
    pub members_hash: String,
    /// Time of the estimate, ms.
    pub elapsed_ms: Option<f64>,
    /// When it was stored.
    pub created_at: Option<String>,
}

/// One row of `zone_members`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ZoneMemberRow {
    /// The segment.
    pub segment_id: String,
    /// Its fit the zone was made from.
    pub fit_id: i64,
    /// E_m shrunk toward the zone, Pa.
    pub shrunk_soil_youngs_modulus_pa: Option<f64>,
    /// ν_m shrunk toward the zone.
    pub shrunk_soil_poisson: Option<f64>,
    /// Its misfit at the zone with the scatter allowed for (χ²₂ under the model).
    pub statistic: Option<f64>,
    /// Left out as inconsistent with the zone.
    pub zone_outlier: bool,
}

/// Store one zone estimate and its members; returns the new `zone_fits` id.
pub fn insert_zone_fit(
    conn: &mut Connection,
    z: &ZoneFitRow,
    members: &[ZoneMemberRow],
) -> Result<i64, DbError> {
    let tx = conn.transaction()?;
    tx.execute(
        "INSERT INTO zone_fits (soil_zone, run_id, n_segments, n_outliers, \
         soil_youngs_modulus_pa, soil_youngs_modulus_lo_pa, soil_youngs_modulus_hi_pa, \
         soil_poisson, soil_poisson_lo, soil_poisson_hi, soil_density_kg_m3, \
         soil_p_wave_speed_m_per_s, soil_p_wave_speed_lo_m_per_s, soil_p_wave_speed_hi_m_per_s, \
         soil_s_wave_speed_m_per_s, soil_s_wave_speed_lo_m_per_s, soil_s_wave_speed_hi_m_per_s, \
         scatter_youngs_modulus_decades, scatter_poisson, scatter_source, chi2_per_dof, flags, \
         outliers, outlier_reasons, members_hash, elapsed_ms) VALUES (?1, ?2, ?3, ?4, ?5, ?6, \
         ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, ?18, ?19, ?20, ?21, ?22, ?23, ?24, \
         ?25, ?26)",
        params![
            z.soil_zone,
            z.run_id,
            z.n_segments,
            z.n_outliers,
            z.soil_youngs_modulus_pa,
            z.soil_youngs_modulus_lo_pa,
            z.soil_youngs_modulus_hi_pa,
            z.soil_poisson,
            z.soil_poisson_lo,
            z.soil_poisson_hi,
            z.soil_density_kg_m3,
            z.soil_p_wave_speed_m_per_s,
            z.soil_p_wave_speed_lo_m_per_s,
            z.soil_p_wave_speed_hi_m_per_s,
            z.soil_s_wave_speed_m_per_s,
            z.soil_s_wave_speed_lo_m_per_s,
            z.soil_s_wave_speed_hi_m_per_s,
            z.scatter_youngs_modulus_decades,
            z.scatter_poisson,
            z.scatter_source,
            z.chi2_per_dof,
            z.flags,
            z.outliers,
            z.outlier_reasons,
            z.members_hash,
            z.elapsed_ms,
        ],
    )?;
    let id = tx.last_insert_rowid();
    {
        let mut stmt = tx.prepare(
            "INSERT INTO zone_members (zone_fit_id, segment_id, fit_id, \
             shrunk_soil_youngs_modulus_pa, shrunk_soil_poisson, statistic, zone_outlier) \
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
        )?;
        for m in members {
            stmt.execute(params![
                id,
                m.segment_id,
                m.fit_id,
                m.shrunk_soil_youngs_modulus_pa,
                m.shrunk_soil_poisson,
                m.statistic,
                m.zone_outlier,
            ])?;
        }
    }
    tx.commit()?;
    Ok(id)
}

fn zone_from_row(r: &Row<'_>) -> rusqlite::Result<ZoneFitRow> {
    Ok(ZoneFitRow {
        id: Some(r.get("id")?),
        soil_zone: r.get("soil_zone")?,
        run_id: r.get("run_id")?,
        n_segments: r.get("n_segments")?,
        n_outliers: r.get("n_outliers")?,
        soil_youngs_modulus_pa: r.get("soil_youngs_modulus_pa")?,
        soil_youngs_modulus_lo_pa: r.get("soil_youngs_modulus_lo_pa")?,
        soil_youngs_modulus_hi_pa: r.get("soil_youngs_modulus_hi_pa")?,
        soil_poisson: r.get("soil_poisson")?,
        soil_poisson_lo: r.get("soil_poisson_lo")?,
        soil_poisson_hi: r.get("soil_poisson_hi")?,
        soil_density_kg_m3: r.get("soil_density_kg_m3")?,
        soil_p_wave_speed_m_per_s: r.get("soil_p_wave_speed_m_per_s")?,
        soil_p_wave_speed_lo_m_per_s: r.get("soil_p_wave_speed_lo_m_per_s")?,
        soil_p_wave_speed_hi_m_per_s: r.get("soil_p_wave_speed_hi_m_per_s")?,
        soil_s_wave_speed_m_per_s: r.get("soil_s_wave_speed_m_per_s")?,
        soil_s_wave_speed_lo_m_per_s: r.get("soil_s_wave_speed_lo_m_per_s")?,
        soil_s_wave_speed_hi_m_per_s: r.get("soil_s_wave_speed_hi_m_per_s")?,
        scatter_youngs_modulus_decades: r.get("scatter_youngs_modulus_decades")?,
        scatter_poisson: r.get("scatter_poisson")?,
        scatter_source: r.get("scatter_source")?,
        chi2_per_dof: r.get("chi2_per_dof")?,
        flags: r.get("flags")?,
        outliers: r.get("outliers")?,
        outlier_reasons: r.get("outlier_reasons")?,
        members_hash: r.get("members_hash")?,
        elapsed_ms: r.get("elapsed_ms")?,
        created_at: r.get("created_at")?,
    })
}

/// The newest estimate of every zone, sorted by zone.
pub fn latest_zone_fits(conn: &Connection) -> Result<Vec<ZoneFitRow>, DbError> {
    let mut stmt = conn.prepare(
        "SELECT * FROM zone_fits z WHERE z.id = \
         (SELECT MAX(y.id) FROM zone_fits y WHERE y.soil_zone = z.soil_zone) \
         ORDER BY soil_zone",
    )?;
    let rows = stmt.query_map([], zone_from_row)?;
    Ok(rows.collect::<Result<_, _>>()?)
}

/// The zones the inventory declares (`soil_zone`, trimmed, non-empty), sorted, each with
/// whether it has a stored estimate.
pub fn declared_zones(conn: &Connection) -> Result<Vec<(String, bool)>, DbError> {
    let mut stmt = conn.prepare(
        "SELECT z, EXISTS (SELECT 1 FROM zone_fits f WHERE f.soil_zone = z) FROM \
         (SELECT DISTINCT TRIM(soil_zone) AS z FROM segments \
          WHERE soil_zone IS NOT NULL AND TRIM(soil_zone) <> '') ORDER BY z",
    )?;
    let rows = stmt.query_map([], |r| Ok((r.get(0)?, r.get(1)?)))?;
    Ok(rows.collect::<Result<_, _>>()?)
}

/// The newest estimate of one zone.
pub fn latest_zone_fit(conn: &Connection, zone: &str) -> Result<Option<ZoneFitRow>, DbError> {
    Ok(conn
        .query_row(
            "SELECT * FROM zone_fits WHERE soil_zone = ?1 ORDER BY id DESC LIMIT 1",
            [zone],
            zone_from_row,
        )
        .optional()?)
}

/// The members of one zone estimate, sorted by segment.
pub fn zone_members(conn: &Connection, zone_fit_id: i64) -> Result<Vec<ZoneMemberRow>, DbError> {
    let mut stmt =
        conn.prepare("SELECT * FROM zone_members WHERE zone_fit_id = ?1 ORDER BY segment_id")?;
    let rows = stmt.query_map([zone_fit_id], member_from_row)?;
    Ok(rows.collect::<Result<_, _>>()?)
}

/// A `zone_members` row (`SELECT *`), read by column name.
pub(crate) fn member_from_row(r: &Row<'_>) -> rusqlite::Result<ZoneMemberRow> {
    Ok(ZoneMemberRow {
        segment_id: r.get("segment_id")?,
        fit_id: r.get("fit_id")?,
        shrunk_soil_youngs_modulus_pa: r.get("shrunk_soil_youngs_modulus_pa")?,
        shrunk_soil_poisson: r.get("shrunk_soil_poisson")?,
        statistic: r.get("statistic")?,
        zone_outlier: r.get("zone_outlier")?,
    })
}

/// Every segment's place in its zone's newest estimate: segment id → (zone, member row).
pub fn latest_zone_memberships(
    conn: &Connection,
) -> Result<std::collections::BTreeMap<String, (ZoneFitRow, ZoneMemberRow)>, DbError> {
    let mut out = std::collections::BTreeMap::new();
    for z in latest_zone_fits(conn)? {
        let Some(id) = z.id else { continue };
        for m in zone_members(conn, id)? {
            out.insert(m.segment_id.clone(), (z.clone(), m));
        }
    }
    Ok(out)
}
