//! The GeoPackage's zone layer: one polygon per soil zone, the convex hull of its
//! segments' geometry buffered by [`ZONE_BUFFER_M`], with the zone's E_m, ν_m, c_P and c_S and
//! their 95 % intervals (model §7.11) from its newest estimate.

use std::collections::BTreeMap;

use rusqlite::{params, Transaction};

use crate::db::wkt::LineString;
use crate::db::zones::ZoneFitRow;

use super::gpkg::FLAGS_LE_XY_ENVELOPE;
use super::record::SegmentExport;

/// Name of the zone layer.
pub const ZONE_TABLE: &str = "soil_zones";
/// Buffer around a zone's hull, m (half a street width: the polygon encloses its pipes).
pub const ZONE_BUFFER_M: f64 = 20.0;
/// Metres per degree of latitude (mean), for the buffer in a geographic system (EPSG:4326).
pub const METRES_PER_DEGREE: f64 = 111_320.0;
/// Vertices of the circle each point is buffered with.
const BUFFER_VERTICES: usize = 16;
/// ISO WKB geometry type code of a 2-D Polygon.
pub const WKB_POLYGON: u32 = 3;

/// Convex hull (Andrew's monotone chain), counter-clockwise, without repeating the first point.
pub fn convex_hull(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut p: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|q| q.0.is_finite() && q.1.is_finite())
        .collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut lower: Vec<(f64, f64)> = Vec::new();
    for &q in &p {
        while lower.len() >= 2 && cross(lower[lower.len() - 2], lower[lower.len() - 1], q) <= 0.0 {
            lower.pop();
        }
        lower.push(q);
    }
    let mut upper: Vec<(f64, f64)> = Vec::new();
    for &q in p.iter().rev() {
        while upper.len() >= 2 && cross(upper[upper.len() - 2], upper[upper.len() - 1], q) <= 0.0 {
            upper.pop();
        }
        upper.push(q);
    }
    lower.pop();
    upper.pop();
    lower.extend(upper);
    lower
}

/// The hull of the points buffered by `d`: the hull of a circle (polygon of
/// `BUFFER_VERTICES` vertices, circumscribing) around every point; a closed ring.
pub fn buffered_hull(points: &[(f64, f64)], d: f64) -> Vec<(f64, f64)> {
    let r = d / (std::f64::consts::PI / BUFFER_VERTICES as f64).cos();
    let around: Vec<(f64, f64)> = convex_hull(points)
        .iter()
        .flat_map(|&(x, y)| {
            (0..BUFFER_VERTICES).map(move |k| {
                let a = std::f64::consts::TAU * k as f64 / BUFFER_VERTICES as f64;
                (x + r * a.cos(), y + r * a.sin())
            })
        })
        .collect();
    let mut ring = convex_hull(&around);
    if let Some(&first) = ring.first() {
        ring.push(first);
    }
    ring
}

/// GeoPackage binary of a one-ring polygon (header as [`super::gpkg::linestring_blob`]).
pub fn polygon_blob(srs_id: i32, ring: &[(f64, f64)]) -> Vec<u8> {
    let line = LineString {
        points: ring.to_vec(),
    };
    let [minx, maxx, miny, maxy] = super::gpkg::envelope(&line);
    let mut b = Vec::with_capacity(8 + 32 + 13 + 16 * ring.len());
    b.extend_from_slice(b"GP");
    b.push(0);
    b.push(FLAGS_LE_XY_ENVELOPE);
    b.extend_from_slice(&srs_id.to_le_bytes());
    for v in [minx, maxx, miny, maxy] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.push(1);
    b.extend_from_slice(&WKB_POLYGON.to_le_bytes());
    b.extend_from_slice(&1u32.to_le_bytes());
    let n = u32::try_from(ring.len()).unwrap_or(u32::MAX);
    b.extend_from_slice(&n.to_le_bytes());
    for &(x, y) in ring.iter().take(n as usize) {
        b.extend_from_slice(&x.to_le_bytes());
        b.extend_from_slice(&y.to_le_bytes());
    }
    b
}

/// Points a zone holds before they are reduced to their convex hull: the hull of a zone's
/// points is the hull of its previous hull and the new points, so a zone of any size holds at
/// most this many points plus its hull (1 MB), and a zone with fewer keeps every point.
pub const HULL_COMPACT_POINTS: usize = 65_536;

/// Each zone's newest estimate and the vertices of its segments' lines (in the GeoPackage's
/// system), gathered while the records stream past.
#[derive(Debug, Default)]
pub(crate) struct ZonePoints {
    zones: BTreeMap<String, (ZoneFitRow, Vec<(f64, f64)>)>,
}

impl ZonePoints {
    /// Add a record (nothing when it has no zone estimate) with its line in the table's system.
    pub fn add(&mut self, rec: &SegmentExport, line: Option<&LineString>) {
        let Some((z, _)) = &rec.zone else { return };
        if !self.zones.contains_key(&z.soil_zone) {
            self.zones
                .insert(z.soil_zone.clone(), (z.clone(), Vec::new()));
        }
        let Some((_, pts)) = self.zones.get_mut(&z.soil_zone) else {
            return;
        };
        if let Some(l) = line {
            pts.extend(l.points.iter().copied());
            if pts.len() > HULL_COMPACT_POINTS {
                *pts = convex_hull(pts);
            }
        }
    }
}

