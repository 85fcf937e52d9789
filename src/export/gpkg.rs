//! OGC GeoPackage writer, with rusqlite into a new file. The file declares GeoPackage 1.2
//! (`user_version` 10200): it uses nothing newer, and GDAL up to 3.6 (Debian 12, QGIS 3.28 LTR)
//! warns on every file that declares 1.4 ("may only be partially supported"). The requirement
//! numbers below are those of OGC 12-128r18 (1.4), which 1.2 (12-128r15) shares.
//!
//! The file holds the required metadata tables (`gpkg_spatial_ref_sys` with the three mandatory
//! rows and the segments' system, `gpkg_contents`, `gpkg_geometry_columns`), one feature table
//! [`TABLE`] of LINESTRINGs in GeoPackage binary encoding, one row per segment (NULL geometry
//! when the segment has none), an R-tree spatial index (extension `gpkg_rtree_index`), and
//! QGIS's `layer_styles` table (an attributes table) holding the default style of
//! [`super::style`].
//!
//! The table has one coordinate system: the one most segments' geometries are in
//! ([`crs::dominant_srid`], found by a first pass over the geometries alone); geometries in another system are reprojected into it, and the few
//! that cannot be are written without geometry, with a warning.

use std::path::Path;

use rusqlite::{params, params_from_iter, Connection};

use super::record::{Records, Value};
use super::style;
use super::zones::ZonePoints;
use super::{ExportError, Tally};
use crate::db::crs::{self, ToCommonCrs};
use crate::db::wkt::LineString;
use crate::outfile::{Contents, OutFile};

/// The feature table.
pub const TABLE: &str = "pipe_segments";
/// Its geometry column.
pub const GEOMETRY_COLUMN: &str = "geom";

/// `PRAGMA application_id` of a GeoPackage: ASCII "GPKG" (12-128r18 Req. 2).
pub const APPLICATION_ID: i32 = 0x4750_4B47;
/// `PRAGMA user_version` of GeoPackage 1.2.0 (Req. 2): the newest version GDAL 3.6 reads
/// without a warning, and enough for everything this file holds.
pub const USER_VERSION: i32 = 10200;

/// GeoPackage binary header flags (12-128r18 §2.1.3.1.1): bit 0 byte order (1 = little
/// endian), bits 1–3 envelope contents indicator (1 = [minx, maxx, miny, maxy]), bit 4 empty
/// geometry, bit 5 binary type (0 = standard).
pub const FLAGS_LE_XY_ENVELOPE: u8 = 0b0000_0011;
/// ISO WKB geometry type code of a 2-D LineString.
pub const WKB_LINESTRING: u32 = 2;

/// The GeoPackage binary encoding of a 2-D line: header "GP", version 0, flags
/// [`FLAGS_LE_XY_ENVELOPE`], `srs_id` (int32), the envelope [minx, maxx, miny, maxy], then the
/// ISO WKB LineString, all little endian.
pub fn linestring_blob(srs_id: i32, line: &LineString) -> Vec<u8> {
    let [minx, maxx, miny, maxy] = envelope(line);
    let mut b = Vec::with_capacity(8 + 32 + 9 + 16 * line.points.len());
    b.extend_from_slice(b"GP");
    b.push(0);
    b.push(FLAGS_LE_XY_ENVELOPE);
    b.extend_from_slice(&srs_id.to_le_bytes());
    for v in [minx, maxx, miny, maxy] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.push(1); // WKB byte order: little endian
    b.extend_from_slice(&WKB_LINESTRING.to_le_bytes());
    let n = u32::try_from(line.points.len()).unwrap_or(u32::MAX);
    b.extend_from_slice(&n.to_le_bytes());
    for &(x, y) in line.points.iter().take(n as usize) {
        b.extend_from_slice(&x.to_le_bytes());
        b.extend_from_slice(&y.to_le_bytes());
    }
    b
}

