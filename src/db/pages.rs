//! Page-by-page reads of the inventory for the exports and the audit report, so what they hold
//! does not grow with the network: the segments a page at a time (keyset paging on the primary
//! key, as a calibrate run reads them), the zone memberships of one page, and a cursor over
//! the segments' geometry alone.

use std::collections::BTreeMap;

use rusqlite::{params, Connection, Row};

use super::inventory::{finish_segment, segment_from_row, SEGMENT_COLUMNS};
use super::zones::{member_from_row, ZoneFitRow, ZoneMemberRow};
use super::{DbError, SegmentRecord};

/// One page of segments with their measurements, sorted by id: those whose id sorts after
/// `after` (from the first when `None`), at most `limit` of them (at least one).
pub fn segments_page(
    conn: &Connection,
    after: Option<&str>,
    limit: usize,
) -> Result<Vec<SegmentRecord>, DbError> {
    let limit = i64::try_from(limit.max(1)).unwrap_or(i64::MAX);
    let rows: Vec<_> = match after {
        None => conn
            .prepare_cached(&format!(
                "SELECT {SEGMENT_COLUMNS} FROM segments ORDER BY segment_id LIMIT ?1"
            ))?
            .query_map([limit], segment_from_row)?
            .collect::<Result<_, _>>()?,
        Some(after) => conn
            .prepare_cached(&format!(
                "SELECT {SEGMENT_COLUMNS} FROM segments WHERE segment_id > ?1 \
                 ORDER BY segment_id LIMIT ?2"
            ))?
            .query_map(params![after, limit], segment_from_row)?
            .collect::<Result<_, _>>()?,
    };
    rows.into_iter().map(|r| finish_segment(conn, r)).collect()
}

/// The places in the zone estimates `zones` (each zone's newest, as
/// [`super::zones::latest_zone_fits`] gives them, sorted by zone) of the segments with ids
/// from `first` to `last` inclusive: segment id → (zone, member row). A segment listed in
/// several of them gets the last zone's, as [`super::zones::latest_zone_memberships`] does.
pub fn zone_memberships_between(
    conn: &Connection,
    zones: &[ZoneFitRow],
    first: &str,
    last: &str,
) -> Result<BTreeMap<String, (ZoneFitRow, ZoneMemberRow)>, DbError> {
    let mut out = BTreeMap::new();
    let mut stmt = conn.prepare_cached(
        "SELECT * FROM zone_members WHERE zone_fit_id = ?1 AND segment_id >= ?2 \
         AND segment_id <= ?3 ORDER BY segment_id",
    )?;
    for z in zones {
        let Some(id) = z.id else { continue };
        let rows = stmt.query_map(params![id, first, last], member_from_row)?;
        for m in rows {
            let m = m?;
            out.insert(m.segment_id.clone(), (z.clone(), m));
        }
    }
    Ok(out)
}

/// A segment's id and stored geometry, without the rest of its row.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GeometryRow {
    /// The segment.
    pub segment_id: String,
    /// Its geometry as stored (WKT), if any.
    pub geometry_wkt: Option<String>,
    /// The EPSG code of that geometry, if stored.
    pub srid: Option<i64>,
}

fn geometry_from_row(r: &Row<'_>) -> rusqlite::Result<GeometryRow> {
    Ok(GeometryRow {
        segment_id: r.get(0)?,
        geometry_wkt: r.get(1)?,
        srid: r.get(2)?,
    })
}

/// Call `f` on every segment's [`GeometryRow`], in id order, through one cursor (one row held at
/// a time). `f`'s error stops the walk and is returned.
pub fn for_each_geometry<E: From<DbError>>(
    conn: &Connection,
    mut f: impl FnMut(GeometryRow) -> Result<(), E>,
) -> Result<(), E> {
    let mut stmt = conn
        .prepare_cached("SELECT segment_id, geometry_wkt, srid FROM segments ORDER BY segment_id")
        .map_err(DbError::from)?;
    let mut rows = stmt.query([]).map_err(DbError::from)?;
    while let Some(r) = rows.next().map_err(DbError::from)? {
        f(geometry_from_row(r).map_err(DbError::from)?)?;
    }
    Ok(())
}
