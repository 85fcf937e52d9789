//! RFC 7946 GeoJSON writer: a FeatureCollection in WGS 84 longitude/latitude (reprojected from
//! each segment's system), no `crs` member, coordinates rounded to [`COORD_DECIMALS`] decimals,
//! `"geometry": null` for segments without geometry. Properties as [`columns`], numbers as
//! [`Precision`] says (a rounded number is written as the JSON number of its printed text).

use std::collections::HashMap;
use std::io::Write as _;
use std::path::Path;

use serde_json::{json, Map, Number, Value as Json};

use super::numbers::{columns, Cell, Precision};
use super::record::Records;
use super::{write_streamed, ExportError, SegmentExport, Tally};
use crate::db::crs::{CrsError, Reprojector, WGS84};

/// Decimals of the written longitudes and latitudes: 1e-7 degree is about 1 cm, as RFC 7946
/// §11.2 suggests (more precision than that is noise).
pub const COORD_DECIMALS: i32 = 7;

fn round_coord(v: f64) -> f64 {
    let k = 10f64.powi(COORD_DECIMALS);
    (v * k).round() / k
}

/// The JSON value of a printed cell.
fn json_cell(c: Cell<'_>) -> Json {
    match c {
        Cell::Null => Json::Null,
        Cell::Text(s) => Json::String(s.to_string()),
        Cell::Number(n) => match n.parse::<i64>() {
            Ok(i) if !n.contains(['.', 'e']) => Json::Number(i.into()),
            _ => n
                .parse::<f64>()
                .ok()
                .and_then(Number::from_f64)
                .map_or(Json::Null, Json::Number),
        },
    }
}

/// The reprojector of each coordinate system met, built once.
type Projectors = HashMap<i64, Result<Reprojector, CrsError>>;

/// One record's Feature (its geometry `null`, with a warning, when it cannot be put in WGS 84).
fn feature(
    rec: &SegmentExport,
    precision: Precision,
    projectors: &mut Projectors,
    warnings: &mut Vec<String>,
) -> Json {
    let geometry = match (&rec.geometry, rec.segment.srid) {
        (Some(line), Some(srid)) => {
            let r = projectors
                .entry(srid)
                .or_insert_with(|| Reprojector::new(srid, WGS84));
            let wgs = match r {
                Ok(r) => r.line(line).map_err(|e| e.to_string()),
                Err(e) => Err(e.to_string()),
            };
            match wgs.and_then(|l| {
                if l.points.iter().all(|&(lon, lat)| {
                    (-180.0..=180.0).contains(&lon) && (-90.0..=90.0).contains(&lat)
                }) {
                    Ok(l)
                } else {
                    Err(format!(
                        "its coordinates are not in EPSG:{srid}'s valid area"
                    ))
                }
            }) {
                Ok(l) => {
                    let coords: Vec<Json> = l
                        .points
                        .iter()
                        .map(|&(lon, lat)| json!([round_coord(lon), round_coord(lat)]))
                        .collect();
                    json!({"type": "LineString", "coordinates": coords})
                }
                Err(e) => {
                    warnings.push(format!(
                        "segment {}: cannot convert its geometry to WGS 84 ({e}); exported \
                         without geometry",
                        rec.id()
                    ));
                    Json::Null
                }
            }
        }
        (Some(_), None) => {
            warnings.push(format!(
                "segment {}: its geometry has no srid, so its coordinate system is unknown; \
                 exported without geometry",
                rec.id()
            ));
            Json::Null
        }
        (None, _) => Json::Null,
    };
    let layout = columns();
    let mut props = Map::with_capacity(layout.properties.len());
    for (p, c) in layout.properties.iter().zip(layout.cells(rec, precision)) {
        props.insert(p.name.to_string(), json_cell(c));
    }
    json!({
        "type": "Feature",
        "id": rec.id(),
        "geometry": geometry,
        "properties": Json::Object(props),
    })
}

/// The whole document, numbers printed at `precision`.
pub fn to_json(
    records: &[SegmentExport],
    precision: Precision,
    warnings: &mut Vec<String>,
) -> Json {
    let mut projectors = Projectors::new();
    let features: Vec<Json> = records
        .iter()
        .map(|rec| feature(rec, precision, &mut projectors, warnings))
        .collect();
    json!({"type": "FeatureCollection", "features": features})
}

/// The document's text before and after its features: the FeatureCollection with no feature,
/// split at its empty `features` array, so the streamed file is byte for byte what
/// `serde_json` writes for the whole document.
fn envelope() -> (String, String) {
    let empty = json!({"type": "FeatureCollection", "features": []}).to_string();
    let at = empty.find("[]").map_or(empty.len(), |i| i + 1);
    (empty[..at].to_string(), empty[at..].to_string())
}

/// Write the GeoJSON of the records to `out`, each feature as it is read.
pub(crate) fn write(
    records: &Records<'_>,
    out: &Path,
    precision: Precision,
) -> Result<Tally, ExportError> {
    let io = |source| ExportError::Write {
        path: out.to_path_buf(),
        source,
    };
    write_streamed(out, |w| {
        let mut tally = Tally::default();
        let mut warnings = Vec::new();
        let mut own_warnings = Vec::new();
        let mut projectors = Projectors::new();
        let (head, tail) = envelope();
        w.write_all(head.as_bytes()).map_err(io)?;
        records.for_each(&mut warnings, |rec| {
            let f = feature(&rec, precision, &mut projectors, &mut own_warnings);
            if tally.summary.segments > 0 {
                w.write_all(b",").map_err(io)?;
            }
            tally.add(&rec);
            tally.summary.with_geometry += usize::from(!f["geometry"].is_null());
            serde_json::to_writer(&mut *w, &f).map_err(|e| {
                if e.is_io() {
                    ExportError::Write {
                        path: out.to_path_buf(),
                        source: e.into(),
                    }
                } else {
                    ExportError::Encode {
                        path: out.to_path_buf(),
                        message: e.to_string(),
                    }
                }
            })
        })?;
        w.write_all(tail.as_bytes()).map_err(io)?;
        warnings.append(&mut own_warnings);
        tally.summary.warnings = warnings;
        Ok(tally)
    })
}
