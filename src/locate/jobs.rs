//! The batch form of `locate`: the jobs file (one correlation a row), and the answers as CSV,
//! GeoJSON (a point per leak and its 95 % interval as a line along the pipe) and GeoPackage
//! layers.

use std::path::{Path, PathBuf};

use crate::outfile::{Contents, OutFile};
use rusqlite::{params, Connection};
use serde_json::{json, Value as Json};

use super::gcc::RecordingPair;
use super::network::SensorSpec;
use super::{DelayInput, Job, Located};
use crate::db::crs::{Reprojector, WGS84};
use crate::export::gpkg;
use crate::spreadsheet::{self, spreadsheet_safe};

/// Columns every jobs file has.
pub const REQUIRED_COLUMNS: [&str; 5] = [
    "job_id",
    "sensor1_segment",
    "sensor1_chainage_m",
    "sensor2_segment",
    "sensor2_chainage_m",
];
/// A measured delay.
pub const DELAY_COLUMNS: [&str; 2] = ["delay_s", "delay_std_s"];
/// Two recordings.
pub const RECORDING_COLUMNS: [&str; 4] = ["recording1", "channel1", "recording2", "channel2"];

/// A job file that cannot be used at all (exit 2).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {message}", file.display())]
pub struct JobsFileError {
    /// The file.
    pub file: PathBuf,
    /// What is wrong.
    pub message: String,
}

/// A row that could not be read: its job fails with this message.
#[derive(Debug, Clone, PartialEq)]
pub struct RowFailure {
    /// The job id (or `line N` when the id is blank).
    pub job_id: String,
    /// The message, naming the file, line and column.
    pub message: String,
}

