//! Property tests of the three readers and writers that crashed on hostile input: GeoPackage
//! layers built as SQLite tables with cells of any type and any bytes; WAV files with arbitrary
//! headers and bodies, and layout files; and the output writers given hostile segment ids. None
//! may panic (exit 101) or abort (134): the readers run here in-process, so a panic fails the
//! property and an abort ends the whole run. Two properties run the real binary and check its
//! exit code.
//!
//! CI runs `FUZZ_CASES` cases per property; set `PROPTEST_CASES` for a longer run, e.g.
//! `PROPTEST_CASES=10000 cargo test --release --test reader_fuzz` (docs/robustness.md).

use std::path::Path;
use std::process::Command;

use pipewave::db::{self, Connection, ImportOptions, ImportSource};
use pipewave::recordings::{analyse_segment, read_layout, EstimateOptions};
use proptest::prelude::*;
use rusqlite::types::Value;

/// Cases per property in CI.
const FUZZ_CASES: u32 = 256;

fn config(ci_cases: u32) -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(ci_cases);
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
    db::migrate::migrate(&mut conn, Path::new(":memory:")).unwrap();
    conn
}

// --- GeoPackage -----------------------------------------------------------------------------------

/// A generated cell: (kind: 0 NULL, 1 integer, 2 real, 3 blob, 4-5 text), bytes, integer, real.
type Cell = (u8, Vec<u8>, i64, f64);
/// A generated feature: its geometry blob and its cells.
type Feature = (Option<Vec<u8>>, Vec<Cell>);

/// A cell of any SQLite type; text may hold any bytes (not UTF-8 too).
fn sql_cell() -> impl Strategy<Value = Cell> {
    (
        0u8..6,
        prop::collection::vec(any::<u8>(), 0..12),
        any::<i64>(),
        any::<f64>(),
    )
}

/// A GeoPackage geometry blob: a valid line, or bytes.
fn geometry() -> impl Strategy<Value = Option<Vec<u8>>> {
    prop_oneof![
        Just(None),
        prop::collection::vec(any::<u8>(), 0..60).prop_map(Some),
        (any::<f64>(), any::<f64>(), 0u32..4).prop_map(|(x, y, n)| {
            let mut b = b"GP\0\x01".to_vec();
            b.extend(4326i32.to_le_bytes());
            b.push(1);
            b.extend(2u32.to_le_bytes());
            b.extend(n.to_le_bytes());
            for i in 0..n {
                b.extend((x + f64::from(i)).to_le_bytes());
                b.extend(y.to_le_bytes());
            }
            Some(b)
        }),
    ]
}

const GPKG_FIELDS: [&str; 7] = [
    "segment_id",
    "material",
    "outer_diameter_mm",
    "wall_thickness_mm",
    "soil_density_kg_m3",
    "soil_type",
    "street",
];

/// Write a one-layer GeoPackage whose features have the given cells.
fn write_gpkg(path: &Path, srs: (i64, &str, i64), rows: &[Feature]) {
    let conn = Connection::open(path).unwrap();
    conn.execute_batch(
        "CREATE TABLE gpkg_spatial_ref_sys (srs_name TEXT, srs_id INTEGER PRIMARY KEY, \
         organization TEXT, organization_coordsys_id INTEGER, definition TEXT);
         CREATE TABLE gpkg_contents (table_name TEXT PRIMARY KEY, data_type TEXT, srs_id INTEGER);
         CREATE TABLE gpkg_geometry_columns (table_name TEXT, column_name TEXT, \
         geometry_type_name TEXT, srs_id INTEGER, z INTEGER, m INTEGER);
         INSERT INTO gpkg_contents VALUES ('pipes', 'features', 1);
         INSERT INTO gpkg_geometry_columns VALUES ('pipes', 'geom', 'LINESTRING', 1, 0, 0);",
    )
    .unwrap();
    conn.execute(
        "INSERT INTO gpkg_spatial_ref_sys VALUES ('s', 1, ?2, ?3, '')",
        rusqlite::params![srs.0, srs.1, srs.2],
    )
    .unwrap();
    let cols: Vec<String> = GPKG_FIELDS.iter().map(|f| format!("\"{f}\"")).collect();
    conn.execute_batch(&format!(
        "CREATE TABLE pipes (fid INTEGER PRIMARY KEY, geom BLOB, {})",
        cols.join(", ")
    ))
    .unwrap();
    for (geom, cells) in rows {
        let mut values = vec![match geom {
            Some(b) => Value::Blob(b.clone()),
            None => Value::Null,
        }];
        for (kind, bytes, i, x) in cells {
            values.push(match kind {
                0 => Value::Null,
                1 => Value::Integer(*i),
                2 => Value::Real(*x),
                3 => Value::Blob(bytes.clone()),
                // Text of any bytes: SQLite stores it as given.
                _ => Value::Blob(bytes.clone()),
            });
        }
        let marks: Vec<String> = (0..values.len())
            .map(|k| {
                let text = k > 0 && cells[k - 1].0 >= 4;
                if text {
                    format!("CAST(?{} AS TEXT)", k + 1)
                } else {
                    format!("?{}", k + 1)
                }
            })
            .collect();
        conn.execute(
            &format!(
                "INSERT INTO pipes (geom, {}) VALUES ({})",
                cols.join(", "),
                marks.join(", ")
            ),
            rusqlite::params_from_iter(values),
        )
        .unwrap();
    }
}

