//! RFC 7946 GeoJSON writer: a FeatureCollection in WGS 84 longitude/latitude (reprojected from
//! each segment's system), no `crs` member, coordinates rounded to [`COORD_DECIMALS`] decimals,
//! `"geometry": null` for segments without geometry. Properties as [`PROPERTIES`].

use std::collections::HashMap;
use std::path::Path;

use serde_json::{json, Map, Number, Value as Json};

use super::crs::{CrsError, Reprojector, WGS84};
use super::record::{Value, PROPERTIES};
use super::{write_file_atomically, ExportError, ExportSummary, SegmentExport};

/// Decimals of the written longitudes and latitudes: 1e-7 degree is about 1 cm, as RFC 7946
/// §11.2 suggests (more precision than that is noise).
pub const COORD_DECIMALS: i32 = 7;

fn round_coord(v: f64) -> f64 {
    let k = 10f64.powi(COORD_DECIMALS);
    (v * k).round() / k
}

/// The JSON value of a property.
pub(crate) fn json_value(v: Value<'_>) -> Json {
    match v {
        Value::Null => Json::Null,
        Value::Text(s) => Json::String(s.to_string()),
        Value::Real(x) => Number::from_f64(x).map_or(Json::Null, Json::Number),
        Value::Integer(i) => Json::Number(i.into()),
    }
}

/// The whole document.
pub fn to_json(records: &[SegmentExport], warnings: &mut Vec<String>) -> Json {
    let mut projectors: HashMap<i64, Result<Reprojector, CrsError>> = HashMap::new();
    let mut features = Vec::with_capacity(records.len());
    for rec in records {
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
            _ => Json::Null,
        };
        let mut props = Map::with_capacity(PROPERTIES.len());
        for p in PROPERTIES {
            props.insert(p.name.to_string(), json_value((p.get)(rec)));
        }
        features.push(json!({
            "type": "Feature",
            "id": rec.id(),
            "geometry": geometry,
            "properties": Json::Object(props),
        }));
    }
    json!({"type": "FeatureCollection", "features": features})
}

/// Write the GeoJSON of `records` to `out`.
pub fn write(records: &[SegmentExport], out: &Path) -> Result<ExportSummary, ExportError> {
    let mut warnings = Vec::new();
    let doc = to_json(records, &mut warnings);
    let with_geometry = doc["features"]
        .as_array()
        .map_or(0, |f| f.iter().filter(|f| !f["geometry"].is_null()).count());
    let bytes = serde_json::to_vec(&doc).map_err(|e| ExportError::Encode {
        path: out.to_path_buf(),
        message: e.to_string(),
    })?;
    write_file_atomically(out, &bytes)?;
    Ok(ExportSummary {
        segments: records.len(),
        with_geometry,
        fitted: records.iter().filter(|r| r.fit.is_some()).count(),
        warnings,
    })
}