/// Read a jobs file: the jobs, each checked, or the row's failure.
pub fn read_jobs(path: &Path) -> Result<Vec<Result<Job, RowFailure>>, JobsFileError> {
    let ferr = |m: String| JobsFileError {
        file: path.to_path_buf(),
        message: m,
    };
    let mut rdr = csv::ReaderBuilder::new()
        .flexible(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| ferr(format!("cannot read it ({e})")))?;
    let headers: Vec<String> = rdr
        .headers()
        .map_err(|e| ferr(format!("cannot read its header ({e})")))?
        .iter()
        .map(|h| h.trim_start_matches('\u{feff}').to_ascii_lowercase())
        .collect();
    let col = |name: &str| headers.iter().position(|h| h == name);
    let missing: Vec<&str> = REQUIRED_COLUMNS
        .iter()
        .copied()
        .filter(|c| col(c).is_none())
        .collect();
    // Sensors may be map coordinates instead of segment and chainage.
    let by_map =
        |n: u8| col(&format!("sensor{n}_x")).is_some() && col(&format!("sensor{n}_y")).is_some();
    let missing: Vec<&str> = missing
        .into_iter()
        .filter(|c| {
            !(c.starts_with("sensor1") && by_map(1) || c.starts_with("sensor2") && by_map(2))
        })
        .filter(|c| *c != "job_id" || col("job_id").is_some())
        .collect();
    if !missing.is_empty() {
        return Err(ferr(format!(
            "missing column{} {} (a jobs file has {}, then delay_s, delay_std_s or \
             recording1, channel1, recording2, channel2)",
            if missing.len() == 1 { "" } else { "s" },
            missing.join(", "),
            REQUIRED_COLUMNS.join(", ")
        )));
    }
    let has_delay = DELAY_COLUMNS.iter().all(|c| col(c).is_some());
    let has_rec = RECORDING_COLUMNS.iter().all(|c| col(c).is_some());
    if !has_delay && !has_rec {
        return Err(ferr(
            "no delay: give the columns delay_s, delay_std_s (a correlator's delay and its \
             error) or recording1, channel1, recording2, channel2 (two WAV recordings)"
                .into(),
        ));
    }
    let base = path.parent().unwrap_or(Path::new("")).to_path_buf();
    let mut out = Vec::new();
    for (i, rec) in rdr.records().enumerate() {
        let line = i as u64 + 2;
        let rec = rec.map_err(|e| ferr(format!("line {line}: cannot read it ({e})")))?;
        if rec.iter().all(|c| c.is_empty()) {
            continue;
        }
        let cell = |name: &str| col(name).and_then(|j| rec.get(j)).unwrap_or("").trim();
        let id = if cell("job_id").is_empty() {
            format!("line {line}")
        } else {
            cell("job_id").to_string()
        };
        let fail = |column: &str, m: String| RowFailure {
            job_id: id.clone(),
            message: format!("{} line {line}, column {column}: {m}", path.display()),
        };
        let number = |name: &str| -> Result<Option<f64>, RowFailure> {
            let t = cell(name);
            if t.is_empty() {
                return Ok(None);
            }
            t.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .map(Some)
                .ok_or_else(|| fail(name, format!("'{t}' is not a number")))
        };
        let job = (|| -> Result<Job, RowFailure> {
            let sensor = |n: u8| -> Result<SensorSpec, RowFailure> {
                let seg = cell(&format!("sensor{n}_segment"));
                if !seg.is_empty() {
                    let c = format!("sensor{n}_chainage_m");
                    let ch = number(&c)?
                        .ok_or_else(|| fail(&c, "blank: give the chainage in metres".into()))?;
                    return Ok(SensorSpec::OnSegment {
                        segment_id: seg.to_string(),
                        chainage_m: ch,
                    });
                }
                match (number(&format!("sensor{n}_x"))?, number(&format!("sensor{n}_y"))?) {
                    (Some(x), Some(y)) => Ok(SensorSpec::Map { x, y }),
                    _ => Err(fail(
                        &format!("sensor{n}_segment"),
                        "blank: give the segment and chainage (or map coordinates sensor{n}_x, sensor{n}_y)".into(),
                    )),
                }
            };
            let (s1, s2) = (sensor(1)?, sensor(2)?);
            let delay = match (number("delay_s")?, cell("recording1").is_empty()) {
                (Some(d), _) => {
                    let s = number("delay_std_s")?.ok_or_else(|| {
                        fail(
                            "delay_std_s",
                            "blank: give the delay's standard error in seconds".into(),
                        )
                    })?;
                    if s < 0.0 {
                        return Err(fail("delay_std_s", format!("{s} is negative")));
                    }
                    super::check_delay(d, s).map_err(|e| fail("delay_s", e.to_string()))?;
                    DelayInput::Given {
                        delay_s: d,
                        std_s: s,
                    }
                }
                (None, false) => {
                    let ch = |name: &str| -> Result<u16, RowFailure> {
                        let t = cell(name);
                        t.parse::<u16>().map_err(|_| {
                            fail(name, format!("'{t}' is not a channel number (0, 1, ...)"))
                        })
                    };
                    let f2 = cell("recording2");
                    if f2.is_empty() {
                        return Err(fail("recording2", "blank: give sensor 2's WAV file".into()));
                    }
                    DelayInput::Recordings(RecordingPair {
                        file1: base.join(cell("recording1")),
                        channel1: ch("channel1")?,
                        file2: base.join(f2),
                        channel2: ch("channel2")?,
                    })
                }
                (None, true) => {
                    return Err(fail(
                        if has_delay { "delay_s" } else { "recording1" },
                        "blank: give a delay (delay_s, delay_std_s) or two recordings".into(),
                    ))
                }
            };
            let band = match (number("band_lo_hz")?, number("band_hi_hz")?) {
                (None, None) => None,
                (Some(a), Some(b)) => {
                    super::check_band((a, b)).map_err(|e| fail("band_lo_hz", e.to_string()))?;
                    Some((a, b))
                }
                (a, b) => {
                    return Err(fail(
                        "band_lo_hz",
                        format!(
                            "band {}–{} Hz: give both ends, 0 < low < high",
                            a.map_or("blank".into(), |v| v.to_string()),
                            b.map_or("blank".into(), |v| v.to_string())
                        ),
                    ))
                }
            };
            let route = Some(cell("path"))
                .filter(|p| !p.is_empty())
                .map(|p| p.split(';').map(|s| s.trim().to_string()).collect());
            Ok(Job {
                id: id.clone(),
                source: path.to_path_buf(),
                line,
                sensor1: s1,
                sensor2: s2,
                delay,
                band_hz: band,
                path: route,
            })
        })();
        out.push(job);
    }
    if out.is_empty() {
        return Err(ferr("no jobs (the file has a header but no rows)".into()));
    }
    Ok(out)
}

