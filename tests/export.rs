//! GIS exports read back independently: the GeoPackage with SQLite (and with GDAL's ogrinfo in
//! a test ignored unless run with `--include-ignored`), the GeoJSON against RFC 7946, the CSV as a join table; every value compared
//! with the database.

mod export_fixture;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

use export_fixture as fx;
use pipewave::db::wkt::LineString;
use pipewave::db::{self, curves_for, latest_fits, Database, FitRow, ImportOptions, ImportSource};
use pipewave::export::numbers::columns;
use pipewave::export::{self, ExportError, ExportFormat, Precision, PROPERTIES};
use pipewave::outfile::OutputError;
use rusqlite::types::Value as Sql;
use rusqlite::Connection;
use tempfile::TempDir;

const N: usize = 60;

fn network(n: usize) -> (TempDir, Database) {
    let dir = tempfile::tempdir().unwrap();
    let database = fx::build(&dir.path().join("pipewave.sqlite"), n);
    (dir, database)
}

/// The database's view of each segment: inventory geometry, latest fit, curve.
struct Expected {
    geometry: Option<LineString>,
    fit: Option<FitRow>,
    curve: BTreeMap<u64, (Option<f64>, Option<f64>)>,
    material: String,
    diameter: f64,
}

fn expected(database: &Database) -> BTreeMap<String, Expected> {
    let conn = database.conn();
    let fits: BTreeMap<String, FitRow> = latest_fits(conn, None)
        .unwrap()
        .into_iter()
        .map(|f| (f.segment_id.clone(), f))
        .collect();
    db::load_segments(conn, None)
        .unwrap()
        .into_iter()
        .map(|s| {
            let fit = fits.get(&s.segment_id).cloned();
            let curve = fit
                .as_ref()
                .map(|f| curves_for(conn, &f.segment_id, f.run_id).unwrap())
                .unwrap_or_default()
                .into_iter()
                .map(|p| {
                    (
                        p.frequency_hz.to_bits(),
                        (p.phase_speed_m_per_s, p.attenuation_db_per_m),
                    )
                })
                .collect();
            let e = Expected {
                geometry: s
                    .geometry_wkt
                    .as_deref()
                    .map(|w| LineString::parse_wkt(w).unwrap()),
                fit,
                curve,
                material: s.material.code().to_string(),
                diameter: s.outer_diameter_mm,
            };
            (s.segment_id, e)
        })
        .collect()
}

/// Independent leak-band mean: trapezoid over the stored points in [100, 800] Hz.
fn band_mean(curve: &BTreeMap<u64, (Option<f64>, Option<f64>)>) -> Option<f64> {
    let mut pts: Vec<(f64, f64)> = curve
        .iter()
        .map(|(f, v)| (f64::from_bits(*f), v.0))
        .filter(|(f, _)| (100.0..=800.0).contains(f))
        .map(|(f, c)| c.map(|c| (f, c)))
        .collect::<Option<_>>()?;
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    if pts.first()?.0 != 100.0 || pts.last()?.0 != 800.0 {
        return None;
    }
    let area: f64 = pts
        .windows(2)
        .map(|w| 0.5 * (w[0].1 + w[1].1) * (w[1].0 - w[0].0))
        .sum();
    Some(area / 700.0)
}

fn speed_at(e: &Expected, f: f64) -> Option<f64> {
    e.curve.get(&f.to_bits()).and_then(|v| v.0)
}

/// Check one property value from an export against the database.
fn check_value(name: &str, got: &Sql, e: &Expected, id: &str) {
    let fit = e.fit.as_ref();
    let real = |v: Option<f64>| v.map_or(Sql::Null, Sql::Real);
    let text = |v: Option<&str>| v.map_or(Sql::Null, |s| Sql::Text(s.to_string()));
    let want = match name {
        "segment_id" => Sql::Text(id.to_string()),
        "material" => Sql::Text(e.material.clone()),
        "outer_diameter_mm" => Sql::Real(e.diameter),
        "status" => Sql::Text(fit.map_or("unfitted", |f| f.status.as_str()).to_string()),
        "flags" => text(fit.map(|f| f.flags.as_str())),
        "effects" => text(fit.map(|f| f.effects.as_str())),
        "run_id" => fit.map_or(Sql::Null, |f| Sql::Integer(f.run_id)),
        "soil_youngs_modulus_pa" => real(fit.and_then(|f| f.soil_youngs_modulus_pa)),
        "soil_youngs_modulus_std_pa" => real(fit.and_then(|f| f.soil_youngs_modulus_std_pa)),
        "soil_poisson" => real(fit.and_then(|f| f.soil_poisson)),
        "soil_poisson_std" => real(fit.and_then(|f| f.soil_poisson_std)),
        "contact" => real(fit.and_then(|f| f.contact)),
        "contact_std" => real(fit.and_then(|f| f.contact_std)),
        "soil_loss_factor" => real(fit.and_then(|f| f.soil_loss_factor)),
        "misfit" => real(fit.and_then(|f| f.misfit)),
        "chi2_per_dof" => real(fit.and_then(|f| f.chi2_per_dof)),
        "speed_100hz_m_per_s" => real(speed_at(e, 100.0)),
        "speed_200hz_m_per_s" => real(speed_at(e, 200.0)),
        "speed_500hz_m_per_s" => real(speed_at(e, 500.0)),
        "speed_1000hz_m_per_s" => real(speed_at(e, 1000.0)),
        "attenuation_500hz_db_per_m" => real(e.curve.get(&500f64.to_bits()).and_then(|v| v.1)),
        "leak_band_speed_m_per_s" => match (got, band_mean(&e.curve)) {
            (Sql::Real(g), Some(w)) => {
                assert!((g - w).abs() <= 1e-9 * w, "{id} {name}: {g} vs {w}");
                return;
            }
            (_, w) => real(w),
        },
        _ => return,
    };
    assert_eq!(got, &want, "{id}: {name}");
}