/// [minx, maxx, miny, maxy] of a line.
pub fn envelope(line: &LineString) -> [f64; 4] {
    let mut e = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for &(x, y) in &line.points {
        e[0] = e[0].min(x);
        e[1] = e[1].max(x);
        e[2] = e[2].min(y);
        e[3] = e[3].max(y);
    }
    e
}

/// Puts the records' lines into one coordinate system, as they stream past: the system most
/// segments' geometries are in ([`Records::dominant_srid`]). Shared with the audit map.
pub(crate) struct CommonGeometry {
    to: Option<ToCommonCrs>,
}

impl CommonGeometry {
    /// Lines into EPSG:`srid` (`None`: no segment has a geometry, so no record gets a line).
    pub fn new(srid: Option<i64>) -> Self {
        CommonGeometry {
            to: srid.map(ToCommonCrs::new),
        }
    }

    /// The common system.
    pub fn srid(&self) -> Option<i64> {
        self.to.as_ref().map(ToCommonCrs::target)
    }

    /// The line of a segment (`id`, its parsed geometry and its system) in the common system;
    /// `None` without a geometry, or when it has no system or cannot be reprojected (then with
    /// a warning in `warnings`). A segment is "with geometry" in the counts exactly when this
    /// gives a line.
    pub fn line(
        &mut self,
        id: &str,
        geometry: Option<&LineString>,
        from: Option<i64>,
        warnings: &mut Vec<String>,
    ) -> Option<LineString> {
        let line = geometry?;
        let (Some(to), Some(from)) = (self.to.as_mut(), from) else {
            warnings.push(format!(
                "segment {id}: its geometry has no srid, so its coordinate system is unknown; \
                 exported without geometry"
            ));
            return None;
        };
        match to.line(from, line) {
            Ok(l) => Some(l),
            Err(e) => {
                warnings.push(format!("segment {id}: {e}; exported without geometry"));
                None
            }
        }
    }
}

/// A `gpkg_spatial_ref_sys` row.
struct SrsRow {
    name: String,
    id: i64,
    organization: &'static str,
    org_id: i64,
    definition: String,
    description: String,
}

const WGS84_WKT: &str = "GEOGCS[\"WGS 84\",DATUM[\"WGS_1984\",SPHEROID[\"WGS 84\",6378137,\
    298.257223563,AUTHORITY[\"EPSG\",\"7030\"]],AUTHORITY[\"EPSG\",\"6326\"]],PRIMEM[\"Greenwich\",\
    0,AUTHORITY[\"EPSG\",\"8901\"]],UNIT[\"degree\",0.0174532925199433,AUTHORITY[\"EPSG\",\"9122\"]],\
    AUTHORITY[\"EPSG\",\"4326\"]]";

/// The three rows every GeoPackage has (Req. 11), plus the table's system.
fn srs_rows(srid: Option<i64>, warnings: &mut Vec<String>) -> Vec<SrsRow> {
    let mut rows = vec![
        SrsRow {
            name: "WGS 84 geodetic".into(),
            id: 4326,
            organization: "EPSG",
            org_id: 4326,
            definition: WGS84_WKT.into(),
            description: "longitude/latitude coordinates in decimal degrees on the WGS 84 spheroid"
                .into(),
        },
        SrsRow {
            name: "Undefined cartesian SRS".into(),
            id: -1,
            organization: "NONE",
            org_id: -1,
            definition: "undefined".into(),
            description: "undefined cartesian coordinate reference system".into(),
        },
        SrsRow {
            name: "Undefined geographic SRS".into(),
            id: 0,
            organization: "NONE",
            org_id: 0,
            definition: "undefined".into(),
            description: "undefined geographic coordinate reference system".into(),
        },
    ];
    if let Some(s) = srid.filter(|&s| s > 0 && s != 4326) {
        let (name, definition) = match crs::lookup(s) {
            Some(d) => (d.name.to_string(), d.wkt.to_string()),
            None => {
                warnings.push(format!(
                    "EPSG:{s} is not in pipewave's coordinate-system registry: the GeoPackage \
                     records it with an 'undefined' definition; GIS software will ask for it"
                ));
                (format!("EPSG:{s}"), "undefined".to_string())
            }
        };
        rows.push(SrsRow {
            name,
            id: s,
            organization: "EPSG",
            org_id: s,
            definition,
            description: String::new(),
        });
    }
    rows
}