/// Columns of the answers file.
pub const OUTPUT_COLUMNS: [&str; 29] = [
    "job_id",
    "status",
    "leak_segment",
    "leak_chainage_m",
    "distance_from_sensor1_m",
    "distance_from_sensor1_lo_m",
    "distance_from_sensor1_hi_m",
    "distance_from_sensor2_m",
    "distance_std_m",
    "table_distance_from_sensor1_m",
    "table_minus_model_m",
    "leak_x",
    "leak_y",
    "span_m",
    "path",
    "speed_sources",
    "delay_s",
    "delay_std_s",
    "band_lo_hz_used",
    "band_hi_hz_used",
    "band_note",
    "error_delay_m",
    "error_speeds_m",
    "error_span_m",
    "error_speed_terms_m",
    "largest_term",
    "advice",
    "notes",
    "message",
];

/// The outcome of one job.
pub type Answer = Result<Located, RowFailure>;

fn f(v: f64, d: usize) -> String {
    format!("{v:.d$}")
}

/// The cells of one answer, in [`OUTPUT_COLUMNS`] order.
pub fn row(a: &Answer) -> Vec<String> {
    match a {
        Err(e) => {
            let mut r = vec![String::new(); OUTPUT_COLUMNS.len()];
            r[0] = e.job_id.clone();
            r[1] = "failed".into();
            r[OUTPUT_COLUMNS.len() - 1] = e.message.clone();
            r
        }
        Ok(l) => {
            let term = |name: &str| {
                l.budget
                    .iter()
                    .find(|t| t.name == name)
                    .map_or(0.0, |t| t.shift_m.abs())
            };
            let speeds: Vec<&super::BudgetTerm> =
                l.budget.iter().filter(|t| t.segment_id.is_some()).collect();
            let speed_total = l.speeds_std_m;
            let (x, y) = l
                .point
                .map_or((String::new(), String::new()), |p| (f(p.0, 3), f(p.1, 3)));
            vec![
                l.job_id.clone(),
                "ok".into(),
                l.leak_segment.clone(),
                f(l.leak_chainage_m, 2),
                f(l.distance_m, 2),
                f(l.lo_m, 2),
                f(l.hi_m, 2),
                f(l.span_m - l.distance_m, 2),
                f(l.std_m, 3),
                f(l.table_distance_m, 2),
                f(l.table_distance_m - l.distance_m, 2),
                x,
                y,
                f(l.span_m, 2),
                l.path_ids.join(";"),
                l.sources
                    .iter()
                    .map(|s| s.as_str())
                    .collect::<Vec<_>>()
                    .join(";"),
                format!("{:.7}", l.delay_s),
                format!("{:.3e}", l.delay_std_s),
                f(l.band_used_hz.0, 1),
                f(l.band_used_hz.1, 1),
                l.band_note.clone(),
                f(term("delay"), 3),
                f(speed_total, 3),
                f(term("span"), 3),
                speeds
                    .iter()
                    .map(|t| {
                        format!(
                            "{}:{:+.3}",
                            t.segment_id.as_deref().unwrap_or(""),
                            t.shift_m
                        )
                    })
                    .collect::<Vec<_>>()
                    .join(";"),
                l.budget.first().map_or(String::new(), |t| t.name.clone()),
                l.advice.clone(),
                l.notes.join("; "),
                String::new(),
            ]
        }
    }
}

/// Write the answers as CSV (text cells spreadsheet-safe, as every CSV pipewave writes).
pub fn write_csv(path: &Path, answers: &[Answer]) -> Result<(), String> {
    let e = |e: csv::Error| format!("cannot write {}: {e}", path.display());
    let mut w = spreadsheet::writer_from_path(path).map_err(e)?;
    w.write_record(OUTPUT_COLUMNS).map_err(e)?;
    for a in answers {
        let r: Vec<String> = row(a)
            .into_iter()
            .map(|c| spreadsheet_safe(&c).into_owned())
            .collect();
        w.write_record(&r).map_err(e)?;
    }
    spreadsheet::finish(w).map_err(e)
}

fn properties(a: &Answer) -> serde_json::Map<String, Json> {
    OUTPUT_COLUMNS
        .iter()
        .zip(row(a))
        .map(|(k, v)| {
            let j = match v.parse::<f64>() {
                Ok(x) if x.is_finite() && !matches!(*k, "job_id" | "leak_segment" | "path") => {
                    json!(x)
                }
                _ => json!(v),
            };
            (k.to_string(), j)
        })
        .collect()
}

