//! Broken and hostile inputs, run as a user would: the real binary on files made here. Each test
//! is one defect found by trying the program as an attacker and a careless user would; each
//! checks the program names the problem (file, line, column or segment), exits with the
//! contract's code, never panics (101) or aborts (134), and replaces nothing it should not.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use rusqlite::Connection;
use tempfile::TempDir;

fn pipewave(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
        .args(args)
        .output()
        .expect("run pipewave")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn manifest(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// A scratch directory with a database path in it.
struct Scratch {
    dir: TempDir,
    db: PathBuf,
}

impl Scratch {
    fn new() -> Scratch {
        let dir = tempfile::tempdir().unwrap();
        let db = dir.path().join("net.sqlite");
        Scratch { dir, db }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    fn write(&self, name: &str, content: &[u8]) -> String {
        let p = self.path(name);
        std::fs::write(&p, content).unwrap();
        p.to_str().unwrap().to_string()
    }

    fn db(&self) -> &str {
        self.db.to_str().unwrap()
    }

    /// `pipewave import --db DB --segments FILE` plus `extra`.
    fn import_segments(&self, file: &str, extra: &[&str]) -> Output {
        let mut args = vec!["import", "--db", self.db(), "--segments", file];
        args.extend(extra);
        pipewave(&args)
    }

    fn conn(&self) -> Connection {
        Connection::open(&self.db).unwrap()
    }
}

fn assert_code(out: &Output, code: i32) {
    assert_eq!(
        out.status.code(),
        Some(code),
        "stdout: {}\nstderr: {}",
        text(&out.stdout),
        text(&out.stderr)
    );
}

const SEG_HEADER: &str = "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3";

// --- 1. line numbers ----------------------------------------------------------------------------

#[test]
fn lf_crlf_and_cr_files_give_the_same_line_numbers() {
    // Line 1 header; lines 2-4 one record with a quoted cell spanning three lines; line 5 blank;
    // line 6 a bad diameter; lines 7-8 a record with a quoted id spanning two lines and a bad
    // wall.
    let lines = [
        format!("{SEG_HEADER},soil_type"),
        "A,DI,170,6,1900,\"clay{NL}with{NL}stones\"".to_string(),
        String::new(),
        "B,DI,x,6,1900,sand".to_string(),
        "\"C{NL}2\",DI,170,y,1900,clay".to_string(),
    ];
    for nl in ["\n", "\r\n", "\r"] {
        for bom in [false, true] {
            let s = Scratch::new();
            let mut body = if bom { "\u{feff}".to_string() } else { String::new() };
            for l in &lines {
                body.push_str(&l.replace("{NL}", nl));
                body.push_str(nl);
            }
            let f = s.write("segments.csv", body.as_bytes());
            let out = s.import_segments(&f, &[]);
            assert_code(&out, 2);
            let err = text(&out.stderr);
            let what = format!("ending {nl:?}, BOM {bom}");
            assert!(
                err.contains("segments.csv:6:3: column outer_diameter_mm: expected a number, found 'x'"),
                "{what}: {err}"
            );
            assert!(
                err.contains("segments.csv:7:4: column wall_thickness_mm: expected a number, found 'y'"),
                "{what}: {err}"
            );
            assert_eq!(err.lines().filter(|l| l.contains("segments.csv:")).count(), 2, "{what}: {err}");
        }
    }
}

// --- 2. GeoPackage text that is not UTF-8 -------------------------------------------------------

/// The fixture GeoPackage copied into `s`, with its spatial triggers dropped (they call
/// SpatiaLite functions this SQLite lacks), and `edit` applied to its layer water_mains.
fn edited_gpkg(s: &Scratch, edit: &str) -> String {
    let p = s.path("pipes.gpkg");
    std::fs::copy(manifest("tests/data/gis/pipes.gpkg"), &p).unwrap();
    let conn = Connection::open(&p).unwrap();
    let triggers: Vec<String> = conn
        .prepare("SELECT name FROM sqlite_master WHERE type = 'trigger'")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    for t in triggers {
        conn.execute_batch(&format!("DROP TRIGGER \"{t}\"")).unwrap();
    }
    conn.execute_batch(edit).unwrap();
    p.to_str().unwrap().to_string()
}

const UTILITY_MAP: [&str; 22] = [
    "--map", "segment_id=ASSET_ID", "--map", "outer_diameter_mm=DIAM_MM", "--map",
    "wall_thickness_mm=WALL_MM", "--map", "soil_density_kg_m3=SOIL_RHO", "--map",
    "pipe_youngs_modulus_pa=E_PIPE", "--map", "pipe_poisson=NU_PIPE", "--map",
    "pipe_density_kg_m3=RHO_PIPE", "--map", "pipe_loss_factor=ETA_PIPE", "--map",
    "length_m=LENGTH", "--map", "soil_type=SOIL", "--map", "install_year=YEAR_LAID",
];

#[test]
fn geopackage_text_that_is_not_utf8_is_named_when_used_and_ignored_otherwise() {
    // A Latin-1 street name ("Müllerstraße") in a field pipewave does not use: imported.
    let s = Scratch::new();
    let gpkg = edited_gpkg(
        &s,
        "UPDATE water_mains SET STREET = CAST(X'4DFC6C6C65727374726FDF65' AS TEXT) WHERE fid = 2;",
    );
    let mut args = vec!["--layer", "water_mains"];
    args.extend(UTILITY_MAP);
    let out = s.import_segments(&gpkg, &args);
    assert_code(&out, 0);
    // The same bytes in the material, which pipewave uses: that feature and field are named.
    let s = Scratch::new();
    let gpkg = edited_gpkg(
        &s,
        "UPDATE water_mains SET MATERIAL = CAST(X'4775DF' AS TEXT) WHERE fid = 3;",
    );
    let out = s.import_segments(&gpkg, &args);
    assert_code(&out, 2);
    let err = text(&out.stderr);
    assert!(
        err.contains("layer water_mains: feature 3: field MATERIAL: not UTF-8"),
        "{err}"
    );
}

// --- 8. import checks with the fitter's ranges ----------------------------------------------------

#[test]
fn measurements_the_fit_would_refuse_are_refused_at_import() {
    let s = Scratch::new();
    let segs = s.write("segments.csv", format!("{SEG_HEADER}\nA,DI,170,6,1900\n").as_bytes());
    let meas = s.write(
        "measurements.csv",
        b"segment_id,frequency_hz,k_re_rad_per_m,attenuation_np_per_m,k_re_std,attenuation_std\n\
          A,100,1e-320,0.01,,\n\
          A,110,1e308,0.01,,\n\
          A,1e-300,1,0.01,,\n\
          A,2e307,1,0.01,,\n\
          A,1e308,1,0.01,,\n\
          A,300,1,1e308,,\n\
          A,400,1,0.01,1e308,\n\
          A,500,1,0.01,,1e308\n\
          A,600,1,0.01,,\n",
    );
    let out = pipewave(&["import", "--db", s.db(), "--segments", &segs, "--measurements", &meas]);
    assert_code(&out, 2);
    let err = text(&out.stderr);
    for (line, col) in [
        (2, "3: column k_re_rad_per_m"),
        (3, "3: column k_re_rad_per_m"),
        (4, "2: column frequency_hz"),
        (5, "2: column frequency_hz"),
        (6, "2: column frequency_hz"),
        (7, "4: column attenuation_np_per_m"),
        (8, "5: column k_re_std"),
        (9, "6: column attenuation_std"),
    ] {
        assert!(err.contains(&format!("measurements.csv:{line}:{col}")), "line {line}: {err}");
    }
    assert!(!err.contains("measurements.csv:10"), "{err}");
    assert!(!err.contains("already has a measurement"), "{err}");
    assert!(!err.contains("inf"), "{err}");
}

// --- 9. absent optional columns keep what is stored --------------------------------------------

#[test]
fn an_absent_optional_column_keeps_the_stored_value_and_an_empty_cell_clears_it() {
    let s = Scratch::new();
    let full = s.write(
        "full.csv",
        format!(
            "{SEG_HEADER},pipe_poisson,length_m,soil_type,install_year,soil_zone,geometry_wkt,srid\n\
             A,DI,170,6,1900,0.28,85,clay,1970,north,\"LINESTRING (0 0, 10 0)\",27700\n"
        )
        .as_bytes(),
    );
    assert_code(&s.import_segments(&full, &[]), 0);
    let stored = |s: &Scratch| -> Vec<Option<String>> {
        s.conn()
            .query_row(
                "SELECT pipe_poisson, length_m, soil_type, install_year, soil_zone, geometry_wkt, \
                 srid FROM segments WHERE segment_id = 'A'",
                [],
                |r| {
                    (0..7)
                        .map(|i| {
                            r.get::<_, rusqlite::types::Value>(i).map(|v| match v {
                                rusqlite::types::Value::Null => None,
                                other => Some(format!("{other:?}")),
                            })
                        })
                        .collect()
                },
            )
            .unwrap()
    };
    let before = stored(&s);
    assert!(before.iter().all(Option::is_some), "{before:?}");
    // Only the required columns: nothing changes.
    let bare = s.write("bare.csv", format!("{SEG_HEADER}\nA,DI,170,6,1900\n").as_bytes());
    let out = s.import_segments(&bare, &[]);
    assert_code(&out, 0);
    assert!(text(&out.stdout).contains("0 updated, 1 unchanged"), "{}", text(&out.stdout));
    assert_eq!(stored(&s), before);
    // The columns present with empty cells: cleared.
    let empty = s.write(
        "empty.csv",
        format!(
            "{SEG_HEADER},pipe_poisson,length_m,soil_type,install_year,soil_zone,geometry_wkt,srid\n\
             A,DI,170,6,1900,,,,,,,\n"
        )
        .as_bytes(),
    );
    let out = s.import_segments(&empty, &[]);
    assert_code(&out, 0);
    assert!(text(&out.stdout).contains("1 updated"), "{}", text(&out.stdout));
    assert!(stored(&s).iter().all(Option::is_none), "{:?}", stored(&s));
}

// --- 10. control characters ----------------------------------------------------------------------

#[test]
fn control_characters_in_cells_and_headers_are_escaped_in_messages() {
    let s = Scratch::new();
    let f = s.write(
        "segments.csv",
        format!("{SEG_HEADER},x\x1b[31m\nA,DI,\x1b]0;owned\x07,6,1900,\0\n").as_bytes(),
    );
    let out = s.import_segments(&f, &[]);
    assert_code(&out, 2);
    let err = text(&out.stderr);
    for c in ['\x1b', '\x07', '\0'] {
        assert!(!err.contains(c), "raw {c:?} in: {err:?}");
    }
    assert!(err.contains("found '\\u{1b}]0;owned\\u{7}'"), "{err}");
    assert!(err.contains("x\\u{1b}[31m"), "{err}");
}

// --- 11. the error list is bounded --------------------------------------------------------------

#[test]
fn the_error_list_names_the_first_1000_problems_then_counts_the_rest() {
    let s = Scratch::new();
    let mut body = format!("{SEG_HEADER}\n");
    for i in 0..2500 {
        body.push_str(&format!("S{i},DI,bad,6,1900\n"));
    }
    let f = s.write("segments.csv", body.as_bytes());
    let out = s.import_segments(&f, &[]);
    assert_code(&out, 2);
    let err = text(&out.stderr);
    let listed: Vec<&str> = err.lines().filter(|l| l.contains("segments.csv:")).collect();
    assert_eq!(listed.len(), 1000, "{}", &err[err.len().saturating_sub(500)..]);
    assert!(listed[0].starts_with(&format!("{f}:2:3:")), "{}", listed[0]);
    assert!(listed[999].starts_with(&format!("{f}:1001:3:")), "{}", listed[999]);
    assert!(err.contains("and 1500 more problems"), "{}", &err[err.len() - 400..]);
    assert!(err.contains("2500 problems found"), "{}", &err[err.len() - 400..]);
}

// --- 12 and 13. GeoJSON: coordinates, --srid, BOM, no features --------------------------------

const PROJECTED_GEOJSON: &str = r#"{"type": "FeatureCollection", "features": [
 {"type": "Feature", "id": 1, "properties": {"segment_id": "A", "material": "DI",
  "outer_diameter_mm": 170, "wall_thickness_mm": 6, "soil_density_kg_m3": 1900},
  "geometry": {"type": "LineString", "coordinates": [[441800, 111900], [441920, 111900]]}}]}"#;

#[test]
fn geojson_without_crs_and_projected_coordinates_is_refused_unless_srid_names_the_crs() {
    let s = Scratch::new();
    let f = s.write("pipes.geojson", PROJECTED_GEOJSON.as_bytes());
    let out = s.import_segments(&f, &[]);
    assert_code(&out, 2);
    let err = text(&out.stderr);
    assert!(err.contains("feature 1"), "{err}");
    assert!(err.contains("--srid"), "{err}");
    assert!(err.contains("longitude"), "{err}");
    let out = s.import_segments(&f, &["--srid", "27700"]);
    assert_code(&out, 0);
    let (srid, wkt): (i64, String) = s
        .conn()
        .query_row("SELECT srid, geometry_wkt FROM segments", [], |r| {
            Ok((r.get(0)?, r.get(1)?))
        })
        .unwrap();
    assert_eq!(srid, 27700);
    assert!(wkt.contains("441800"), "{wkt}");
}

#[test]
fn geojson_with_a_bom_imports_and_an_empty_collection_says_so() {
    let s = Scratch::new();
    let geographic = PROJECTED_GEOJSON
        .replace("[441800, 111900], [441920, 111900]", "[-1.5, 51.2], [-1.49, 51.2]");
    let f = s.write("pipes.geojson", format!("\u{feff}{geographic}").as_bytes());
    let out = s.import_segments(&f, &[]);
    assert_code(&out, 0);
    let f = s.write("empty.geojson", br#"{"type": "FeatureCollection", "features": []}"#);
    let out = s.import_segments(&f, &[]);
    assert_code(&out, 2);
    let err = text(&out.stderr);
    assert!(err.contains("no features"), "{err}");
    assert!(!err.contains("missing required"), "{err}");
}