/// Insert the mandatory `gpkg_spatial_ref_sys` rows and that of EPSG:`srid`, each unless
/// present (so a layer can be added to an existing GeoPackage).
pub(crate) fn ensure_srs(
    tx: &rusqlite::Transaction<'_>,
    srid: Option<i64>,
    warnings: &mut Vec<String>,
) -> rusqlite::Result<()> {
    for r in srs_rows(srid, warnings) {
        tx.execute(
            "INSERT OR IGNORE INTO gpkg_spatial_ref_sys (srs_name, srs_id, organization, \
             organization_coordsys_id, definition, description) VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
            params![
                r.name,
                r.id,
                r.organization,
                r.org_id,
                r.definition,
                r.description
            ],
        )?;
    }
    Ok(())
}

/// The required tables (12-128r18 Annex C, tables 29, 30, 31 and the extensions table).
pub(crate) const SCHEMA: &str = "
CREATE TABLE gpkg_spatial_ref_sys (
  srs_name TEXT NOT NULL,
  srs_id INTEGER PRIMARY KEY,
  organization TEXT NOT NULL,
  organization_coordsys_id INTEGER NOT NULL,
  definition TEXT NOT NULL,
  description TEXT
);
CREATE TABLE gpkg_contents (
  table_name TEXT NOT NULL PRIMARY KEY,
  data_type TEXT NOT NULL,
  identifier TEXT UNIQUE,
  description TEXT DEFAULT '',
  last_change DATETIME NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ','now')),
  min_x DOUBLE,
  min_y DOUBLE,
  max_x DOUBLE,
  max_y DOUBLE,
  srs_id INTEGER,
  CONSTRAINT fk_gc_r_srs_id FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys(srs_id)
);
CREATE TABLE gpkg_geometry_columns (
  table_name TEXT NOT NULL,
  column_name TEXT NOT NULL,
  geometry_type_name TEXT NOT NULL,
  srs_id INTEGER NOT NULL,
  z TINYINT NOT NULL,
  m TINYINT NOT NULL,
  CONSTRAINT pk_geom_cols PRIMARY KEY (table_name, column_name),
  CONSTRAINT uk_gc_table_name UNIQUE (table_name),
  CONSTRAINT fk_gc_tn FOREIGN KEY (table_name) REFERENCES gpkg_contents(table_name),
  CONSTRAINT fk_gc_srs FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys (srs_id)
);
CREATE TABLE gpkg_extensions (
  table_name TEXT,
  column_name TEXT,
  extension_name TEXT NOT NULL,
  definition TEXT NOT NULL,
  scope TEXT NOT NULL,
  CONSTRAINT ge_tce UNIQUE (table_name, column_name, extension_name)
);
";

