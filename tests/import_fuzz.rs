//! Property tests of the import readers on arbitrary input: the two CSV importers, the WKT
//! parser and the GIS layer readers (GeoJSON, Shapefile; the GeoPackage geometry blob is fuzzed
//! by a unit test beside its parser). None may panic, and every problem must name its file and
//! its place (line and column, or layer, feature and field), with numbers in short form.
//!
//! The CI run is short (`FUZZ_CASES` cases per property, below); set `PROPTEST_CASES` for a
//! longer run, e.g. `PROPTEST_CASES=20000 cargo test --release --test import_fuzz`.

use std::f64::consts::PI;

use pipewave::db::wkt::LineString;
use pipewave::db::{self, Connection, ImportOptions, ImportReport, ImportSource, SourceKind};
use proptest::prelude::*;

/// Cases per property in CI.
const FUZZ_CASES: u32 = 256;

fn config() -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(FUZZ_CASES);
    ProptestConfig {
        cases,
        failure_persistence: None,
        // A fixed seed (overriding PROPTEST_RNG_SEED): the same cases on every run.
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x7069_7065_7761_7665),
        ..ProptestConfig::default()
    }
}

fn database() -> Connection {
    let mut conn = Connection::open_in_memory().unwrap();
    conn.pragma_update(None, "foreign_keys", true).unwrap();
    db::migrate::migrate(&mut conn, std::path::Path::new(":memory:")).unwrap();
    conn
}

/// The longest run of digits in `s` (a number printed in full has hundreds).
fn longest_digit_run(s: &str) -> usize {
    s.split(|c: char| !c.is_ascii_digit())
        .map(str::len)
        .max()
        .unwrap_or(0)
}

/// Every error names the file and a place; numbers are short. `digits_in_input` is the longest
/// digit run the input itself holds (echoed cells may repeat it).
fn check_report(r: &ImportReport, names: &[&str], layer: bool, digits_in_input: usize) {
    for e in &r.errors {
        let text = e.to_string();
        assert!(
            names.contains(&e.file.as_str()),
            "error of an unknown file: {text}"
        );
        assert!(text.starts_with(&e.file), "{text}");
        if e.layer.is_none() {
            // A CSV problem: its line (1-based), or, for a layer, a problem with the file as
            // a whole (line 0, no layer yet: the layer could not be read).
            assert!(e.line >= 1 || layer, "no line in {text}");
        }
        if let Some(c) = &e.column {
            // The name may be blank (a header cell with no name): the index places it.
            assert!(c.index >= 1, "{text}");
        }
        assert!(
            longest_digit_run(&e.message) <= digits_in_input.max(20),
            "a number printed in full: {text}"
        );
    }
    if r.rejected {
        assert!(!r.errors.is_empty(), "rejected without a reason");
    }
}

/// A cell: a number in any notation (huge, tiny, negative, non-finite), a word, or blank.
fn cell() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<f64>().prop_map(|x| format!("{x:e}")),
        (-1e4f64..1e4).prop_map(|x| format!("{x}")),
        Just(String::new()),
        "[A-Za-z ,\"'\\-]{0,12}",
        Just("1e308".to_string()),
        Just("-0".to_string()),
        Just("NaN".to_string()),
        prop::sample::select(vec!["CI", "DI", "Cast Iron", "uPVC", "PE100", "hdpe", "XX"])
            .prop_map(str::to_string),
        Just("\"LINESTRING (0 0, 1 1)\"".to_string()),
        "[0-9]{4}-[0-9]{2}-[0-9]{2}",
    ]
}

const SEGMENT_HEADER: [&str; 10] = [
    "segment_id",
    "material",
    "outer_diameter_mm",
    "wall_thickness_mm",
    "soil_density_kg_m3",
    "pipe_poisson",
    "geometry_wkt",
    "srid",
    "soil_zone",
    "street",
];

const MEASUREMENT_HEADER: [&str; 8] = [
    "segment_id",
    "frequency_hz",
    "omega_rad_s",
    "k_re_rad_per_m",
    "attenuation_np_per_m",
    "k_re_std",
    "measured_on",
    "campaign",
];

