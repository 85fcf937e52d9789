//! GIS layers as import files: a GeoPackage feature table, a GeoJSON FeatureCollection or an
//! ESRI Shapefile (with its `.dbf` and `.prj`), read in pure Rust (SQLite, `geojson`,
//! `shapefile`) into the same [`RawTable`] a CSV gives: one row per feature, the attributes as
//! text cells and the geometry as the `geometry_wkt` and `srid` cells. The header check, the
//! `--map` pairs, the material spellings and every row check are then those of the CSV.
//!
//! Geometry: a LineString, or a MultiLineString of one part (GIS exports often write every line
//! as a multi-line); a MultiLineString of several parts, or any other type, is rejected for that
//! feature with a message naming the layer, the feature id and the geometry field.

use std::io::Cursor;
use std::path::Path;

use rusqlite::types::ValueRef;
use rusqlite::{Connection, OpenFlags};

use super::table::{RawRow, RawTable, Rows};
use super::{ColumnRef, ImportSource, RowError, SourceKind};
use crate::db::crs;
use crate::db::wkt::LineString;
use crate::units::short;

/// EPSG code of WGS 84 longitude/latitude, the coordinate system of RFC 7946 GeoJSON.
pub const WGS84: i64 = 4326;

/// The geometry of one feature, as read.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Geometry {
    /// No geometry (NULL, empty).
    None,
    /// A line's parts: one for a LineString, any number for a MultiLineString.
    Lines {
        /// The type as the format names it, for messages.
        kind: &'static str,
        /// Each part's vertices (x, y).
        parts: Vec<Vec<(f64, f64)>>,
    },
    /// Another type (point, polygon, ...): its name.
    Other(String),
}

/// One feature: its id (1-based position where the format has none), attribute cells in the
/// order of the layer's fields, and geometry (or why it cannot be read).
#[derive(Debug)]
struct Feature {
    fid: u64,
    values: Vec<String>,
    /// Fields (indices into `values`) whose text is not UTF-8 (read as blank): an error only
    /// when pipewave uses the field.
    not_utf8: Vec<usize>,
    geometry: Result<Geometry, String>,
}

/// A layer as read from any of the formats.
#[derive(Debug, Default)]
struct Layer {
    name: String,
    /// Attribute fields, in order.
    fields: Vec<String>,
    /// The geometry field's name, for messages (`geom`, `geometry`, `shape`).
    geometry_field: String,
    /// EPSG code of the layer's coordinate system, if known.
    srid: Option<i64>,
    /// Why the coordinate system has no EPSG code, when it has none.
    srid_problem: Option<String>,
    features: Vec<Feature>,
}

/// Read the GIS layer of `source` (the layer named `wanted` for a GeoPackage holding several).
/// Errors that make the layer unusable come as `Err`.
#[allow(clippy::type_complexity)]
pub(super) fn read(
    source: &ImportSource,
    wanted: Option<&str>,
    srid: Option<i64>,
) -> Result<(RawTable, Vec<RowError>), Vec<RowError>> {
    let file = source.name.as_str();
    let whole = |layer: Option<&str>, msg: String| {
        let mut e = RowError::new(file, 0, None, msg);
        e.layer = layer.map(str::to_string);
        vec![e]
    };
    let stem = Path::new(file)
        .file_stem()
        .map_or_else(|| file.to_string(), |s| s.to_string_lossy().into_owned());
    let layer = match &source.kind {
        SourceKind::GeoPackage(path) => read_gpkg(path, wanted),
        SourceKind::GeoJson => read_geojson(&source.data, &stem, srid),
        SourceKind::Shapefile { dbf, prj } => {
            read_shapefile(&source.data, dbf.as_deref(), prj.as_deref(), &stem)
        }
        SourceKind::Csv | SourceKind::CsvFile(_) => Err("not a GIS layer".to_string()),
    };
    let layer = match layer {
        Ok(l) => l,
        Err(msg) => return Err(whole(None, msg)),
    };
    if let (Some(w), false) = (wanted, matches!(source.kind, SourceKind::GeoPackage(_))) {
        if !w.eq_ignore_ascii_case(&layer.name) {
            return Err(whole(
                None,
                format!(
                    "--layer {w}: this file holds one layer, '{}' (--layer chooses among the \
                     layers of a GeoPackage)",
                    layer.name
                ),
            ));
        }
    }
    if layer.features.is_empty() {
        return Err(whole(
            Some(&layer.name),
            "the layer has no features (an empty FeatureCollection or table): there is nothing \
             to import"
                .to_string(),
        ));
    }
    let has_geometry = layer
        .features
        .iter()
        .any(|f| matches!(f.geometry, Ok(Geometry::Lines { .. })));
    if has_geometry && layer.srid.is_none() {
        return Err(whole(
            Some(&layer.name),
            layer.srid_problem.clone().unwrap_or_else(|| {
                "the layer's coordinate system has no EPSG code; save it in an EPSG system \
                 (such as 27700 or 4326)"
                    .to_string()
            }),
        ));
    }
    if let (true, Some(s)) = (has_geometry, layer.srid) {
        if crs::lookup(s).is_none() {
            return Err(whole(
                Some(&layer.name),
                format!(
                    "the layer's coordinate system: {}; save the layer in an EPSG system of the \
                     registry (such as 27700 or 4326)",
                    crs::CrsError::Unknown(s)
                ),
            ));
        }
    }
    Ok((to_raw(file, layer), Vec::new()))
}