fn gpkg_rows() -> impl Strategy<Value = Vec<Feature>> {
    prop::collection::vec(
        (
            geometry(),
            prop::collection::vec(sql_cell(), GPKG_FIELDS.len()),
        ),
        0..6,
    )
}

proptest! {
    #![proptest_config(config(FUZZ_CASES))]

    #[test]
    fn geopackage_tables_of_arbitrary_cells(
        rows in gpkg_rows(),
        srs in prop_oneof![
            Just((27700i64, "EPSG", 27700i64)),
            Just((4326, "EPSG", 4326)),
            Just((1, "NONE", -1)),
        ],
        skip in any::<bool>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("layer.gpkg");
        write_gpkg(&path, srs, &rows);
        let source = ImportSource::from_path(&path).unwrap();
        let mut conn = database();
        let r = db::import(
            &mut conn,
            Some(&source),
            None,
            ImportOptions { skip_invalid: skip, ..ImportOptions::default() },
        )
        .unwrap();
        for e in &r.errors {
            let t = e.to_string();
            prop_assert!(t.starts_with(&source.name), "{}", t);
            prop_assert!(!t.chars().any(char::is_control), "{:?}", t);
        }
        prop_assert!(r.errors.len() <= r.problems);
        if r.rejected {
            prop_assert!(r.problems > 0);
        }
    }
}

// --- WAV files and layouts --------------------------------------------------------------------------

/// The bytes of a WAV file with any header fields and body.
fn wav_bytes(
    format: u16,
    channels: u16,
    rate: u32,
    bits: u16,
    claimed: u32,
    body: &[u8],
) -> Vec<u8> {
    let block = channels.wrapping_mul(bits.div_ceil(8));
    let mut b = Vec::new();
    b.extend(b"RIFF");
    b.extend(claimed.wrapping_add(36).to_le_bytes());
    b.extend(b"WAVEfmt ");
    b.extend(16u32.to_le_bytes());
    b.extend(format.to_le_bytes());
    b.extend(channels.to_le_bytes());
    b.extend(rate.to_le_bytes());
    b.extend(rate.wrapping_mul(u32::from(block)).to_le_bytes());
    b.extend(block.to_le_bytes());
    b.extend(bits.to_le_bytes());
    b.extend(b"data");
    b.extend(claimed.to_le_bytes());
    b.extend(body);
    b
}

fn wav_header() -> impl Strategy<Value = (u16, u16, u32, u16, u32)> {
    (
        prop::sample::select(vec![1u16, 3, 0xFFFE, 0, 7]),
        prop_oneof![1u16..4, any::<u16>()],
        prop_oneof![Just(8000u32), Just(0), Just(1), any::<u32>()],
        prop::sample::select(vec![8u16, 16, 24, 32, 0, 12, 64]),
        prop_oneof![Just(u32::MAX), Just(0xFFFF_FFF0), 0u32..100_000],
    )
}

/// A layout of arbitrary rows over the files a.wav and b.wav.
fn layout_text() -> impl Strategy<Value = String> {
    prop::collection::vec(
        (
            prop::sample::select(vec!["S1", "S2", "", "S\u{1b}"]),
            prop::sample::select(vec!["a.wav", "b.wav", "missing.wav", "../a.wav", ""]),
            prop_oneof![Just("0".to_string()), Just("1".to_string()), "[0-9x-]{0,6}"],
            prop_oneof![
                (-100.0f64..100.0).prop_map(|x| x.to_string()),
                Just("0".to_string()),
                Just("NaN".to_string()),
                Just("1e308".to_string()),
            ],
        ),
        0..6,
    )
    .prop_map(|rows| {
        let mut t = "segment_id,file,channel,position_m\n".to_string();
        for (s, f, c, x) in rows {
            t.push_str(&format!("{s},{f},{c},{x}\n"));
        }
        t
    })
}

fn analyse_all(dir: &Path) {
    let Ok(layout) = read_layout(&dir.join("layout.csv")) else {
        return;
    };
    for seg in &layout.segments {
        let _ = analyse_segment(&layout.path, seg, &EstimateOptions::default(), &|_| {});
    }
}