/// A CSV with the given header (some columns maybe dropped) and random rows.
fn csv_text(header: &'static [&'static str]) -> impl Strategy<Value = String> {
    (
        prop::collection::vec(any::<bool>(), header.len()),
        prop::collection::vec(
            prop::collection::vec(cell(), header.len()..=header.len() + 1),
            0..6,
        ),
    )
        .prop_map(move |(keep, rows)| {
            let cols: Vec<usize> = (0..header.len()).filter(|&i| keep[i] || i < 2).collect();
            let mut s = cols
                .iter()
                .map(|&i| header[i])
                .collect::<Vec<_>>()
                .join(",");
            s.push('\n');
            for r in rows {
                let cells: Vec<&str> = cols.iter().map(|&i| r[i].as_str()).collect();
                s.push_str(&cells.join(","));
                s.push('\n');
            }
            s
        })
}

fn import_csv(
    segments: Option<Vec<u8>>,
    measurements: Option<Vec<u8>>,
    strict: bool,
) -> ImportReport {
    import_csv_into(&mut database(), segments, measurements, strict)
}

fn import_csv_into(
    conn: &mut Connection,
    segments: Option<Vec<u8>>,
    measurements: Option<Vec<u8>>,
    strict: bool,
) -> ImportReport {
    let s = segments.map(|d| ImportSource::from_bytes("segments.csv", d));
    let m = measurements.map(|d| ImportSource::from_bytes("measurements.csv", d));
    db::import(
        conn,
        s.as_ref(),
        m.as_ref(),
        ImportOptions {
            strict,
            ..ImportOptions::default()
        },
    )
    .unwrap()
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn segments_csv_of_arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let digits = longest_digit_run(&String::from_utf8_lossy(&bytes));
        let r = import_csv(Some(bytes), None, false);
        check_report(&r, &["segments.csv"], false, digits);
    }

    #[test]
    fn segments_csv_of_plausible_rows(text in csv_text(&SEGMENT_HEADER), strict in any::<bool>()) {
        let r = import_csv(Some(text.into_bytes()), None, strict);
        check_report(&r, &["segments.csv"], false, 20);
    }

    #[test]
    fn measurements_csv_of_arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let segs = b"segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3\nA,CI,150,8,1900\n".to_vec();
        let digits = longest_digit_run(&String::from_utf8_lossy(&bytes));
        let r = import_csv(Some(segs), Some(bytes), false);
        check_report(&r, &["segments.csv", "measurements.csv"], false, digits);
    }

    #[test]
    fn measurements_csv_of_plausible_rows(text in csv_text(&MEASUREMENT_HEADER)) {
        let segs = b"segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3\nA,CI,150,8,1900\n".to_vec();
        let mut conn = database();
        let r = import_csv_into(&mut conn, Some(segs), Some(text.into_bytes()), false);
        check_report(&r, &["segments.csv", "measurements.csv"], false, 20);
        // Whatever was stored is a measurement the model can use.
        if !r.rejected {
            for m in pipewave::db::inventory::load_measurements(&conn, "A").unwrap() {
                prop_assert!(m.omega_rad_s > 0.0 && (m.omega_rad_s - 2.0 * PI * m.frequency_hz).abs() <= 1e-9 * m.omega_rad_s);
            }
        }
    }

    #[test]
    fn wkt_of_arbitrary_text(text in ".{0,80}") {
        if let Ok(l) = LineString::parse_wkt(&text) {
            prop_assert!(l.points.len() >= 2);
            prop_assert_eq!(LineString::parse_wkt(&l.to_wkt()).unwrap(), l);
        }
    }

    #[test]
    fn wkt_of_plausible_lines(
        pts in prop::collection::vec((any::<f64>(), any::<f64>()), 0..5),
        keyword in prop::sample::select(vec!["LINESTRING", "linestring", "LINESTRING Z", "POINT", "LINESTRING EMPTY"]),
    ) {
        let body: Vec<String> = pts.iter().map(|(x, y)| format!("{x:e} {y:e}")).collect();
        let text = format!("{keyword} ({})", body.join(", "));
        match LineString::parse_wkt(&text) {
            Ok(l) => {
                prop_assert_eq!(&l.points, &pts);
                prop_assert_eq!(LineString::parse_wkt(&l.to_wkt()).unwrap(), l);
            }
            Err(e) => prop_assert!(longest_digit_run(&e) <= 20, "{}", e),
        }
    }

    #[test]
    fn geojson_of_arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        let digits = longest_digit_run(&String::from_utf8_lossy(&bytes));
        let r = import_layer(bytes, SourceKind::GeoJson);
        check_report(&r, &["pipes.geojson"], true, digits);
    }

    #[test]
    fn geojson_of_plausible_features(
        feats in prop::collection::vec((cell(), cell(), cell(), prop::collection::vec((any::<f64>(), any::<f64>()), 0..3), 0..3usize), 0..4),
    ) {
        let features: Vec<serde_json::Value> = feats
            .iter()
            .enumerate()
            .map(|(i, (id, mat, d, pts, parts))| {
                let line: Vec<[f64; 2]> = pts.iter().map(|&(x, y)| [x, y]).collect();
                let geometry = match parts {
                    0 => serde_json::Value::Null,
                    1 => serde_json::json!({"type": "LineString", "coordinates": line}),
                    n => serde_json::json!({"type": "MultiLineString", "coordinates": vec![line; *n - 1]}),
                };
                serde_json::json!({"type": "Feature", "id": i, "properties": {
                    "ASSET_ID": id, "material": mat, "DIAM_MM": d, "wall_thickness_mm": "8",
                    "soil_density_kg_m3": 1900}, "geometry": geometry})
            })
            .collect();
        let doc = serde_json::json!({"type": "FeatureCollection", "features": features});
        let mut conn = database();
        let src = ImportSource { name: "pipes.geojson".into(), data: doc.to_string().into_bytes(), kind: SourceKind::GeoJson };
        let r = db::import(&mut conn, Some(&src), None, ImportOptions {
            map: vec![("segment_id".into(), "ASSET_ID".into()), ("outer_diameter_mm".into(), "DIAM_MM".into())],
            ..ImportOptions::default()
        }).unwrap();
        check_report(&r, &["pipes.geojson"], true, 20);
        for e in &r.errors {
            // Past the file as a whole, every problem is a feature's.
            if e.layer.is_some() && e.line > 0 {
                let names_feature = e.to_string().contains(&format!("feature {}", e.line));
                prop_assert!(names_feature, "{}", e);
            }
        }
    }

    #[test]
    fn shapefile_of_arbitrary_bytes(
        shp in prop::collection::vec(any::<u8>(), 0..300),
        dbf in prop::option::of(prop::collection::vec(any::<u8>(), 0..300)),
        prj in prop::option::of(".{0,40}"),
    ) {
        let r = import_layer(shp, SourceKind::Shapefile { dbf, prj: prj.map(String::into_bytes) });
        check_report(&r, &["pipes.shp"], true, 20);
    }

    #[test]
    fn shapefile_with_a_real_header_and_arbitrary_tail(cut in 0usize..2000, noise in prop::collection::vec(any::<u8>(), 0..64), at in 0usize..2000) {
        // The committed fixture, truncated and overwritten somewhere.
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/gis");
        let mut shp = std::fs::read(dir.join("pipes.shp")).unwrap();
        let mut dbf = std::fs::read(dir.join("pipes.dbf")).unwrap();
        for f in [&mut shp, &mut dbf] {
            let at = at.min(f.len());
            for (i, b) in noise.iter().enumerate() {
                if let Some(x) = f.get_mut(at + i) { *x = *b; }
            }
            let keep = f.len().saturating_sub(cut);
            f.truncate(keep);
        }
        let prj = std::fs::read(dir.join("pipes.prj")).ok();
        let r = import_layer(shp, SourceKind::Shapefile { dbf: Some(dbf), prj });
        check_report(&r, &["pipes.shp"], true, 20);
    }
}

fn import_layer(data: Vec<u8>, kind: SourceKind) -> ImportReport {
    let name = match kind {
        SourceKind::GeoJson => "pipes.geojson",
        _ => "pipes.shp",
    };
    let mut conn = database();
    let src = ImportSource {
        name: name.into(),
        data,
        kind,
    };
    db::import(&mut conn, Some(&src), None, ImportOptions::default()).unwrap()
}