/// The layer as a table: its fields (less any named `geometry_wkt` or `srid`, which the layer's
/// own geometry replaces), then `geometry_wkt` and `srid`.
fn to_raw(file: &str, layer: Layer) -> RawTable {
    let replaced =
        |f: &str| f.eq_ignore_ascii_case("geometry_wkt") || f.eq_ignore_ascii_case("srid");
    let keep: Vec<usize> = (0..layer.fields.len())
        .filter(|&i| !replaced(&layer.fields[i]))
        .collect();
    let mut header: Vec<String> = keep.iter().map(|&i| layer.fields[i].clone()).collect();
    let geometry_col = header.len();
    header.push("geometry_wkt".into());
    header.push("srid".into());
    let srid = layer.srid.map(|s| s.to_string()).unwrap_or_default();
    let rows: Vec<RawRow> = layer
        .features
        .into_iter()
        .map(|f| {
            let mut cells: Vec<String> = keep
                .iter()
                .map(|&i| f.values.get(i).map_or("", |v| v.trim()).to_string())
                .collect();
            let not_utf8 = keep
                .iter()
                .enumerate()
                .filter(|(_, i)| f.not_utf8.contains(i))
                .map(|(cell, _)| cell)
                .collect();
            let mut errors = Vec::new();
            let geographic = layer.srid.is_some_and(crs::is_geographic);
            let wkt = match f
                .geometry
                .and_then(line_of)
                .and_then(|l| check_geographic(l, geographic, layer.srid))
                .and_then(|l| match (&l, layer.srid) {
                    (Some(line), Some(s)) => crs::check_line(s, line).map(|()| l),
                    _ => Ok(l),
                }) {
                Ok(Some(line)) => line.to_wkt(),
                Ok(None) => String::new(),
                Err(msg) => {
                    let mut e = RowError::new(
                        file,
                        f.fid,
                        Some(ColumnRef::new(geometry_col, &layer.geometry_field)),
                        msg,
                    );
                    e.layer = Some(layer.name.clone());
                    errors.push(e);
                    String::new()
                }
            };
            cells.push(if wkt.is_empty() {
                String::new()
            } else {
                srid.clone()
            });
            cells.insert(geometry_col, wkt);
            RawRow {
                line: f.fid,
                cells,
                errors,
                not_utf8,
            }
        })
        .collect();
    RawTable {
        file: file.to_string(),
        layer: Some(layer.name),
        header_line: 0,
        header,
        rows: Rows::Loaded(rows.into_iter()),
    }
}

/// A line in a longitude/latitude system (WGS 84 and the like) must have longitudes within
/// ±180° and latitudes within ±90°: coordinates outside are those of a projected system
/// (metres) in a file that does not say so, as a GeoJSON without `crs` (RFC 7946 makes it
/// WGS 84).
fn check_geographic(
    line: Option<LineString>,
    geographic: bool,
    srid: Option<i64>,
) -> Result<Option<LineString>, String> {
    if let (true, Some(l)) = (geographic, &line) {
        if let Some((x, y)) = l
            .points
            .iter()
            .find(|(x, y)| x.abs() > crs::MAX_LONGITUDE || y.abs() > crs::MAX_LATITUDE)
        {
            return Err(format!(
                "the coordinates ({}, {}) are not longitude and latitude, although the layer is \
                 in EPSG:{}, a longitude/latitude system (a GeoJSON without crs is in WGS 84, \
                 EPSG:4326); if they are in a projected system, name it with --srid N (such as \
                 --srid 27700)",
                short(*x),
                short(*y),
                srid.unwrap_or(WGS84)
            ));
        }
    }
    Ok(line)
}

/// The one line of a geometry, or why it is not one.
fn line_of(g: Geometry) -> Result<Option<LineString>, String> {
    match g {
        Geometry::None => Ok(None),
        Geometry::Other(kind) => Err(format!(
            "the geometry is a {kind}; a segment is a line (LineString)"
        )),
        Geometry::Lines { kind, mut parts } => {
            parts.retain(|p| !p.is_empty());
            match parts.len() {
                0 => Ok(None),
                1 => {
                    let points = parts.pop().unwrap_or_default();
                    if points.len() < 2 {
                        return Err(format!(
                            "the {kind} has {} point; a line needs at least 2",
                            points.len()
                        ));
                    }
                    if points.iter().any(|(x, y)| !x.is_finite() || !y.is_finite()) {
                        return Err(format!(
                            "the {kind} has a coordinate that is not a finite number"
                        ));
                    }
                    Ok(Some(LineString { points }))
                }
                n => Err(format!(
                    "the {kind} has {n} parts; a segment is one line: split the feature into {n} \
                     segments or merge its parts"
                )),
            }
        }
    }
}

// --- GeoPackage --------------------------------------------------------------------------------

/// A SQL identifier, double-quoted.
fn quote(id: &str) -> String {
    format!("\"{}\"", id.replace('"', "\"\""))
}