/// Write the answers as GeoJSON in WGS 84 (RFC 7946): for each located leak a Point with the
/// answer's columns, and its 95 % interval as a LineString along the pipe.
pub fn write_geojson(
    path: &Path,
    answers: &[Answer],
    srid: Option<i64>,
) -> Result<Vec<String>, String> {
    let mut warnings = Vec::new();
    let proj = srid.map(|s| Reprojector::new(s, WGS84));
    let to_wgs = |p: (f64, f64)| -> Option<(f64, f64)> {
        match &proj {
            Some(Ok(r)) => r.point(p).ok(),
            _ => None,
        }
    };
    let mut features = Vec::new();
    for a in answers {
        let Ok(l) = a else { continue };
        let Some(pt) = l.point.and_then(to_wgs) else {
            warnings.push(format!(
                "job {}: no map point (the leak's segment has no geometry, or its CRS is unknown)",
                l.job_id
            ));
            continue;
        };
        features.push(json!({
            "type": "Feature",
            "id": l.job_id,
            "geometry": {"type": "Point", "coordinates": [pt.0, pt.1]},
            "properties": properties(a),
        }));
        let line: Option<Vec<Json>> = l
            .interval_line
            .iter()
            .map(|&p| to_wgs(p).map(|q| json!([q.0, q.1])))
            .collect();
        if let Some(coords) = line.filter(|c| c.len() >= 2) {
            features.push(json!({
                "type": "Feature",
                "id": format!("{}-interval", l.job_id),
                "geometry": {"type": "LineString", "coordinates": coords},
                "properties": {
                    "job_id": l.job_id,
                    "kind": "interval_95",
                    "distance_from_sensor1_lo_m": l.lo_m,
                    "distance_from_sensor1_hi_m": l.hi_m,
                },
            }));
        }
    }
    let doc = json!({"type": "FeatureCollection", "features": features});
    let text = serde_json::to_string_pretty(&doc).map_err(|e| e.to_string())?;
    crate::outfile::write_bytes(path, crate::outfile::Contents::Plain, text.as_bytes())
        .map_err(|e| e.to_string())?;
    Ok(warnings)
}

/// The leak points' layer in a GeoPackage.
pub const POINTS_TABLE: &str = "leaks";
/// The intervals' layer.
pub const INTERVALS_TABLE: &str = "leak_intervals";

/// GeoPackage binary of a 2-D point (12-128r18 §2.1.3: header without envelope, then ISO WKB).
fn point_blob(srs_id: i32, p: (f64, f64)) -> Vec<u8> {
    let mut b = Vec::with_capacity(29);
    b.extend_from_slice(b"GP");
    b.push(0);
    // Flags: little endian, no envelope.
    b.push(0b0000_0001);
    b.extend_from_slice(&srs_id.to_le_bytes());
    b.push(1);
    b.extend_from_slice(&1u32.to_le_bytes());
    b.extend_from_slice(&p.0.to_le_bytes());
    b.extend_from_slice(&p.1.to_le_bytes());
    b
}