/// Write the zone layer into an open GeoPackage transaction: `zones` hold the points in the
/// table's system `table_srs` (`srs_id` as in the blobs). Zones without any geometry get a
/// NULL polygon. Returns the number of zones written.
pub(crate) fn write_zone_layer(
    tx: &Transaction<'_>,
    zones: ZonePoints,
    srs_id: i32,
    table_srs: i64,
) -> rusqlite::Result<usize> {
    let zones = zones.zones;
    if zones.is_empty() {
        return Ok(0);
    }
    let buffer = if table_srs == 4326 {
        ZONE_BUFFER_M / METRES_PER_DEGREE
    } else {
        ZONE_BUFFER_M
    };
    tx.execute_batch(&format!(
        "CREATE TABLE {ZONE_TABLE} (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, \
         geom POLYGON, soil_zone TEXT NOT NULL UNIQUE, n_segments INTEGER, n_outliers INTEGER, \
         soil_youngs_modulus_pa DOUBLE, soil_youngs_modulus_lo_pa DOUBLE, \
         soil_youngs_modulus_hi_pa DOUBLE, soil_poisson DOUBLE, soil_poisson_lo DOUBLE, \
         soil_poisson_hi DOUBLE, soil_p_wave_speed_m_per_s DOUBLE, \
         soil_p_wave_speed_lo_m_per_s DOUBLE, soil_p_wave_speed_hi_m_per_s DOUBLE, \
         soil_s_wave_speed_m_per_s DOUBLE, soil_s_wave_speed_lo_m_per_s DOUBLE, \
         soil_s_wave_speed_hi_m_per_s DOUBLE, scatter_source TEXT, chi2_per_dof DOUBLE, \
         flags TEXT, outliers TEXT);"
    ))?;
    let mut bbox = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    {
        let mut ins = tx.prepare(&format!(
            "INSERT INTO {ZONE_TABLE} (geom, soil_zone, n_segments, n_outliers, \
             soil_youngs_modulus_pa, soil_youngs_modulus_lo_pa, soil_youngs_modulus_hi_pa, \
             soil_poisson, soil_poisson_lo, soil_poisson_hi, soil_p_wave_speed_m_per_s, \
             soil_p_wave_speed_lo_m_per_s, soil_p_wave_speed_hi_m_per_s, \
             soil_s_wave_speed_m_per_s, soil_s_wave_speed_lo_m_per_s, \
             soil_s_wave_speed_hi_m_per_s, scatter_source, chi2_per_dof, flags, outliers) \
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, \
             ?18, ?19, ?20)"
        ))?;
        for (name, (z, pts)) in &zones {
            let ring = buffered_hull(pts, buffer);
            let blob = (ring.len() >= 4).then(|| {
                for &(x, y) in &ring {
                    bbox = [
                        bbox[0].min(x),
                        bbox[1].max(x),
                        bbox[2].min(y),
                        bbox[3].max(y),
                    ];
                }
                polygon_blob(srs_id, &ring)
            });
            ins.execute(params![
                blob,
                name,
                z.n_segments,
                z.n_outliers,
                z.soil_youngs_modulus_pa,
                z.soil_youngs_modulus_lo_pa,
                z.soil_youngs_modulus_hi_pa,
                z.soil_poisson,
                z.soil_poisson_lo,
                z.soil_poisson_hi,
                z.soil_p_wave_speed_m_per_s,
                z.soil_p_wave_speed_lo_m_per_s,
                z.soil_p_wave_speed_hi_m_per_s,
                z.soil_s_wave_speed_m_per_s,
                z.soil_s_wave_speed_lo_m_per_s,
                z.soil_s_wave_speed_hi_m_per_s,
                z.scatter_source,
                z.chi2_per_dof,
                z.flags,
                z.outliers,
            ])?;
        }
    }
    super::gpkg::register_feature_table(
        tx,
        ZONE_TABLE,
        "soil zones: buffered hull of their pipes, with the zone's soil (pipewave)",
        bbox[0].is_finite().then_some(bbox),
        "geom",
        "POLYGON",
        table_srs,
    )?;
    Ok(zones.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_buffered_hull_encloses_every_point_by_the_buffer() {
        let pts = [
            (0.0, 0.0),
            (100.0, 0.0),
            (50.0, 10.0),
            (100.0, 80.0),
            (0.0, 80.0),
        ];
        let hull = convex_hull(&pts);
        assert_eq!(hull.len(), 4, "{hull:?}");
        let ring = buffered_hull(&pts, 20.0);
        assert_eq!(ring.first(), ring.last());
        let xs: Vec<f64> = ring.iter().map(|p| p.0).collect();
        let min_x = xs.iter().copied().fold(f64::INFINITY, f64::min);
        let max_x = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert!(
            (min_x + 20.0).abs() < 1.0 && (max_x - 120.0).abs() < 1.0,
            "{min_x} {max_x}"
        );
        // Counter-clockwise: positive signed area.
        let area: f64 = ring
            .windows(2)
            .map(|w| w[0].0 * w[1].1 - w[1].0 * w[0].1)
            .sum();
        assert!(area > 0.0);
    }
}