fn read_gpkg(path: &Path, wanted: Option<&str>) -> Result<Layer, String> {
    let flags = OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX;
    let conn = Connection::open_with_flags(path, flags)
        .map_err(|e| format!("cannot open the GeoPackage: {e}"))?;
    let sql = |e: rusqlite::Error| format!("cannot read the GeoPackage: {e}");
    let layers: Vec<String> = conn
        .prepare(
            "SELECT table_name FROM gpkg_contents WHERE data_type = 'features' ORDER BY table_name",
        )
        .and_then(|mut s| s.query_map([], |r| r.get(0))?.collect())
        .map_err(|e| format!("not a GeoPackage (no readable gpkg_contents table: {e})"))?;
    let name = match wanted {
        Some(w) => layers
            .iter()
            .find(|l| l.eq_ignore_ascii_case(w))
            .cloned()
            .ok_or_else(|| {
                format!(
                    "--layer {w}: no such feature layer; the GeoPackage has: {}",
                    layers.join(", ")
                )
            })?,
        None => match layers.as_slice() {
            [one] => one.clone(),
            [] => return Err("the GeoPackage has no feature layer".into()),
            many => {
                return Err(format!(
                    "the GeoPackage has {} feature layers ({}); choose one with --layer NAME",
                    many.len(),
                    many.join(", ")
                ))
            }
        },
    };
    let (geometry_field, srs_id): (String, i64) = conn
        .query_row(
            "SELECT column_name, srs_id FROM gpkg_geometry_columns WHERE table_name = ?1",
            [&name],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .map_err(|e| format!("layer {name}: no geometry column in gpkg_geometry_columns ({e})"))?;
    let srs: Option<(String, i64)> = conn
        .query_row(
            "SELECT organization, organization_coordsys_id FROM gpkg_spatial_ref_sys \
             WHERE srs_id = ?1",
            [srs_id],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .ok();
    let (srid, srid_problem) = match srs {
        Some((org, code)) if org.eq_ignore_ascii_case("EPSG") && code > 0 => (Some(code), None),
        Some((org, code)) => (
            None,
            Some(format!(
                "the layer's coordinate system (srs_id {srs_id}, {org}:{code}) has no EPSG code; \
                 save the layer in an EPSG system (such as 27700 or 4326)"
            )),
        ),
        None => (
            None,
            Some(format!(
                "the layer's srs_id {srs_id} is not in gpkg_spatial_ref_sys"
            )),
        ),
    };
    let columns: Vec<(String, bool)> = conn
        .prepare("SELECT name, pk FROM pragma_table_info(?1) ORDER BY cid")
        .and_then(|mut s| {
            s.query_map([&name], |r| Ok((r.get(0)?, r.get::<_, i64>(1)? > 0)))?
                .collect()
        })
        .map_err(sql)?;
    let fid = columns
        .iter()
        .find(|(_, pk)| *pk)
        .map(|(c, _)| c.clone())
        .unwrap_or_else(|| "rowid".into());
    let fields: Vec<String> = columns
        .iter()
        .filter(|(c, pk)| !pk && !c.eq_ignore_ascii_case(&geometry_field))
        .map(|(c, _)| c.clone())
        .collect();
    let mut select: Vec<String> = vec![quote(&fid), quote(&geometry_field)];
    select.extend(fields.iter().map(|f| quote(f)));
    let mut stmt = conn
        .prepare(&format!(
            "SELECT {} FROM {} ORDER BY 1",
            select.join(", "),
            quote(&name)
        ))
        .map_err(sql)?;
    let n = fields.len();
    // Cells are read as ValueRef: text that is not UTF-8 (a Latin-1 name from a legacy GIS)
    // is noted, never converted (rusqlite's Value conversion panics on it).
    let mut rows = stmt.query([]).map_err(sql)?;
    let mut features = Vec::new();
    while let Some(r) = rows.next().map_err(sql)? {
        let i = features.len();
        let cell = |k: usize| r.get_ref(k).map_err(sql);
        let fid = match cell(0)? {
            ValueRef::Integer(k) => u64::try_from(k).unwrap_or(i as u64 + 1),
            _ => i as u64 + 1,
        };
        let geometry = match cell(1)? {
            ValueRef::Null => Ok(Geometry::None),
            ValueRef::Blob(b) => gpkg_geometry(b),
            _ => Err("the geometry is not a GeoPackage geometry blob".to_string()),
        };
        let mut values = Vec::with_capacity(n);
        let mut not_utf8 = Vec::new();
        for k in 0..n {
            values.push(match cell(k + 2)? {
                ValueRef::Null => String::new(),
                ValueRef::Integer(v) => v.to_string(),
                ValueRef::Real(x) => x.to_string(),
                ValueRef::Text(t) | ValueRef::Blob(t) => match std::str::from_utf8(t) {
                    Ok(t) => t.to_string(),
                    Err(_) => {
                        not_utf8.push(k);
                        String::new()
                    }
                },
            });
        }
        features.push(Feature {
            fid,
            values,
            not_utf8,
            geometry,
        });
    }
    Ok(Layer {
        name,
        fields,
        geometry_field,
        srid,
        srid_problem,
        features,
    })
}

/// A little reader of bytes that never reads past the end.
struct Bytes<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Bytes<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.b.len());
        let end = end.ok_or_else(|| {
            format!(
                "the geometry blob ends early (byte {} of {})",
                self.at,
                self.b.len()
            )
        })?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
    fn u32(&mut self, le: bool) -> Result<u32, String> {
        let a: [u8; 4] = self.take(4)?.try_into().map_err(|_| "short read")?;
        Ok(if le {
            u32::from_le_bytes(a)
        } else {
            u32::from_be_bytes(a)
        })
    }
    fn f64(&mut self, le: bool) -> Result<f64, String> {
        let a: [u8; 8] = self.take(8)?.try_into().map_err(|_| "short read")?;
        Ok(if le {
            f64::from_le_bytes(a)
        } else {
            f64::from_be_bytes(a)
        })
    }
    fn remaining(&self) -> usize {
        self.b.len() - self.at
    }
}