fn read_f64(b: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}
fn read_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

#[test]
fn geopackage_meets_the_standard_and_holds_the_database_values() {
    let (dir, database) = network(N);
    let out = dir.path().join("net.gpkg");
    let summary = export::write(&database, ExportFormat::Gpkg, &out).unwrap();
    assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    assert_eq!(summary.segments, N);
    let exp = expected(&database);
    let g = Connection::open(&out).unwrap();

    // Req. 2: application id 'GPKG' and version 1.2.0 (what GDAL 3.6 reads without a warning).
    let app: i64 = g
        .query_row("PRAGMA application_id", [], |r| r.get(0))
        .unwrap();
    assert_eq!(app, 0x4750_4B47);
    let ver: i64 = g
        .query_row("PRAGMA user_version", [], |r| r.get(0))
        .unwrap();
    assert_eq!(ver, 10200);
    let ok: String = g
        .query_row("PRAGMA integrity_check", [], |r| r.get(0))
        .unwrap();
    assert_eq!(ok, "ok");
    let fk: i64 = g
        .query_row("SELECT COUNT(*) FROM pragma_foreign_key_check", [], |r| {
            r.get(0)
        })
        .unwrap();
    assert_eq!(fk, 0);

    // Req. 11: the mandatory SRS rows, and the segments' system with its WKT.
    let srs: BTreeMap<i64, (String, i64, String)> = g
        .prepare("SELECT srs_id, organization, organization_coordsys_id, definition FROM gpkg_spatial_ref_sys")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, (r.get(1)?, r.get(2)?, r.get(3)?))))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(
        srs.keys().copied().collect::<Vec<_>>(),
        [-1, 0, 4326, 27700]
    );
    assert_eq!(srs[&-1].2, "undefined");
    assert_eq!(srs[&0].2, "undefined");
    assert!(srs[&4326].2.starts_with("GEOGCS[\"WGS 84\""));
    assert_eq!((srs[&27700].0.as_str(), srs[&27700].1), ("EPSG", 27700));
    assert!(srs[&27700]
        .2
        .starts_with("PROJCS[\"OSGB 1936 / British National Grid\""));
    assert!(srs[&27700].2.ends_with("AUTHORITY[\"EPSG\",\"27700\"]]"));

    // gpkg_contents and gpkg_geometry_columns.
    let (dtype, ident, minx, miny, maxx, maxy, srs_id): (String, String, f64, f64, f64, f64, i64) =
        g.query_row(
            "SELECT data_type, identifier, min_x, min_y, max_x, max_y, srs_id FROM gpkg_contents \
             WHERE table_name = 'pipe_segments'",
            [],
            |r| {
                Ok((
                    r.get(0)?,
                    r.get(1)?,
                    r.get(2)?,
                    r.get(3)?,
                    r.get(4)?,
                    r.get(5)?,
                    r.get(6)?,
                ))
            },
        )
        .unwrap();
    assert_eq!(
        (dtype.as_str(), ident.as_str(), srs_id),
        ("features", "pipe_segments", 27700)
    );
    let all_pts: Vec<(f64, f64)> = exp
        .values()
        .filter_map(|e| e.geometry.as_ref())
        .flat_map(|l| l.points.iter().copied())
        .collect();
    let fold = |f: fn(&(f64, f64)) -> f64, min: bool| {
        all_pts.iter().map(f).fold(
            if min {
                f64::INFINITY
            } else {
                f64::NEG_INFINITY
            },
            |a, b| {
                if min {
                    a.min(b)
                } else {
                    a.max(b)
                }
            },
        )
    };
    assert_eq!(
        [minx, miny, maxx, maxy],
        [
            fold(|p| p.0, true),
            fold(|p| p.1, true),
            fold(|p| p.0, false),
            fold(|p| p.1, false)
        ]
    );
    let gc: (String, String, String, i64, i64, i64) = g
        .query_row("SELECT table_name, column_name, geometry_type_name, srs_id, z, m FROM gpkg_geometry_columns", [], |r| {
            Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?, r.get(4)?, r.get(5)?))
        })
        .unwrap();
    assert_eq!(
        gc,
        (
            "pipe_segments".into(),
            "geom".into(),
            "LINESTRING".into(),
            27700,
            0,
            0
        )
    );
    let geom_type: String = g
        .query_row(
            "SELECT type FROM pragma_table_info('pipe_segments') WHERE name = 'geom'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(geom_type, "LINESTRING");

    // The features: one per segment, geometry and every property as in the database.
    let cols: Vec<String> = g
        .prepare("SELECT name FROM pragma_table_info('pipe_segments')")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    let mut want_cols = vec!["fid".to_string(), "geom".to_string()];
    want_cols.extend(columns().properties.iter().map(|p| p.name.to_string()));
    assert_eq!(cols, want_cols);
    let rows: Vec<Vec<Sql>> = g
        .prepare("SELECT * FROM pipe_segments ORDER BY fid")
        .unwrap()
        .query_map([], |r| {
            (0..cols.len()).map(|i| r.get::<_, Sql>(i)).collect()
        })
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(rows.len(), N);
    let mut seen = BTreeSet::new();
    let mut n_geom = 0;
    for row in &rows {
        let Sql::Text(id) = &row[2] else {
            panic!("segment_id {:?}", row[2])
        };
        assert!(seen.insert(id.clone()), "duplicate {id}");
        let e = &exp[id];
        match (&row[1], &e.geometry) {
            (Sql::Null, None) => {}
            (Sql::Blob(b), Some(line)) => {
                n_geom += 1;
                assert_eq!(&b[..2], b"GP", "{id}");
                assert_eq!(b[2], 0, "{id}: version");
                let flags = b[3];
                assert_eq!(flags & 1, 1, "{id}: little endian");
                assert_eq!(
                    (flags >> 1) & 0b111,
                    1,
                    "{id}: envelope [minx, maxx, miny, maxy]"
                );
                assert_eq!((flags >> 4) & 1, 0, "{id}: not empty");
                assert_eq!((flags >> 5) & 1, 0, "{id}: standard binary");
                assert_eq!(flags >> 6, 0, "{id}: reserved bits");
                assert_eq!(i32::from_le_bytes(b[4..8].try_into().unwrap()), 27700);
                let xs = line.points.iter().map(|p| p.0);
                let ys = line.points.iter().map(|p| p.1);
                let env = [
                    xs.clone().fold(f64::INFINITY, f64::min),
                    xs.fold(f64::NEG_INFINITY, f64::max),
                    ys.clone().fold(f64::INFINITY, f64::min),
                    ys.fold(f64::NEG_INFINITY, f64::max),
                ];
                assert_eq!(
                    [
                        read_f64(b, 8),
                        read_f64(b, 16),
                        read_f64(b, 24),
                        read_f64(b, 32)
                    ],
                    env
                );
                assert_eq!(b[40], 1, "{id}: WKB little endian");
                assert_eq!(read_u32(b, 41), 2, "{id}: WKB LineString");
                let n = read_u32(b, 45) as usize;
                assert_eq!(n, line.points.len());
                assert_eq!(b.len(), 49 + 16 * n);
                for (k, p) in line.points.iter().enumerate() {
                    assert_eq!(
                        (read_f64(b, 49 + 16 * k), read_f64(b, 57 + 16 * k)),
                        *p,
                        "{id}"
                    );
                }
            }
            (got, want) => panic!("{id}: geometry {got:?}, database {want:?}"),
        }
        for (name, v) in cols.iter().zip(row).skip(2) {
            check_value(name, v, e, id);
        }
    }
    assert_eq!(seen.len(), exp.len());
    // The fixture covers unfitted, failed, flagged and geometry-less segments.
    let statuses: BTreeSet<String> = rows
        .iter()
        .map(|r| {
            match &r[2 + columns()
                .properties
                .iter()
                .position(|p| p.name == "status")
                .unwrap()]
            {
                Sql::Text(s) => s.clone(),
                v => panic!("{v:?}"),
            }
        })
        .collect();
    assert_eq!(
        statuses,
        ["failed", "flagged", "ok", "unfitted"]
            .map(String::from)
            .into()
    );
    assert!(n_geom < N && n_geom > 0);

    // R-tree index: one entry per geometry, enclosing its envelope (stored as 32-bit floats,
    // rounded outwards).
    let ext: i64 = g
        .query_row(
            "SELECT COUNT(*) FROM gpkg_extensions WHERE table_name = 'pipe_segments' AND \
             column_name = 'geom' AND extension_name = 'gpkg_rtree_index'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(ext, 1);
    let bad: i64 = g
        .query_row(
            "SELECT COUNT(*) FROM pipe_segments p JOIN rtree_pipe_segments_geom r ON r.id = p.fid",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(bad as usize, n_geom);
    drop(g);
    // The pipewave database was not touched by the export.
    assert_eq!(expected(&database).len(), N);
}

/// GDAL's messages on stderr: every non-blank line is a warning or an error (ogrinfo prints
/// nothing there for a file it reads cleanly; GDAL 3.6 used to print "This version of
/// GeoPackage user_version=0x000028A0 (10400, v1.4.0) ... may only be partially supported" for
/// a GeoPackage that declared 1.4).
fn gdal_warnings(stderr: &str) -> Vec<&str> {
    stderr.lines().filter(|l| !l.trim().is_empty()).collect()
}

#[test]
#[ignore = "needs gdal-bin"]
fn geopackage_opens_in_gdal_without_warnings() {
    let v = Command::new("ogrinfo")
        .arg("--version")
        .output()
        .expect("GDAL's ogrinfo (apt-get install gdal-bin)");
    assert!(v.status.success());
    let (dir, database) = network(N);
    let out = dir.path().join("net.gpkg");
    export::write(&database, ExportFormat::Gpkg, &out).unwrap();
    let o = Command::new("ogrinfo")
        .args(["-ro", "-al", "-so"])
        .arg(&out)
        .env("CPL_DEBUG", "OFF")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let warnings = gdal_warnings(&stderr);
    assert!(warnings.is_empty(), "ogrinfo warned: {warnings:?}");
    assert!(stdout.contains("Layer name: pipe_segments"), "{stdout}");
    assert!(stdout.contains("Geometry: Line String"), "{stdout}");
    assert!(stdout.contains(&format!("Feature Count: {N}")), "{stdout}");
    assert!(
        stdout.contains("British National Grid") || stdout.contains("27700"),
        "{stdout}"
    );
    assert!(stdout.contains("leak_band_speed_m_per_s: Real"), "{stdout}");
    // QGIS's style table, read by GDAL with QGIS's field types.
    assert!(stdout.contains("Layer name: layer_styles"), "{stdout}");
    for field in [
        "f_table_name: String (256.0)",
        "styleName: String (30.0)",
        "styleQML: String (0.0)",
        "useAsDefault: Integer(Boolean) (0.0)",
        "update_time: DateTime (0.0)",
    ] {
        assert!(stdout.contains(field), "{field} missing in {stdout}");
    }
    // The full read (every feature, geometry decoded) is also silent.
    let o = Command::new("ogrinfo")
        .args(["-ro", "-al", "-q"])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.success() && gdal_warnings(&stderr).is_empty(),
        "{stderr}"
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        stdout.matches("LINESTRING (").count(),
        (0..N).filter(|&i| fx::has_geometry(i)).count()
    );
}

/// The QML of a style, checked: well-formed XML whose rule-based renderer colours by
/// `leak_band_speed_m_per_s` within each kind of segment (trusted, predicted, distrusted).
/// Returns each class of the trusted kind as (lower, upper, label).
fn qml_classes(qml: &str) -> Vec<(f64, f64, String)> {
    use quick_xml::events::Event;
    let mut r = quick_xml::Reader::from_str(qml);
    let mut renderer = None;
    let mut classes = Vec::new();
    let mut kinds = Vec::new();
    let mut depth = 0i64;
    loop {
        let (e, is_start) = match r.read_event() {
            Ok(Event::Start(e)) => (e, true),
            Ok(Event::Empty(e)) => (e, false),
            Ok(Event::End(_)) => {
                depth -= 1;
                continue;
            }
            Ok(Event::Eof) => break,
            Ok(_) => continue,
            Err(e) => panic!("the QML is not well-formed at {}: {e}", r.buffer_position()),
        };
        depth += i64::from(is_start);
        let attr = |name: &str| -> Option<String> {
            e.attributes()
                .map(|a| a.expect("attribute"))
                .find(|a| a.key.as_ref() == name.as_bytes())
                .map(|a| {
                    String::from_utf8(a.value.into_owned())
                        .unwrap()
                        .replace("&quot;", "\"")
                        .replace("&lt;", "<")
                        .replace("&gt;", ">")
                        .replace("&amp;", "&")
                })
        };
        match e.name().as_ref() {
            b"renderer-v2" => renderer = attr("type"),
            b"rule" => {
                let key = attr("key").unwrap();
                let filter = attr("filter").unwrap();
                if is_start {
                    kinds.push(key.clone());
                } else if key.starts_with("trusted-") && !key.ends_with("-none") {
                    // "leak_band_speed_m_per_s" >= LO AND "leak_band_speed_m_per_s" < HI
                    let num = |after: &str| -> f64 {
                        filter[filter.find(after).unwrap() + after.len()..]
                            .split_whitespace()
                            .next()
                            .unwrap()
                            .parse()
                            .unwrap()
                    };
                    assert!(filter.contains("\"leak_band_speed_m_per_s\""), "{filter}");
                    let hi = if filter.contains("<=") {
                        num("<= ")
                    } else {
                        num("< ")
                    };
                    classes.push((num(">= "), hi, attr("label").unwrap()));
                }
            }
            _ => {}
        }
    }
    assert_eq!(depth, 0, "unbalanced elements");
    assert_eq!(renderer.as_deref(), Some("RuleRenderer"));
    assert_eq!(kinds, ["trusted", "predicted", "distrusted"]);
    classes
}

/// The classes cover every exported leak-band speed, increase, and are labelled in m/s.
fn check_classes(classes: &[(f64, f64, String)], database: &Database) {
    assert!(!classes.is_empty() && classes.len() <= 5, "{classes:?}");
    for w in classes.windows(2) {
        assert_eq!(w[0].1, w[1].0, "contiguous classes: {classes:?}");
    }
    // Rules select by the exported status: every flagged segment falls under the distrusted
    // kind (dashed over a casing), checked on the style's own filter text.
    for (lo, hi, label) in classes {
        assert!(lo < hi);
        assert_eq!(*label, format!("{lo:.0} – {hi:.0} m/s"));
    }
    let speeds: Vec<f64> = expected(database)
        .values()
        .filter_map(|e| band_mean(&e.curve))
        .collect();
    assert!(speeds.len() > 5, "the fixture has fitted segments");
    let (lo, hi) = (classes[0].0, classes[classes.len() - 1].1);
    for v in speeds {
        assert!(lo <= v && v <= hi, "{v} outside {lo}..{hi}");
    }
}

#[test]
fn geopackage_carries_a_default_qgis_style_in_qgis_layout() {
    let (dir, database) = network(N);
    let out = dir.path().join("net.gpkg");
    export::write(&database, ExportFormat::Gpkg, &out).unwrap();
    let g = Connection::open(&out).unwrap();
    // The table as QGIS creates it (through GDAL): names, declared types, primary key.
    let cols: Vec<(String, String, i64)> = g
        .prepare("SELECT name, type, pk FROM pragma_table_info('layer_styles')")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    let want = [
        ("id", "INTEGER", 1),
        ("f_table_catalog", "TEXT(256)", 0),
        ("f_table_schema", "TEXT(256)", 0),
        ("f_table_name", "TEXT(256)", 0),
        ("f_geometry_column", "TEXT(256)", 0),
        ("styleName", "TEXT(30)", 0),
        ("styleQML", "TEXT", 0),
        ("styleSLD", "TEXT", 0),
        ("useAsDefault", "BOOLEAN", 0),
        ("description", "TEXT", 0),
        ("owner", "TEXT(30)", 0),
        ("ui", "TEXT(30)", 0),
        ("update_time", "DATETIME", 0),
    ];
    assert_eq!(
        cols,
        want.map(|(n, t, pk)| (n.to_string(), t.to_string(), pk))
    );
    let kind: String = g
        .query_row(
            "SELECT data_type FROM gpkg_contents WHERE table_name = 'layer_styles'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(kind, "attributes");
    // One default style for the feature table, as QGIS looks it up (loadStyle's filter).
    let rows: Vec<(String, i64, String, String)> = g
        .prepare(
            "SELECT styleName, useAsDefault, styleQML, update_time FROM layer_styles \
             WHERE f_table_schema = '' AND f_table_name = 'pipe_segments' \
             AND f_geometry_column = 'geom'",
        )
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(rows.len(), 1);
    let (name, default, qml, time) = &rows[0];
    assert!(!name.is_empty() && name.len() <= 30, "{name}");
    assert_eq!(*default, 1);
    assert!(time.ends_with('Z') && time.len() == 24, "{time}");
    check_classes(&qml_classes(qml), &database);
}

#[test]
fn geojson_and_csv_exports_get_the_style_as_a_qml_file_beside_them() {
    let (dir, database) = network(N);
    let g = dir.path().join("net.gpkg");
    export::write(&database, ExportFormat::Gpkg, &g).unwrap();
    let stored: String = Connection::open(&g)
        .unwrap()
        .query_row("SELECT styleQML FROM layer_styles", [], |r| r.get(0))
        .unwrap();
    for (format, file, qml) in [
        (ExportFormat::GeoJson, "net.geojson", "net.qml"),
        (ExportFormat::Csv, "join.csv", "join.qml"),
    ] {
        export::write(&database, format, &dir.path().join(file)).unwrap();
        let text = std::fs::read_to_string(dir.path().join(qml)).unwrap();
        check_classes(&qml_classes(&text), &database);
        assert_eq!(
            text, stored,
            "{format}: the same style as in the GeoPackage"
        );
    }
}

/// One segment at a given geometry in a new database.
fn single(dir: &Path, name: &str, rows: &[(&str, &str, &str)]) -> Database {
    let mut database = Database::open(dir.join(name)).unwrap();
    let mut csv = String::from("segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,geometry_wkt,srid\n");
    for (id, wkt, srid) in rows {
        csv.push_str(&format!("{id},DI,160,6,1900,\"{wkt}\",{srid}\n"));
    }
    let r = db::import(
        database.conn_mut(),
        Some(&ImportSource::from_bytes("segments.csv", csv)),
        None,
        ImportOptions::default(),
    )
    .unwrap();
    assert!(r.errors.is_empty(), "{:?}", r.errors);
    database
}

/// Metres between two WGS 84 points (equirectangular; exact enough over a few metres).
fn metres(a: (f64, f64), b: (f64, f64)) -> f64 {
    const M_PER_DEG: f64 = 111_320.0;
    let dx = (a.0 - b.0) * M_PER_DEG * b.1.to_radians().cos();
    let dy = (a.1 - b.1) * M_PER_DEG;
    dx.hypot(dy)
}

/// Reference: E 441800, N 111900 (Southampton) on the British National Grid is WGS 84
/// lon -1.40689879, lat 50.90506588 with EPSG:27700's TOWGS84 Helmert (the transformation
/// "OSGB36 to WGS 84 (6)", ~2 m accuracy), computed with PROJ 9.1 (Debian proj-bin):
/// `echo 441800 111900 0 0 | cct -d 8 +proj=pipeline +step +inv +proj=tmerc +lat_0=49 +lon_0=-2
/// +k=0.9996012717 +x_0=400000 +y_0=-100000 +ellps=airy +step +proj=cart +ellps=airy
/// +step +proj=helmert +x=446.448 +y=-125.157 +z=542.06 +rx=0.15 +ry=0.247 +rz=0.842 +s=-20.489
/// +convention=position_vector +step +inv +proj=cart +ellps=WGS84 +step +proj=unitconvert
/// +xy_in=rad +xy_out=deg`. Without the datum shift the point would land ~120 m away
/// (lon -1.40546072, lat 50.90450536), so the 1 m tolerance checks the datum handling too.
const SOUTHAMPTON_WGS84: (f64, f64) = (-1.40689879, 50.90506588);

#[test]
fn geojson_is_rfc7946_wgs84_lon_lat() {
    let (dir, database) = network(N);
    let out = dir.path().join("net.geojson");
    let summary =
        export::write_with_precision(&database, ExportFormat::GeoJson, &out, Precision::Full)
            .unwrap();
    assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!(doc["type"], "FeatureCollection");
    assert!(doc.get("crs").is_none(), "RFC 7946 §4: no crs member");
    let feats = doc["features"].as_array().unwrap();
    assert_eq!(feats.len(), N);
    let exp = expected(&database);
    for f in feats {
        assert_eq!(f["type"], "Feature");
        let props = f["properties"].as_object().unwrap();
        let id = props["segment_id"].as_str().unwrap();
        assert_eq!(f["id"], id);
        let e = &exp[id];
        // Same property names, in the same order, as the GeoPackage columns.
        assert_eq!(
            props.keys().map(String::as_str).collect::<Vec<_>>().len(),
            PROPERTIES.len()
        );
        for p in PROPERTIES {
            let v = &props[p.name];
            let sql = match v {
                serde_json::Value::Null => Sql::Null,
                serde_json::Value::String(s) => Sql::Text(s.clone()),
                serde_json::Value::Number(n)
                    if p.kind == pipewave::export::record::Kind::Integer =>
                {
                    Sql::Integer(n.as_i64().unwrap())
                }
                serde_json::Value::Number(n) => Sql::Real(n.as_f64().unwrap()),
                other => panic!("{id} {}: {other}", p.name),
            };
            check_value(p.name, &sql, e, id);
        }
        match (&f["geometry"], &e.geometry) {
            (serde_json::Value::Null, None) => {}
            (g, Some(line)) => {
                assert_eq!(g["type"], "LineString");
                let coords = g["coordinates"].as_array().unwrap();
                assert_eq!(coords.len(), line.points.len());
                for c in coords {
                    let c = c.as_array().unwrap();
                    assert_eq!(c.len(), 2, "2-D positions");
                    let (lon, lat) = (c[0].as_f64().unwrap(), c[1].as_f64().unwrap());
                    assert!((-180.0..=180.0).contains(&lon) && (-90.0..=90.0).contains(&lat));
                    // Longitude first: Southampton is at about 1.4°W, 50.9°N.
                    assert!((-1.6..-1.2).contains(&lon), "{id}: lon {lon}");
                    assert!((50.8..51.0).contains(&lat), "{id}: lat {lat}");
                    for v in [&c[0], &c[1]] {
                        let s = v.to_string();
                        let decimals = s.split('.').nth(1).map_or(0, str::len);
                        assert!(decimals <= 7, "{id}: {s} has more than 7 decimals");
                    }
                }
            }
            (g, None) => panic!("{id}: geometry {g} for a segment without one"),
        }
    }

    // A known point, within 1 m.
    let database = single(
        dir.path(),
        "one.sqlite",
        &[("P1", "LINESTRING (441800 111900, 441900 111950)", "27700")],
    );
    let out = dir.path().join("one.geojson");
    export::write(&database, ExportFormat::GeoJson, &out).unwrap();
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let c = &doc["features"][0]["geometry"]["coordinates"][0];
    let got = (c[0].as_f64().unwrap(), c[1].as_f64().unwrap());
    let d = metres(got, SOUTHAMPTON_WGS84);
    assert!(d < 1.0, "{got:?} is {d:.2} m from {SOUTHAMPTON_WGS84:?}");
    assert_eq!(doc["features"][0]["properties"]["status"], "unfitted");
}

#[test]
fn geometries_in_other_systems_are_reprojected_into_the_geopackage_system() {
    let dir = tempfile::tempdir().unwrap();
    let (lon, lat) = SOUTHAMPTON_WGS84;
    let database = single(
        dir.path(),
        "mixed.sqlite",
        &[
            ("A", "LINESTRING (441000 111000, 441100 111000)", "27700"),
            ("B", "LINESTRING (442000 112000, 442100 112050)", "27700"),
            (
                "C",
                &format!("LINESTRING ({lon} {lat}, {} {lat})", lon + 0.001),
                "4326",
            ),
            ("D", "LINESTRING (1 2, 3 4)", "27700"),
        ],
    );
    // An unknown system, which import refuses, edited into the database.
    database
        .conn()
        .execute(
            "UPDATE segments SET srid = 999999 WHERE segment_id = 'D'",
            [],
        )
        .unwrap();
    let out = dir.path().join("mixed.gpkg");
    let summary = export::write(&database, ExportFormat::Gpkg, &out).unwrap();
    assert_eq!(summary.with_geometry, 3);
    assert_eq!(summary.warnings.len(), 1, "{:?}", summary.warnings);
    assert!(summary.warnings[0].contains("segment D") && summary.warnings[0].contains("999999"));
    let g = Connection::open(&out).unwrap();
    let blob: Vec<u8> = g
        .query_row(
            "SELECT geom FROM pipe_segments WHERE segment_id = 'C'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(i32::from_le_bytes(blob[4..8].try_into().unwrap()), 27700);
    let (x, y) = (read_f64(&blob, 49), read_f64(&blob, 57));
    assert!((x - 441_800.0).hypot(y - 111_900.0) < 1.0, "({x}, {y})");
    let d: Option<Vec<u8>> = g
        .query_row(
            "SELECT geom FROM pipe_segments WHERE segment_id = 'D'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert!(d.is_none());
    let n: i64 = g
        .query_row("SELECT COUNT(*) FROM pipe_segments", [], |r| r.get(0))
        .unwrap();
    assert_eq!(n, 4, "segments without usable geometry are kept");
}

#[test]
fn csv_is_a_join_table_keyed_by_segment_id() {
    let (dir, database) = network(N);
    let out = dir.path().join("net.csv");
    export::write_with_precision(&database, ExportFormat::Csv, &out, Precision::Full).unwrap();
    let mut rdr = csv::Reader::from_path(&out).unwrap();
    let headers: Vec<String> = rdr.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(headers[0], "segment_id");
    let order = &columns().properties;
    assert_eq!(
        headers,
        order.iter().map(|p| p.name.to_string()).collect::<Vec<_>>()
    );
    let exp = expected(&database);
    let mut ids = BTreeSet::new();
    for rec in rdr.records() {
        let rec = rec.unwrap();
        let id = rec[0].to_string();
        assert!(ids.insert(id.clone()), "join key {id} repeated");
        let e = &exp[&id];
        for (p, cell) in order.iter().zip(rec.iter()) {
            let v = if cell.is_empty() {
                Sql::Null
            } else {
                match p.kind {
                    pipewave::export::record::Kind::Text => Sql::Text(cell.to_string()),
                    pipewave::export::record::Kind::Real => Sql::Real(cell.parse().unwrap()),
                    pipewave::export::record::Kind::Integer => Sql::Integer(cell.parse().unwrap()),
                }
            };
            // Text columns that are empty in the database read back as empty cells.
            let v = match (&v, p.kind) {
                (Sql::Null, pipewave::export::record::Kind::Text)
                    if e.fit.is_some() && matches!(p.name, "flags" | "effects") =>
                {
                    Sql::Text(String::new())
                }
                _ => v,
            };
            check_value(p.name, &v, e, &id);
        }
    }
    assert_eq!(ids, exp.keys().cloned().collect());
}

/// The CSV export counts the segments with geometry as the GeoPackage and GeoJSON exports do
/// (it has no geometry column, but its summary must not say "0 with geometry" where they say
/// 60), and every row of it is one line.
#[test]
fn csv_counts_geometry_as_the_gis_exports_do_and_rows_are_one_line() {
    let (dir, database) = network(N);
    let mut counts = Vec::new();
    for (format, name) in [
        (ExportFormat::Csv, "net.csv"),
        (ExportFormat::Gpkg, "net.gpkg"),
        (ExportFormat::GeoJson, "net.geojson"),
    ] {
        let out = dir.path().join(name);
        let s = export::write_with_precision(&database, format, &out, Precision::People).unwrap();
        counts.push((s.segments, s.with_geometry));
    }
    assert!(counts[0].1 > 0, "{counts:?}");
    assert_eq!(counts[0], counts[1], "csv against gpkg");
    assert_eq!(counts[0], counts[2], "csv against geojson");
    let text = std::fs::read_to_string(dir.path().join("net.csv")).unwrap();
    assert_eq!(text.lines().count(), counts[0].0 + 1, "one line per row");
}

#[test]
fn export_never_overwrites_a_pipewave_database() {
    let (dir, database) = network(8);
    let db_path = dir.path().join("pipewave.sqlite");
    let before = std::fs::metadata(&db_path).unwrap().len();
    for f in [ExportFormat::Gpkg, ExportFormat::GeoJson, ExportFormat::Csv] {
        let e = export::write(&database, f, &db_path).unwrap_err();
        assert!(
            matches!(e, ExportError::Output(OutputError::TheDatabase { .. })),
            "{e}"
        );
        assert!(e.to_string().contains("pipewave.sqlite"), "{e}");
    }
    // Another pipewave database at the out path is refused too.
    let other = dir.path().join("other.sqlite");
    drop(Database::open(&other).unwrap());
    assert!(export::write(&database, ExportFormat::Gpkg, &other).is_err());
    assert_eq!(std::fs::metadata(&db_path).unwrap().len(), before);
    assert_eq!(expected(&database).len(), 8);
    // A directory is refused with a suggestion; an existing GeoPackage is replaced.
    let e = export::write(&database, ExportFormat::Gpkg, dir.path()).unwrap_err();
    assert!(
        matches!(e, ExportError::Output(OutputError::Directory { .. })),
        "{e}"
    );
    let out = dir.path().join("x.gpkg");
    export::write(&database, ExportFormat::Gpkg, &out).unwrap();
    export::write(&database, ExportFormat::Gpkg, &out).unwrap();
    let n: i64 = Connection::open(&out)
        .unwrap()
        .query_row("SELECT COUNT(*) FROM pipe_segments", [], |r| r.get(0))
        .unwrap();
    assert_eq!(n, 8);
    // No temporary files are left behind.
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn cli_export_and_audit_exit_codes() {
    let (dir, database) = network(12);
    drop(database);
    let bin = env!("CARGO_BIN_EXE_pipewave");
    let db_path = dir.path().join("pipewave.sqlite");
    for (fmt, file) in [
        ("gpkg", "a.gpkg"),
        ("geojson", "a.geojson"),
        ("csv", "a.csv"),
    ] {
        let o = Command::new(bin)
            .args(["export", "--db"])
            .arg(&db_path)
            .args(["--format", fmt, "--out"])
            .arg(dir.path().join(file))
            .output()
            .unwrap();
        assert_eq!(
            o.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(String::from_utf8_lossy(&o.stdout).contains("12 segments"));
    }
    let o = Command::new(bin)
        .args(["audit", "--db"])
        .arg(&db_path)
        .arg("--out")
        .arg(dir.path().join("report.html"))
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // A missing database is not created, and exits 2 naming it.
    let missing = dir.path().join("nope.sqlite");
    let o = Command::new(bin)
        .args(["export", "--db"])
        .arg(&missing)
        .args(["--format", "csv", "--out"])
        .arg(dir.path().join("b.csv"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("nope.sqlite"));
    assert!(!missing.exists());
    // Unknown format, and --out the database itself: exit 2.
    let o = Command::new(bin)
        .args(["export", "--db"])
        .arg(&db_path)
        .args(["--format", "shp", "--out", "x.shp"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let o = Command::new(bin)
        .args(["audit", "--db"])
        .arg(&db_path)
        .arg("--out")
        .arg(&db_path)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("refusing"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Every table of a GeoPackage, row by row, without the columns that hold the time of writing.
fn gpkg_rows(path: &Path) -> Vec<String> {
    let conn = Connection::open(path).unwrap();
    let tables: Vec<String> = conn
        .prepare("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let mut out = Vec::new();
    for t in tables {
        let mut stmt = conn.prepare(&format!("SELECT * FROM \"{t}\"")).unwrap();
        let names: Vec<String> = stmt.column_names().iter().map(|s| s.to_string()).collect();
        let mut rows = stmt.query([]).unwrap();
        while let Some(r) = rows.next().unwrap() {
            let cells: Vec<String> = (0..names.len())
                .filter(|&i| names[i] != "last_change" && names[i] != "update_time")
                .map(|i| format!("{}={:?}", names[i], r.get::<_, Sql>(i).unwrap()))
                .collect();
            out.push(format!("{t}: {}", cells.join(" ")));
        }
    }
    out
}

/// Streaming: the exports and the audit report read the database a page at a time. Pages of 1
/// and 3 segments give the same files, byte for byte (the GeoPackage row for row), as one page
/// holding the whole network, and the same warnings; the network has segments without a fit,
/// failed fits, segments without geometry, one with an unreadable geometry, one in another
/// system, one that cannot be reprojected, and two soil zones, one member an outlier.
#[test]
fn exports_and_audit_read_in_small_pages_equal_one_page() {
    let (dir, mut database) = network(23);
    {
        let conn = database.conn();
        for (id, wkt, srid) in [
            ("S00001", "LINESTRING (441800 111900", 27700),
            ("S00002", "LINESTRING (-1.404 50.909, -1.401 50.911)", 4326),
            ("S00004", "LINESTRING (1 2, 3 4)", 99_999),
        ] {
            conn.execute(
                "UPDATE segments SET geometry_wkt = ?1, srid = ?2 WHERE segment_id = ?3",
                rusqlite::params![wkt, srid, id],
            )
            .unwrap();
        }
    }
    let fits = latest_fits(database.conn(), None).unwrap();
    for (zone, range, e) in [("north", 0..10, 4e7), ("south", 10..20, 9e7)] {
        let members: Vec<db::zones::ZoneMemberRow> = fits
            .iter()
            .filter(|f| range.contains(&f.segment_id[1..].parse::<usize>().unwrap()))
            .enumerate()
            .map(|(k, f)| db::zones::ZoneMemberRow {
                segment_id: f.segment_id.clone(),
                fit_id: f.id.unwrap(),
                shrunk_soil_youngs_modulus_pa: Some(e * (1.0 + 0.01 * k as f64)),
                shrunk_soil_poisson: Some(0.3),
                statistic: Some(if k == 2 { 41.5 } else { 1.0 + k as f64 }),
                zone_outlier: k == 2,
            })
            .collect();
        let z = db::zones::ZoneFitRow {
            soil_zone: zone.to_string(),
            n_segments: members.len() as i64,
            n_outliers: 1,
            soil_youngs_modulus_pa: Some(e),
            soil_youngs_modulus_lo_pa: Some(0.8 * e),
            soil_youngs_modulus_hi_pa: Some(1.2 * e),
            soil_poisson: Some(0.3),
            soil_p_wave_speed_m_per_s: Some(250.0),
            scatter_youngs_modulus_decades: 0.04,
            scatter_poisson: 0.01,
            scatter_source: "prior".into(),
            outliers: members[2].segment_id.clone(),
            outlier_reasons: format!("{}: far from its zone", members[2].segment_id),
            ..Default::default()
        };
        db::zones::insert_zone_fit(database.conn_mut(), &z, &members).unwrap();
    }
    let out = dir.path();
    let mut files: Vec<BTreeMap<&str, Vec<u8>>> = Vec::new();
    let mut layers = Vec::new();
    let mut warnings = Vec::new();
    for page in [1, 3, 10_000] {
        let mut f = BTreeMap::new();
        let mut w = Vec::new();
        for (format, name) in [
            (ExportFormat::GeoJson, "p.geojson"),
            (ExportFormat::Csv, "p.csv"),
            (ExportFormat::Gpkg, "p.gpkg"),
        ] {
            let s = export::write_paged(&database, format, &out.join(name), page).unwrap();
            assert_eq!((s.segments, s.fitted), (23, 22), "{format} page {page}");
            w.push(s);
        }
        let s = pipewave::report::audit::write_paged(&database, &out.join("p.html"), page).unwrap();
        w.push(s);
        for name in ["p.geojson", "p.csv", "p.qml", "p.html"] {
            f.insert(name, std::fs::read(out.join(name)).unwrap());
        }
        files.push(f);
        layers.push(gpkg_rows(&out.join("p.gpkg")));
        warnings.push(w);
    }
    for k in 1..files.len() {
        for (name, bytes) in &files[0] {
            assert!(bytes == &files[k][name], "{name} differs between pages");
        }
        assert_eq!(layers[0], layers[k]);
        assert_eq!(warnings[0], warnings[k]);
    }
    // What was compared holds what the network has.
    let w = &warnings[0];
    for s in w {
        assert!(
            s.warnings
                .iter()
                .any(|m| m.contains("S00001") && m.contains("cannot be read")),
            "{:?}",
            s.warnings
        );
    }
    assert!(w[2]
        .warnings
        .iter()
        .any(|m| m.starts_with("segment S00004:")));
    assert!(w[3]
        .warnings
        .iter()
        .any(|m| m.starts_with("segment S00004:")));
    let zones = layers[0]
        .iter()
        .filter(|r| r.starts_with("soil_zones:"))
        .count();
    assert_eq!(zones, 2);
    let html = String::from_utf8(files[0]["p.html"].clone()).unwrap();
    assert!(html.contains("<section id=\"zones\">") && html.contains("zone_outlier"));
    // And the streamed CSV and GeoJSON are those of the records held in memory.
    let mut held_warnings = Vec::new();
    let records = export::load_records(&database, &mut held_warnings).unwrap();
    assert_eq!(records.len(), 23);
    assert_eq!(
        export::csv::to_bytes(&records, Precision::People).unwrap(),
        files[0]["p.csv"]
    );
    let doc = export::geojson::to_json(&records, Precision::People, &mut Vec::new());
    assert_eq!(serde_json::to_vec(&doc).unwrap(), files[0]["p.geojson"]);
}