/// Write the located leaks as two layers (points and 95 % intervals) into a GeoPackage: added
/// to an existing one (replacing earlier leak layers), or a new file.
pub fn write_gpkg(
    path: &Path,
    answers: &[Answer],
    srid: Option<i64>,
) -> Result<Vec<String>, String> {
    let e = |x: rusqlite::Error| format!("GeoPackage {}: {x}", path.display());
    let exists = path.exists();
    // An existing GeoPackage is copied and extended beside itself, then moved over it: a
    // failure halfway leaves it as it was.
    let file = OutFile::for_path(path, Contents::GeoPackage, true).map_err(|x| x.to_string())?;
    let mut conn = Connection::open(file.temp_path()).map_err(e)?;
    if exists {
        let id: i32 = conn
            .pragma_query_value(None, "application_id", |r| r.get(0))
            .map_err(e)?;
        if id != gpkg::APPLICATION_ID {
            return Err(format!(
                "{} exists and is not a GeoPackage; name a new file or a GeoPackage to add the \
                 leak layers to",
                path.display()
            ));
        }
    } else {
        conn.pragma_update(None, "application_id", gpkg::APPLICATION_ID)
            .map_err(e)?;
        conn.pragma_update(None, "user_version", gpkg::USER_VERSION)
            .map_err(e)?;
    }
    let mut warnings = Vec::new();
    let tx = conn.transaction().map_err(e)?;
    if !exists {
        tx.execute_batch(gpkg::SCHEMA).map_err(e)?;
    }
    gpkg::ensure_srs(&tx, srid, &mut warnings).map_err(e)?;
    for t in [POINTS_TABLE, INTERVALS_TABLE] {
        tx.execute(
            "DELETE FROM gpkg_geometry_columns WHERE table_name = ?1",
            [t],
        )
        .map_err(e)?;
        tx.execute("DELETE FROM gpkg_contents WHERE table_name = ?1", [t])
            .map_err(e)?;
        tx.execute_batch(&format!("DROP TABLE IF EXISTS {t}"))
            .map_err(e)?;
    }
    let srs = srid.unwrap_or(-1);
    let srs_id = i32::try_from(srs).unwrap_or(-1);
    let cols: Vec<String> = OUTPUT_COLUMNS
        .iter()
        .map(|c| format!("\"{c}\" TEXT"))
        .collect();
    tx.execute_batch(&format!(
        "CREATE TABLE {POINTS_TABLE} (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, geom POINT, {});
         CREATE TABLE {INTERVALS_TABLE} (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, geom LINESTRING, \
         job_id TEXT, distance_from_sensor1_lo_m REAL, distance_from_sensor1_hi_m REAL);",
        cols.join(", ")
    ))
    .map_err(e)?;
    let marks: Vec<String> = (0..=OUTPUT_COLUMNS.len())
        .map(|i| format!("?{}", i + 1))
        .collect();
    let names: Vec<String> = OUTPUT_COLUMNS.iter().map(|c| format!("\"{c}\"")).collect();
    let mut bbox = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    let mut grow = |p: (f64, f64)| {
        bbox = [
            bbox[0].min(p.0),
            bbox[1].max(p.0),
            bbox[2].min(p.1),
            bbox[3].max(p.1),
        ];
    };
    {
        let mut ins = tx
            .prepare(&format!(
                "INSERT INTO {POINTS_TABLE} (geom, {}) VALUES ({})",
                names.join(", "),
                marks.join(", ")
            ))
            .map_err(e)?;
        let mut line_ins = tx
            .prepare(&format!(
                "INSERT INTO {INTERVALS_TABLE} (geom, job_id, distance_from_sensor1_lo_m, \
                 distance_from_sensor1_hi_m) VALUES (?1, ?2, ?3, ?4)"
            ))
            .map_err(e)?;
        for a in answers {
            let blob = a.as_ref().ok().and_then(|l| l.point).map(|p| {
                grow(p);
                point_blob(srs_id, p)
            });
            let mut values: Vec<rusqlite::types::Value> =
                vec![blob.map_or(rusqlite::types::Value::Null, rusqlite::types::Value::Blob)];
            values.extend(row(a).into_iter().map(rusqlite::types::Value::Text));
            ins.execute(rusqlite::params_from_iter(values)).map_err(e)?;
            if let Ok(l) = a {
                if l.interval_line.len() >= 2 {
                    let ls = crate::db::wkt::LineString {
                        points: l.interval_line.clone(),
                    };
                    l.interval_line.iter().for_each(|&p| grow(p));
                    line_ins
                        .execute(params![
                            gpkg::linestring_blob(srs_id, &ls),
                            l.job_id,
                            l.lo_m,
                            l.hi_m
                        ])
                        .map_err(e)?;
                }
            }
        }
    }
    let extent = bbox[0].is_finite().then_some(bbox);
    gpkg::register_feature_table(
        &tx,
        POINTS_TABLE,
        "leaks located by pipewave locate",
        extent,
        "geom",
        "POINT",
        srs,
    )
    .map_err(e)?;
    gpkg::register_feature_table(
        &tx,
        INTERVALS_TABLE,
        "95 % intervals of the located leaks, along the pipe",
        extent,
        "geom",
        "LINESTRING",
        srs,
    )
    .map_err(e)?;
    tx.commit().map_err(e)?;
    conn.close().map_err(|(_, x)| e(x))?;
    file.commit().map_err(|x| x.to_string())?;
    Ok(warnings)
}