/// A GeoPackage geometry blob (OGC 12-128r18 §2.1.3): header "GP", version, flags, srs_id,
/// envelope, then ISO WKB.
pub(super) fn gpkg_geometry(blob: &[u8]) -> Result<Geometry, String> {
    let mut r = Bytes { b: blob, at: 0 };
    if r.take(2)? != b"GP" {
        return Err("the geometry is not a GeoPackage geometry blob (no 'GP' header)".into());
    }
    let _version = r.u8()?;
    let flags = r.u8()?;
    if flags & 0b0010_0000 != 0 {
        return Err("the geometry uses an extended GeoPackage geometry type".into());
    }
    let le = flags & 1 == 1;
    let _srs_id = r.u32(le)?;
    let envelope = match (flags >> 1) & 0b111 {
        0 => 0,
        1 => 32,
        2 | 3 => 48,
        4 => 64,
        k => {
            return Err(format!(
                "the geometry blob has an invalid envelope code {k}"
            ))
        }
    };
    r.take(envelope)?;
    if flags & 0b0001_0000 != 0 {
        return Ok(Geometry::None);
    }
    wkb(&mut r)
}

/// Names of the WKB geometry types, by base code.
fn wkb_name(base: u32) -> String {
    match base {
        1 => "Point".into(),
        3 => "Polygon".into(),
        4 => "MultiPoint".into(),
        6 => "MultiPolygon".into(),
        7 => "GeometryCollection".into(),
        k => format!("geometry of WKB type {k}"),
    }
}

/// A WKB header: byte order, base type code and coordinate dimension (ISO codes 1000/2000/3000
/// for Z/M/ZM, and the EWKB high bits, both accepted).
fn wkb_header(r: &mut Bytes<'_>) -> Result<(bool, u32, usize), String> {
    let le = match r.u8()? {
        0 => false,
        1 => true,
        b => return Err(format!("the WKB byte-order mark is {b}, not 0 or 1")),
    };
    let t = r.u32(le)?;
    let (z, m) = (t & 0x8000_0000 != 0, t & 0x4000_0000 != 0);
    let t = t & 0x0FFF_FFFF;
    let (base, dims) = match t / 1000 {
        0 => (t, 2 + usize::from(z) + usize::from(m)),
        1 | 2 => (t % 1000, 3),
        3 => (t % 1000, 4),
        _ => return Err(format!("unknown WKB geometry type {t}")),
    };
    Ok((le, base, dims))
}

/// The points of a WKB LineString body.
fn wkb_points(r: &mut Bytes<'_>, le: bool, dims: usize) -> Result<Vec<(f64, f64)>, String> {
    let n = r.u32(le)? as usize;
    if n.saturating_mul(dims * 8) > r.remaining() {
        return Err(format!("the geometry blob says {n} points but holds fewer"));
    }
    let mut pts = Vec::with_capacity(n);
    for _ in 0..n {
        let x = r.f64(le)?;
        let y = r.f64(le)?;
        for _ in 2..dims {
            r.f64(le)?;
        }
        pts.push((x, y));
    }
    Ok(pts)
}

fn wkb(r: &mut Bytes<'_>) -> Result<Geometry, String> {
    let (le, base, dims) = wkb_header(r)?;
    match base {
        2 => Ok(Geometry::Lines {
            kind: "LineString",
            parts: vec![wkb_points(r, le, dims)?],
        }),
        5 => {
            let n = r.u32(le)? as usize;
            // Each part takes at least 9 bytes (its header and point count).
            if n.saturating_mul(9) > r.remaining() {
                return Err(format!("the geometry blob says {n} parts but holds fewer"));
            }
            let mut parts = Vec::with_capacity(n);
            for _ in 0..n {
                let (ple, pbase, pdims) = wkb_header(r)?;
                if pbase != 2 {
                    return Err(format!(
                        "a MultiLineString part is a {}, not a LineString",
                        wkb_name(pbase)
                    ));
                }
                parts.push(wkb_points(r, ple, pdims)?);
            }
            Ok(Geometry::Lines {
                kind: "MultiLineString",
                parts,
            })
        }
        b => Ok(Geometry::Other(wkb_name(b))),
    }
}

// --- GeoJSON -----------------------------------------------------------------------------------