/// The R-tree index and the triggers that keep it in step with the feature table
/// (GeoPackage 1.2, 12-128r15 Annex F.3: triggers `insert`, `update1`–`update4`, `delete`). The
/// triggers call the GeoPackage SQL functions (ST_IsEmpty, ST_MinX, ...) that GIS software
/// provides; pipewave fills the index itself and never edits the table afterwards.
fn rtree_sql(t: &str, c: &str) -> String {
    format!(
        "CREATE VIRTUAL TABLE rtree_{t}_{c} USING rtree(id, minx, maxx, miny, maxy);
CREATE TRIGGER rtree_{t}_{c}_insert AFTER INSERT ON {t}
  WHEN (new.{c} NOT NULL AND NOT ST_IsEmpty(NEW.{c}))
BEGIN
  INSERT OR REPLACE INTO rtree_{t}_{c} VALUES (
    NEW.fid, ST_MinX(NEW.{c}), ST_MaxX(NEW.{c}), ST_MinY(NEW.{c}), ST_MaxY(NEW.{c}));
END;
CREATE TRIGGER rtree_{t}_{c}_update1 AFTER UPDATE OF {c} ON {t}
  WHEN OLD.fid = NEW.fid AND (NEW.{c} NOTNULL AND NOT ST_IsEmpty(NEW.{c}))
BEGIN
  INSERT OR REPLACE INTO rtree_{t}_{c} VALUES (
    NEW.fid, ST_MinX(NEW.{c}), ST_MaxX(NEW.{c}), ST_MinY(NEW.{c}), ST_MaxY(NEW.{c}));
END;
CREATE TRIGGER rtree_{t}_{c}_update2 AFTER UPDATE OF {c} ON {t}
  WHEN OLD.fid = NEW.fid AND (NEW.{c} ISNULL OR ST_IsEmpty(NEW.{c}))
BEGIN
  DELETE FROM rtree_{t}_{c} WHERE id = OLD.fid;
END;
CREATE TRIGGER rtree_{t}_{c}_update3 AFTER UPDATE ON {t}
  WHEN OLD.fid != NEW.fid AND (NEW.{c} NOTNULL AND NOT ST_IsEmpty(NEW.{c}))
BEGIN
  DELETE FROM rtree_{t}_{c} WHERE id = OLD.fid;
  INSERT OR REPLACE INTO rtree_{t}_{c} VALUES (
    NEW.fid, ST_MinX(NEW.{c}), ST_MaxX(NEW.{c}), ST_MinY(NEW.{c}), ST_MaxY(NEW.{c}));
END;
CREATE TRIGGER rtree_{t}_{c}_update4 AFTER UPDATE ON {t}
  WHEN OLD.fid != NEW.fid AND (NEW.{c} ISNULL OR ST_IsEmpty(NEW.{c}))
BEGIN
  DELETE FROM rtree_{t}_{c} WHERE id IN (OLD.fid, NEW.fid);
END;
CREATE TRIGGER rtree_{t}_{c}_delete AFTER DELETE ON {t}
  WHEN old.{c} NOT NULL
BEGIN
  DELETE FROM rtree_{t}_{c} WHERE id = OLD.fid;
END;
"
    )
}

/// Add QGIS's `layer_styles` table with the default style of the feature table, and register it
/// as an attributes table (as GDAL does when QGIS creates it).
/// Register a feature table: its row in `gpkg_contents` (with its extent `[min_x, max_x,
/// min_y, max_y]`, NULL when it has no geometry) and in `gpkg_geometry_columns` (OGC 12-128r18
/// §1.1.3, §2.1.5).
pub(crate) fn register_feature_table(
    tx: &rusqlite::Transaction<'_>,
    table: &str,
    description: &str,
    extent: Option<[f64; 4]>,
    geometry_column: &str,
    geometry_type: &str,
    srs_id: i64,
) -> rusqlite::Result<()> {
    let e = |i: usize| extent.map(|b| b[i]);
    tx.execute(
        "INSERT INTO gpkg_contents (table_name, data_type, identifier, description, min_x, min_y, \
         max_x, max_y, srs_id) VALUES (?1, 'features', ?1, ?2, ?3, ?4, ?5, ?6, ?7)",
        params![table, description, e(0), e(2), e(1), e(3), srs_id],
    )?;
    tx.execute(
        "INSERT INTO gpkg_geometry_columns (table_name, column_name, geometry_type_name, srs_id, \
         z, m) VALUES (?1, ?2, ?3, ?4, 0, 0)",
        params![table, geometry_column, geometry_type, srs_id],
    )?;
    Ok(())
}

fn write_style(tx: &rusqlite::Transaction<'_>, qml: &str) -> rusqlite::Result<()> {
    tx.execute_batch(style::LAYER_STYLES_SQL)?;
    tx.execute(
        "INSERT INTO layer_styles (f_table_catalog, f_table_schema, f_table_name, \
         f_geometry_column, styleName, styleQML, styleSLD, useAsDefault, description, owner) \
         VALUES ('', '', ?1, ?2, ?3, ?4, '', 1, ?5, '')",
        params![
            TABLE,
            GEOMETRY_COLUMN,
            style::STYLE_NAME,
            qml,
            "segments coloured by leak-band speed (m/s), classes from the data"
        ],
    )?;
    tx.execute(
        "INSERT INTO gpkg_contents (table_name, data_type, identifier, description) \
         VALUES ('layer_styles', 'attributes', 'layer_styles', '')",
        [],
    )?;
    Ok(())
}