proptest! {
    #![proptest_config(config(FUZZ_CASES))]

    #[test]
    fn wav_files_of_arbitrary_headers_and_bodies(
        a in wav_header(),
        body_a in prop::collection::vec(any::<u8>(), 0..3000),
        b in wav_header(),
        body_b in prop::collection::vec(any::<u8>(), 0..3000),
        layout in layout_text(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("a.wav"), wav_bytes(a.0, a.1, a.2, a.3, a.4, &body_a)).unwrap();
        std::fs::write(dir.path().join("b.wav"), wav_bytes(b.0, b.1, b.2, b.3, b.4, &body_b)).unwrap();
        std::fs::write(dir.path().join("layout.csv"), layout).unwrap();
        analyse_all(dir.path());
    }

    #[test]
    fn layout_files_of_arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("layout.csv"), bytes).unwrap();
        std::fs::write(dir.path().join("a.wav"), wav_bytes(1, 1, 8000, 16, 10, &[0; 10])).unwrap();
        analyse_all(dir.path());
    }

    #[test]
    fn the_sample_reservation_never_exceeds_the_file(
        header in any::<u64>(),
        file in 0u64..1 << 40,
        per_frame in 0u64..64,
    ) {
        let n = pipewave::recordings::wav::reserve_frames(header, file, per_frame) as u64;
        prop_assert!(n <= header);
        prop_assert!(n.saturating_mul(per_frame.max(1)) <= file);
    }
}

// --- writers given hostile ids -----------------------------------------------------------------------

/// Ids an attacker would try: control characters, quotes, formula and HTML text, any Unicode.
fn hostile_id() -> impl Strategy<Value = String> {
    prop_oneof![
        "[=+@\\-][A-Za-z0-9(),;\"']{0,10}",
        "<script>[a-z]{0,5}</script>",
        "[\"',;\\\\]{1,6}[a-z]{0,3}",
        "\\PC{1,12}",
        "[a-z]{0,3}[\\x00-\\x1f\\x7f]{1,3}[a-z]{0,3}",
    ]
    .prop_map(|s| s.trim().replace('\0', "\u{1}"))
    .prop_filter("a segment id", |s| !s.is_empty())
}

fn run(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
        .args(args)
        .output()
        .expect("run pipewave")
}

proptest! {
    #![proptest_config(config(FUZZ_CASES / 8))]

    /// Through the binary: import segments with hostile ids, then export every format and the
    /// audit. Every command succeeds; the CSV and GeoJSON read back with the same ids.
    #[test]
    fn writers_given_hostile_ids(ids in prop::collection::btree_set(hostile_id(), 1..5)) {
        let dir = tempfile::tempdir().unwrap();
        let db = dir.path().join("db.sqlite");
        let mut w = csv::Writer::from_writer(Vec::new());
        w.write_record(["segment_id", "material", "outer_diameter_mm", "wall_thickness_mm",
            "soil_density_kg_m3"]).unwrap();
        for id in &ids {
            w.write_record([id.as_str(), "DI", "170", "6", "1900"]).unwrap();
        }
        let segs = dir.path().join("segments.csv");
        std::fs::write(&segs, w.into_inner().unwrap()).unwrap();
        let db_s = db.to_str().unwrap();
        let out = run(&["import", "--db", db_s, "--segments", segs.to_str().unwrap()]);
        let code = out.status.code();
        prop_assert!(code == Some(0) || code == Some(2), "{:?} {}", code, String::from_utf8_lossy(&out.stderr));
        prop_assume!(code == Some(0));
        for (format, name) in [("csv", "o.csv"), ("geojson", "o.geojson"), ("gpkg", "o.gpkg")] {
            let p = dir.path().join(name);
            let out = run(&["export", "--db", db_s, "--format", format, "--out", p.to_str().unwrap()]);
            prop_assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
        }
        let html = dir.path().join("a.html");
        let out = run(&["audit", "--db", db_s, "--out", html.to_str().unwrap()]);
        prop_assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
        let page = std::fs::read_to_string(&html).unwrap();
        prop_assert!(!page.contains("<script>"));
        let mut r = csv::Reader::from_path(dir.path().join("o.csv")).unwrap();
        let back: std::collections::BTreeSet<String> = r
            .records()
            .map(|rec| {
                let rec = rec.unwrap();
                pipewave::spreadsheet::unneutralise(&rec[0]).to_string()
            })
            .collect();
        prop_assert_eq!(&back, &ids);
        let gj: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("o.geojson")).unwrap()).unwrap();
        let n = gj["features"].as_array().map_or(0, Vec::len);
        prop_assert_eq!(n, ids.len());
    }

    /// Through the binary: a WAV whose header overstates its length, among good layouts.
    #[test]
    fn wavenumbers_binary_never_panics_or_aborts(
        a in wav_header(),
        body in prop::collection::vec(any::<u8>(), 0..2000),
        layout in layout_text(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("a.wav"), wav_bytes(a.0, a.1, a.2, a.3, a.4, &body)).unwrap();
        std::fs::write(dir.path().join("b.wav"), wav_bytes(a.0, a.1, a.2, a.3, a.4, &body)).unwrap();
        std::fs::write(dir.path().join("layout.csv"), layout).unwrap();
        let out = run(&[
            "wavenumbers",
            "--layout",
            dir.path().join("layout.csv").to_str().unwrap(),
            "--out",
            dir.path().join("m.csv").to_str().unwrap(),
        ]);
        let code = out.status.code();
        prop_assert!(matches!(code, Some(0..=2)), "{:?}: {}", code, String::from_utf8_lossy(&out.stderr));
    }
}