fn read_geojson(data: &[u8], stem: &str, given_srid: Option<i64>) -> Result<Layer, String> {
    // A byte-order mark, as Windows tools write, is not part of the JSON.
    let data = data.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(data);
    let text = std::str::from_utf8(data).map_err(|e| {
        format!(
            "the GeoJSON is not UTF-8 text (byte {}); save it as UTF-8",
            e.valid_up_to()
        )
    })?;
    let doc: serde_json::Value =
        serde_json::from_str(text).map_err(|e| format!("the GeoJSON cannot be read: {e}"))?;
    let gj = geojson::GeoJson::from_json_value(doc.clone())
        .map_err(|e| format!("the file is not GeoJSON: {e}"))?;
    let features = match gj {
        geojson::GeoJson::FeatureCollection(fc) => fc.features,
        geojson::GeoJson::Feature(f) => vec![f],
        geojson::GeoJson::Geometry(_) => {
            return Err("the GeoJSON is a bare geometry; a layer is a FeatureCollection".into())
        }
    };
    // RFC 7946 GeoJSON is WGS 84; GDAL still writes the 2008 `crs` member for other systems.
    let (srid, srid_problem) = match doc.get("crs") {
        None | Some(serde_json::Value::Null) => (Some(given_srid.unwrap_or(WGS84)), None),
        Some(crs) => {
            let name = crs
                .pointer("/properties/name")
                .and_then(|v| v.as_str())
                .unwrap_or("");
            match crs_name_epsg(name) {
                Some(s) if given_srid.is_some_and(|g| g != s) => {
                    return Err(format!(
                        "the GeoJSON names its crs '{name}' (EPSG:{s}) but --srid says {}; \
                         --srid is for a file that does not name its CRS",
                        given_srid.unwrap_or(s)
                    ))
                }
                Some(s) => (Some(s), None),
                None => (
                    None,
                    Some(format!(
                        "the GeoJSON's crs '{name}' is not an EPSG code pipewave can read \
                         (expected urn:ogc:def:crs:EPSG::NNNN)"
                    )),
                ),
            }
        }
    };
    let name = doc
        .get("name")
        .and_then(|v| v.as_str())
        .unwrap_or(stem)
        .to_string();
    let mut fields: Vec<String> = Vec::new();
    for f in &features {
        for k in f.properties.iter().flat_map(|p| p.keys()) {
            if !fields.contains(k) {
                fields.push(k.clone());
            }
        }
    }
    let features = features
        .into_iter()
        .enumerate()
        .map(|(i, f)| {
            let fid = match &f.id {
                Some(geojson::feature::Id::Number(n)) => n.as_u64().unwrap_or(i as u64 + 1),
                _ => i as u64 + 1,
            };
            let values = fields
                .iter()
                .map(|k| match f.properties.as_ref().and_then(|p| p.get(k)) {
                    None | Some(serde_json::Value::Null) => String::new(),
                    Some(serde_json::Value::String(s)) => s.clone(),
                    Some(v) => v.to_string(),
                })
                .collect();
            let geometry = match f.geometry.map(|g| g.value) {
                None => Ok(Geometry::None),
                Some(geojson::Value::LineString(pts)) => positions(&pts).map(|p| Geometry::Lines {
                    kind: "LineString",
                    parts: vec![p],
                }),
                Some(geojson::Value::MultiLineString(parts)) => parts
                    .iter()
                    .map(|p| positions(p))
                    .collect::<Result<Vec<_>, _>>()
                    .map(|parts| Geometry::Lines {
                        kind: "MultiLineString",
                        parts,
                    }),
                Some(other) => Ok(Geometry::Other(
                    match other {
                        geojson::Value::Point(_) => "Point",
                        geojson::Value::MultiPoint(_) => "MultiPoint",
                        geojson::Value::Polygon(_) => "Polygon",
                        geojson::Value::MultiPolygon(_) => "MultiPolygon",
                        _ => "GeometryCollection",
                    }
                    .to_string(),
                )),
            };
            Feature {
                fid,
                values,
                not_utf8: Vec::new(),
                geometry,
            }
        })
        .collect();
    Ok(Layer {
        name,
        fields,
        geometry_field: "geometry".into(),
        srid,
        srid_problem,
        features,
    })
}

/// GeoJSON positions as (x, y); a position needs at least two numbers.
fn positions(pts: &[Vec<f64>]) -> Result<Vec<(f64, f64)>, String> {
    pts.iter()
        .enumerate()
        .map(|(i, p)| match p.as_slice() {
            [x, y, ..] => Ok((*x, *y)),
            _ => Err(format!("position {} has fewer than two numbers", i + 1)),
        })
        .collect()
}

/// The EPSG code of an OGC CRS name: `urn:ogc:def:crs:EPSG::27700`, `EPSG:27700`, or CRS84.
fn crs_name_epsg(name: &str) -> Option<i64> {
    let n = name.trim();
    if n.to_ascii_uppercase().ends_with("CRS84") {
        return Some(WGS84);
    }
    let upper = n.to_ascii_uppercase();
    let at = upper.rfind("EPSG")?;
    let code = upper[at + 4..].trim_start_matches(':');
    // `urn:ogc:def:crs:EPSG:9.9:27700` carries a version between the colons.
    let code = code.rsplit(':').next()?;
    code.parse().ok().filter(|&c: &i64| c > 0)
}

// --- Shapefile ---------------------------------------------------------------------------------

fn read_shapefile(
    shp: &[u8],
    dbf: Option<&[u8]>,
    prj: Option<&[u8]>,
    stem: &str,
) -> Result<Layer, String> {
    let dbf = dbf.ok_or_else(|| {
        format!("the Shapefile has no {stem}.dbf beside it (its attribute table)")
    })?;
    check_shp(shp)?;
    let shapes = shapefile::ShapeReader::new(Cursor::new(shp))
        .and_then(|r| r.read())
        .map_err(|e| format!("the .shp cannot be read: {e}"))?;
    let mut table = shapefile::dbase::Reader::new(Cursor::new(dbf))
        .map_err(|e| format!("the .dbf cannot be read: {e}"))?;
    let fields: Vec<String> = table
        .fields()
        .iter()
        .map(|f| f.name().to_string())
        .collect();
    let records = table
        .read()
        .map_err(|e| format!("the .dbf cannot be read: {e}"))?;
    if records.len() != shapes.len() {
        return Err(format!(
            "the .shp has {} shapes but the .dbf {} records; the two files do not belong together",
            shapes.len(),
            records.len()
        ));
    }
    let (srid, srid_problem) = match prj {
        None => (
            None,
            Some(format!(
                "the Shapefile has no {stem}.prj beside it, so its coordinate system is unknown"
            )),
        ),
        Some(p) => {
            let wkt = String::from_utf8_lossy(p);
            match prj_epsg(&wkt) {
                Some(s) => (Some(s), None),
                None => (
                    None,
                    Some(format!(
                        "the .prj names a coordinate system pipewave cannot match to an EPSG code \
                         ('{}'); save the layer in a common EPSG system, or export it as a \
                         GeoPackage",
                        wkt_name(&wkt).unwrap_or("unnamed")
                    )),
                ),
            }
        }
    };
    let features = shapes
        .into_iter()
        .zip(records)
        .enumerate()
        .map(|(i, (shape, rec))| {
            let values = fields
                .iter()
                .map(|f| rec.get(f).map(dbf_text).unwrap_or_default())
                .collect();
            Feature {
                fid: i as u64 + 1,
                values,
                not_utf8: Vec::new(),
                geometry: Ok(shape_geometry(shape)),
            }
        })
        .collect();
    Ok(Layer {
        name: stem.to_string(),
        fields,
        geometry_field: "shape".into(),
        srid,
        srid_problem,
        features,
    })
}