/// Write the GeoPackage of the records to `out` (through a temporary file), each row as it
/// is read.
pub(crate) fn write(records: &Records<'_>, out: &Path) -> Result<Tally, ExportError> {
    let file = OutFile::for_path(out, Contents::GeoPackage, false)?;
    let tally = write_to(records, file.temp_path(), out)?;
    file.commit()?;
    Ok(tally)
}

fn write_to(records: &Records<'_>, tmp: &Path, out: &Path) -> Result<Tally, ExportError> {
    let sql = |source| ExportError::Gpkg {
        path: out.to_path_buf(),
        source,
    };
    let mut common = CommonGeometry::new(records.dominant_srid()?);
    let srid = common.srid();
    // -1: "undefined cartesian", when no segment has a geometry.
    let table_srs = srid.unwrap_or(-1);
    let srs_id = i32::try_from(table_srs).unwrap_or(-1);

    let mut conn = Connection::open(tmp).map_err(sql)?;
    conn.pragma_update(None, "application_id", APPLICATION_ID)
        .map_err(sql)?;
    conn.pragma_update(None, "user_version", USER_VERSION)
        .map_err(sql)?;
    let tx = conn.transaction().map_err(sql)?;
    tx.execute_batch(SCHEMA).map_err(sql)?;
    let mut srs_warnings = Vec::new();
    ensure_srs(&tx, srid, &mut srs_warnings).map_err(sql)?;

    let layout = super::numbers::columns();
    let columns: Vec<String> = layout
        .properties
        .iter()
        .map(|p| {
            let extra = if p.name == "segment_id" {
                " NOT NULL UNIQUE"
            } else {
                ""
            };
            format!("\"{}\" {}{extra}", p.name, p.kind.gpkg_type())
        })
        .collect();
    tx.execute_batch(&format!(
        "CREATE TABLE {TABLE} (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, \
         {GEOMETRY_COLUMN} LINESTRING, {});",
        columns.join(", ")
    ))
    .map_err(sql)?;

    let mut bbox = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    let mut tally = Tally::default();
    let mut load_warnings = Vec::new();
    let mut geometry_warnings = Vec::new();
    let mut zones = ZonePoints::default();
    let plan =
        crate::db::field::plan_picks(records.db().conn()).map_err(ExportError::db(records.db()))?;
    let mut field_layers = super::field::FieldLayers::new(plan);
    {
        let names: Vec<String> = layout
            .properties
            .iter()
            .map(|p| format!("\"{}\"", p.name))
            .collect();
        let marks: Vec<String> = (0..=layout.properties.len())
            .map(|i| format!("?{}", i + 1))
            .collect();
        let mut ins = tx
            .prepare(&format!(
                "INSERT INTO {TABLE} ({GEOMETRY_COLUMN}, {}) VALUES ({})",
                names.join(", "),
                marks.join(", ")
            ))
            .map_err(sql)?;
        // The R-tree is created after the rows (so its triggers, which need the GIS SQL
        // functions, never fire here); its rows are collected meanwhile (40 bytes a segment).
        let mut index_rows: Vec<(i64, [f64; 4])> = Vec::new();
        let mut values: Vec<rusqlite::types::Value> =
            Vec::with_capacity(layout.properties.len() + 1);
        records.for_each(&mut load_warnings, |rec| {
            tally.add(&rec);
            let line = common.line(
                rec.id(),
                rec.geometry.as_ref(),
                rec.segment.srid,
                &mut geometry_warnings,
            );
            let blob = line.as_ref().map(|l| linestring_blob(srs_id, l));
            values.clear();
            values.push(blob.map_or(rusqlite::types::Value::Null, rusqlite::types::Value::Blob));
            // Full precision always: the GeoPackage is a database.
            for p in &layout.properties {
                values.push(match (p.get)(&rec) {
                    Value::Null => rusqlite::types::Value::Null,
                    Value::Text(s) => rusqlite::types::Value::Text(s.to_string()),
                    Value::Real(x) => rusqlite::types::Value::Real(x),
                    Value::Integer(i) => rusqlite::types::Value::Integer(i),
                });
            }
            ins.execute(params_from_iter(values.drain(..)))
                .map_err(sql)?;
            if let Some(l) = &line {
                let e = envelope(l);
                bbox = [
                    bbox[0].min(e[0]),
                    bbox[1].max(e[1]),
                    bbox[2].min(e[2]),
                    bbox[3].max(e[3]),
                ];
                index_rows.push((tx.last_insert_rowid(), e));
                tally.summary.with_geometry += 1;
            }
            zones.add(&rec, line.as_ref());
            field_layers
                .add(&tx, &rec, line.as_ref(), srs_id)
                .map_err(sql)?;
            Ok(())
        })?;
        tx.execute_batch(&rtree_sql(TABLE, GEOMETRY_COLUMN))
            .map_err(sql)?;
        let mut idx = tx
            .prepare(&format!(
                "INSERT INTO rtree_{TABLE}_{GEOMETRY_COLUMN} (id, minx, maxx, miny, maxy) \
                 VALUES (?1, ?2, ?3, ?4, ?5)"
            ))
            .map_err(sql)?;
        for (fid, e) in index_rows {
            idx.execute(params![fid, e[0], e[1], e[2], e[3]])
                .map_err(sql)?;
        }
    }
    register_feature_table(
        &tx,
        TABLE,
        "pipe segments with fitted soil parameters, wave speed and attenuation (pipewave)",
        (tally.summary.with_geometry > 0).then_some(bbox),
        GEOMETRY_COLUMN,
        "LINESTRING",
        table_srs,
    )
    .map_err(sql)?;
    tx.execute(
        "INSERT INTO gpkg_extensions (table_name, column_name, extension_name, definition, scope) \
         VALUES (?1, ?2, 'gpkg_rtree_index', 'http://www.geopackage.org/spec/#extension_rtree', \
         'write-only')",
        params![TABLE, GEOMETRY_COLUMN],
    )
    .map_err(sql)?;
    write_style(&tx, &style::qml(tally.speeds.iter().copied())).map_err(sql)?;
    super::zones::write_zone_layer(&tx, zones, srs_id, table_srs).map_err(sql)?;
    field_layers.finish(&tx, table_srs).map_err(sql)?;
    tx.commit().map_err(sql)?;
    conn.close().map_err(|(_, e)| sql(e))?;
    load_warnings.append(&mut geometry_warnings);
    load_warnings.append(&mut srs_warnings);
    tally.summary.warnings = load_warnings;
    Ok(tally)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blob_layout_is_the_geopackage_binary() {
        let l = LineString {
            points: vec![(1.0, 5.0), (-2.0, 7.5), (3.0, 6.0)],
        };
        let b = linestring_blob(27700, &l);
        assert_eq!(&b[..2], b"GP");
        assert_eq!(b[2], 0);
        assert_eq!(b[3], 0b11);
        assert_eq!(i32::from_le_bytes(b[4..8].try_into().unwrap()), 27700);
        let f = |i: usize| f64::from_le_bytes(b[i..i + 8].try_into().unwrap());
        assert_eq!([f(8), f(16), f(24), f(32)], [-2.0, 3.0, 5.0, 7.5]);
        assert_eq!(b[40], 1);
        assert_eq!(u32::from_le_bytes(b[41..45].try_into().unwrap()), 2);
        assert_eq!(u32::from_le_bytes(b[45..49].try_into().unwrap()), 3);
        assert_eq!(
            [f(49), f(57), f(65), f(73), f(81), f(89)],
            [1.0, 5.0, -2.0, 7.5, 3.0, 6.0]
        );
        assert_eq!(b.len(), 97);
    }
}