/// Check the record structure of a `.shp` (ESRI Shapefile Technical Description, 1998) before
/// the `shapefile` crate reads it: every record inside the file, and every part and point count
/// non-negative and within its record. The crate trusts these counts (a negative part count
/// makes it allocate without bound and panic), so a damaged file must be refused here.
fn check_shp(shp: &[u8]) -> Result<(), String> {
    const HEADER: usize = 100;
    let be = |at: usize| -> Option<i64> {
        Some(i64::from(i32::from_be_bytes(
            shp.get(at..at + 4)?.try_into().ok()?,
        )))
    };
    let le = |at: usize| -> Option<i64> {
        Some(i64::from(i32::from_le_bytes(
            shp.get(at..at + 4)?.try_into().ok()?,
        )))
    };
    if shp.len() < HEADER || be(0) != Some(9994) {
        return Err("the .shp is not an ESRI Shapefile (no 100-byte header with code 9994)".into());
    }
    let mut at = HEADER;
    let mut record = 0;
    while at < shp.len() {
        record += 1;
        let bad = |why: &str| format!("the .shp is damaged at record {record}: {why}");
        let len = be(at + 4).ok_or_else(|| bad("the record header is cut short"))?;
        if len < 2 {
            return Err(bad("its length is less than a shape type"));
        }
        let bytes = usize::try_from(len * 2).map_err(|_| bad("its length is too large"))?;
        let start = at + 8;
        let end = start
            .checked_add(bytes)
            .filter(|&e| e <= shp.len())
            .ok_or_else(|| bad("it runs past the end of the file"))?;
        let shape_type = le(start).ok_or_else(|| bad("no shape type"))?;
        // (offset of the part count or None, offset of the point count, bytes per part index)
        let counts = match shape_type {
            3 | 5 | 13 | 15 | 23 | 25 => Some((Some(36), 40, 4, 44)),
            31 => Some((Some(36), 40, 8, 44)),
            8 | 18 | 28 => Some((None, 36, 0, 40)),
            _ => None,
        };
        if let Some((parts_at, points_at, per_part, base)) = counts {
            let parts = match parts_at {
                Some(p) => le(start + p).ok_or_else(|| bad("the part count is cut short"))?,
                None => 0,
            };
            let points =
                le(start + points_at).ok_or_else(|| bad("the point count is cut short"))?;
            if parts < 0 || points < 0 {
                return Err(bad("a negative part or point count"));
            }
            let need = base + parts * per_part + points * 16;
            if need > len * 2 {
                return Err(bad("its part and point counts do not fit in it"));
            }
            // Each part starts at a point index: increasing, from 0, within the points.
            let mut previous = 0;
            for k in 0..parts {
                let first = usize::try_from(k * 4)
                    .ok()
                    .map(|o| start + base as usize + o);
                let first = first
                    .and_then(le)
                    .ok_or_else(|| bad("a part index is cut short"))?;
                if first < previous || first > points || (k == 0 && first != 0) {
                    return Err(bad("its part indices are not increasing point numbers"));
                }
                previous = first;
            }
        }
        at = end;
    }
    Ok(())
}

fn shape_geometry(shape: shapefile::Shape) -> Geometry {
    use shapefile::Shape;
    let lines = |parts: Vec<Vec<(f64, f64)>>| Geometry::Lines {
        kind: if parts.len() == 1 {
            "Polyline"
        } else {
            "Polyline (multi-part)"
        },
        parts,
    };
    match shape {
        Shape::NullShape => Geometry::None,
        Shape::Polyline(l) => lines(
            l.parts()
                .iter()
                .map(|p| p.iter().map(|q| (q.x, q.y)).collect())
                .collect(),
        ),
        Shape::PolylineM(l) => lines(
            l.parts()
                .iter()
                .map(|p| p.iter().map(|q| (q.x, q.y)).collect())
                .collect(),
        ),
        Shape::PolylineZ(l) => lines(
            l.parts()
                .iter()
                .map(|p| p.iter().map(|q| (q.x, q.y)).collect())
                .collect(),
        ),
        other => Geometry::Other(format!("{} shape", other.shapetype())),
    }
}

/// A dBase value as text: numbers in their shortest round-trip form (a `Float` field is 32-bit,
/// printed as such, so 5.3 reads back as 5.3).
fn dbf_text(v: &shapefile::dbase::FieldValue) -> String {
    use shapefile::dbase::FieldValue as F;
    match v {
        F::Character(s) => s.clone().unwrap_or_default(),
        F::Numeric(x) => x.map(|x| x.to_string()).unwrap_or_default(),
        F::Float(x) => x.map(|x| x.to_string()).unwrap_or_default(),
        F::Logical(b) => b.map(|b| b.to_string()).unwrap_or_default(),
        F::Date(d) => d
            .map(|d| format!("{:04}-{:02}-{:02}", d.year(), d.month(), d.day()))
            .unwrap_or_default(),
        F::Integer(i) => i.to_string(),
        F::Currency(x) | F::Double(x) => x.to_string(),
        F::DateTime(t) => {
            let d = t.date();
            format!("{:04}-{:02}-{:02}", d.year(), d.month(), d.day())
        }
        F::Memo(s) => s.clone(),
    }
}

/// The first quoted string of a WKT: the coordinate system's name.
fn wkt_name(wkt: &str) -> Option<&str> {
    let start = wkt.find('"')? + 1;
    let len = wkt[start..].find('"')?;
    Some(&wkt[start..start + len])
}

/// Lower case, letters and digits only: `WGS_1984_UTM_Zone_32N` -> `wgs1984utmzone32n`.
fn squash(s: &str) -> String {
    s.chars()
        .filter(char::is_ascii_alphanumeric)
        .map(|c| c.to_ascii_lowercase())
        .collect()
}

/// ESRI names of common systems (as ArcGIS and GDAL write them in a `.prj`, without an EPSG
/// authority), squashed, and their EPSG codes.
const ESRI_NAMES: &[(&str, i64)] = &[
    ("britishnationalgrid", 27700),
    ("osgb1936britishnationalgrid", 27700),
    ("gcsosgb1936", 4277),
    ("gcswgs1984", 4326),
    ("wgs84", 4326),
    ("wgs1984webmercatorauxiliarysphere", 3857),
    ("wgs84pseudomercator", 3857),
    ("gcsetrs1989", 4258),
    ("etrs1989laea", 3035),
    ("etrs89laeaeurope", 3035),
    ("rgf1993lambert93", 2154),
    ("rgf93lambert93", 2154),
    ("irenet95irishtransversemercator", 2157),
    ("nad1983", 4269),
    ("gcsnorthamerican1983", 4269),
];

/// The EPSG code of a `.prj` (OGC or ESRI WKT 1): the coordinate system's own
/// `AUTHORITY["EPSG","N"]` (the last one in the text), else its name: a common ESRI name
/// ([`ESRI_NAMES`]) or a UTM zone on WGS 84 (326NN/327NN), ETRS89 (258NN) or NAD83 (269NN).
pub(super) fn prj_epsg(wkt: &str) -> Option<i64> {
    let upper = wkt.to_ascii_uppercase();
    if let Some(at) = upper.rfind("AUTHORITY[") {
        let tail = &upper[at..];
        let end = tail.find(']').unwrap_or(tail.len());
        let parts: Vec<&str> = tail[..end]
            .split(['"', ',', '['])
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .collect();
        // Only the outermost node's authority names the system itself: it closes the WKT.
        let closes = tail[end..]
            .trim_matches(|c: char| c == ']' || c.is_whitespace())
            .is_empty();
        if let ["AUTHORITY", "EPSG", code] = parts.as_slice() {
            if closes {
                if let Ok(c) = code.parse::<i64>() {
                    return Some(c);
                }
            }
        }
    }
    let name = squash(wkt_name(wkt)?);
    if let Some(&(_, code)) = ESRI_NAMES.iter().find(|(n, _)| *n == name) {
        return Some(code);
    }
    for (prefix, north, south) in [
        ("wgs1984utmzone", 32600, Some(32700)),
        ("wgs84utmzone", 32600, Some(32700)),
        ("etrs1989utmzone", 25800, None),
        ("etrs89utmzone", 25800, None),
        ("nad1983utmzone", 26900, None),
        ("nad83utmzone", 26900, None),
    ] {
        let Some(rest) = name.strip_prefix(prefix) else {
            continue;
        };
        let (zone, hemi) = rest.split_at(rest.len().saturating_sub(1));
        let zone: i64 = zone.parse().ok().filter(|z| (1..=60).contains(z))?;
        return match hemi {
            "n" => Some(north + zone),
            "s" => south.map(|s| s + zone),
            _ => None,
        };
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blob(wkb: &[u8], flags: u8) -> Vec<u8> {
        let mut b = b"GP\0".to_vec();
        b.push(flags);
        b.extend_from_slice(&27700i32.to_le_bytes());
        if (flags >> 1) & 7 == 1 {
            b.extend_from_slice(&[0u8; 32]);
        }
        b.extend_from_slice(wkb);
        b
    }

    fn wkb_line(pts: &[(f64, f64)], ty: u32) -> Vec<u8> {
        let mut b = vec![1u8];
        b.extend_from_slice(&ty.to_le_bytes());
        b.extend_from_slice(&(pts.len() as u32).to_le_bytes());
        for (x, y) in pts {
            b.extend_from_slice(&x.to_le_bytes());
            b.extend_from_slice(&y.to_le_bytes());
        }
        b
    }

    #[test]
    fn geopackage_blobs_of_lines_and_one_part_multilines() {
        let pts = [(1.0, 2.0), (3.5, -4.0)];
        let g = gpkg_geometry(&blob(&wkb_line(&pts, 2), 0b11)).unwrap();
        assert_eq!(line_of(g).unwrap().unwrap().points, pts);
        let mut multi = vec![1u8];
        multi.extend_from_slice(&5u32.to_le_bytes());
        multi.extend_from_slice(&1u32.to_le_bytes());
        multi.extend_from_slice(&wkb_line(&pts, 2));
        let g = gpkg_geometry(&blob(&multi, 1)).unwrap();
        assert_eq!(line_of(g).unwrap().unwrap().points, pts);
        // Two parts: rejected, naming the count.
        let mut two = vec![1u8];
        two.extend_from_slice(&5u32.to_le_bytes());
        two.extend_from_slice(&2u32.to_le_bytes());
        two.extend_from_slice(&wkb_line(&pts, 2));
        two.extend_from_slice(&wkb_line(&pts, 2));
        let e = line_of(gpkg_geometry(&blob(&two, 1)).unwrap()).unwrap_err();
        assert!(e.contains("MultiLineString has 2 parts"), "{e}");
        // A point count larger than the blob: an error, no huge allocation.
        let mut lie = wkb_line(&pts, 2);
        lie[5..9].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(gpkg_geometry(&blob(&lie, 1)).is_err());
        // Empty flag.
        assert_eq!(gpkg_geometry(&blob(&[], 0b1_0001)).unwrap(), Geometry::None);
    }

    fn fuzz_config() -> proptest::test_runner::Config {
        let cases = std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(256);
        proptest::test_runner::Config {
            cases,
            failure_persistence: None,
            ..Default::default()
        }
    }

    proptest::proptest! {
        #![proptest_config(fuzz_config())]

        /// No panic on any blob, and a huge count never allocates: an error instead.
        #[test]
        fn geopackage_blobs_of_arbitrary_bytes(
            flags in proptest::num::u8::ANY,
            tail in proptest::collection::vec(proptest::num::u8::ANY, 0..200),
        ) {
            let mut b = vec![b'G', b'P', 0, flags];
            b.extend_from_slice(&tail);
            if let Ok(Ok(Some(l))) = gpkg_geometry(&b).map(line_of) {
                proptest::prop_assert!(l.points.len() >= 2);
            }
            let _ = gpkg_geometry(&tail);
        }

        #[test]
        fn prj_files_of_arbitrary_text(t in ".{0,120}") {
            let _ = prj_epsg(&t);
            let _ = crs_name_epsg(&t);
        }
    }

    #[test]
    fn a_damaged_shp_is_refused_before_the_crate_reads_it() {
        let mut shp = vec![0u8; 100];
        shp[..4].copy_from_slice(&9994i32.to_be_bytes());
        let mut rec = Vec::new();
        rec.extend_from_slice(&1i32.to_be_bytes());
        rec.extend_from_slice(&22i32.to_be_bytes()); // 44 bytes of content
        rec.extend_from_slice(&3i32.to_le_bytes()); // polyline
        rec.extend_from_slice(&[0u8; 32]);
        rec.extend_from_slice(&(-5i32).to_le_bytes());
        rec.extend_from_slice(&0i32.to_le_bytes());
        shp.extend_from_slice(&rec);
        let e = check_shp(&shp).unwrap_err();
        assert!(
            e.contains("record 1: a negative part or point count"),
            "{e}"
        );
        assert!(check_shp(b"not a shapefile").is_err());
        // A part index past the points (found by the fuzz test: the crate's subtraction
        // overflowed).
        let n = shp.len();
        shp[n - 8..n - 4].copy_from_slice(&1i32.to_le_bytes());
        shp[n - 4..].copy_from_slice(&2i32.to_le_bytes());
        shp[107] = 40; // 80 bytes: the counts, one part index and two points
        shp.extend_from_slice(&256i32.to_le_bytes());
        shp.extend_from_slice(&[0u8; 32]);
        let e = check_shp(&shp).unwrap_err();
        assert!(e.contains("part indices"), "{e}");
    }

    #[test]
    fn epsg_codes_from_prj_files_and_crs_names() {
        let bng =
            "PROJCS[\"British_National_Grid\",GEOGCS[\"GCS_OSGB_1936\",DATUM[\"D_OSGB_1936\",\
                   SPHEROID[\"Airy_1830\",6377563.396,299.3249646]],PRIMEM[\"Greenwich\",0.0],\
                   UNIT[\"Degree\",0.0174532925199433]],PROJECTION[\"Transverse_Mercator\"],\
                   UNIT[\"Meter\",1.0]]";
        assert_eq!(prj_epsg(bng), Some(27700));
        let with_auth = "PROJCS[\"x\",GEOGCS[\"y\",AUTHORITY[\"EPSG\",\"4277\"]],AUTHORITY[\"EPSG\",\"27700\"]]";
        assert_eq!(prj_epsg(with_auth), Some(27700));
        assert_eq!(
            prj_epsg("PROJCS[\"WGS_1984_UTM_Zone_32N\",GEOGCS[]]"),
            Some(32632)
        );
        assert_eq!(
            prj_epsg("PROJCS[\"WGS_1984_UTM_Zone_18S\",GEOGCS[]]"),
            Some(32718)
        );
        assert_eq!(
            prj_epsg("PROJCS[\"ETRS_1989_UTM_Zone_33N\",GEOGCS[]]"),
            Some(25833)
        );
        assert_eq!(prj_epsg("GEOGCS[\"GCS_WGS_1984\",DATUM[]]"), Some(4326));
        assert_eq!(prj_epsg("PROJCS[\"Local grid\"]"), None);
        assert_eq!(prj_epsg(""), None);
        assert_eq!(crs_name_epsg("urn:ogc:def:crs:EPSG::27700"), Some(27700));
        assert_eq!(crs_name_epsg("EPSG:3857"), Some(3857));
        assert_eq!(crs_name_epsg("urn:ogc:def:crs:OGC:1.3:CRS84"), Some(4326));
        assert_eq!(crs_name_epsg("local"), None);
    }
}
