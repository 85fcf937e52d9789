//! `pipewave import`, run as a user would: the real binary on temporary databases.
//!
//! Fixtures: `tests/data/import/segments.csv` (4 segments) and `measurements.csv` (8 rows for 3
//! of them), hand-written. The bad-row cases are generated here, each next to its expectation.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use rusqlite::types::Value;
use rusqlite::Connection;
use tempfile::TempDir;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/import")
        .join(name)
}

fn pipewave(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
        .args(args)
        .output()
        .expect("run pipewave")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
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

    fn write(&self, name: &str, content: &[u8]) -> PathBuf {
        let p = self.dir.path().join(name);
        std::fs::write(&p, content).unwrap();
        p
    }

    fn db(&self) -> &str {
        self.db.to_str().unwrap()
    }

    /// `pipewave import --db DB` with the given files (None: flag absent) and extra flags.
    fn import(
        &self,
        segments: Option<&Path>,
        measurements: Option<&Path>,
        extra: &[&str],
    ) -> Output {
        let mut args = vec!["import", "--db", self.db()];
        if let Some(s) = segments {
            args.extend(["--segments", s.to_str().unwrap()]);
        }
        if let Some(m) = measurements {
            args.extend(["--measurements", m.to_str().unwrap()]);
        }
        args.extend(extra);
        pipewave(&args)
    }

    fn import_fixtures(&self) -> Output {
        let out = self.import(
            Some(&fixture("segments.csv")),
            Some(&fixture("measurements.csv")),
            &[],
        );
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        out
    }

    fn conn(&self) -> Connection {
        Connection::open(&self.db).unwrap()
    }

    fn count(&self, table: &str) -> i64 {
        self.conn()
            .query_row(&format!("SELECT COUNT(*) FROM {table}"), [], |r| r.get(0))
            .unwrap()
    }

    /// Every row of segments and measurements, every column, as text.
    fn snapshot(&self) -> Vec<String> {
        let conn = self.conn();
        let mut out = Vec::new();
        for sql in [
            "SELECT * FROM segments ORDER BY segment_id",
            "SELECT * FROM measurements ORDER BY segment_id, omega_rad_s",
        ] {
            let mut stmt = conn.prepare(sql).unwrap();
            let n = stmt.column_count();
            let rows = stmt
                .query_map([], |r| {
                    (0..n)
                        .map(|i| r.get::<_, Value>(i).map(|v| format!("{v:?}")))
                        .collect::<Result<Vec<_>, _>>()
                })
                .unwrap();
            for r in rows {
                out.push(r.unwrap().join("|"));
            }
        }
        out
    }

    fn hashes(&self) -> BTreeMap<String, String> {
        let conn = self.conn();
        let mut stmt = conn
            .prepare("SELECT segment_id, inputs_hash FROM segments")
            .unwrap();
        let rows = stmt.query_map([], |r| Ok((r.get(0)?, r.get(1)?))).unwrap();
        rows.map(Result::unwrap).collect()
    }
}

/// Data lines of a fixture (lines after the header).
fn data_lines(name: &str) -> i64 {
    let t = std::fs::read_to_string(fixture(name)).unwrap();
    i64::try_from(t.lines().filter(|l| !l.trim().is_empty()).count()).unwrap() - 1
}

#[test]
fn a_good_import_stores_every_row_with_units_converted() {
    let s = Scratch::new();
    let out = s.import_fixtures();
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains(
            "segments 4 new, 0 updated, 0 unchanged; measurements 8 written for 3 segments"
        ),
        "{stdout}"
    );
    assert_eq!(text(&out.stderr), "");
    assert_eq!(s.count("segments"), data_lines("segments.csv"));
    assert_eq!(s.count("measurements"), data_lines("measurements.csv"));

    let conn = s.conn();
    // Materials stored upper case; " mdpe " trimmed.
    let materials: Vec<String> = conn
        .prepare("SELECT material FROM segments ORDER BY segment_id")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(materials, ["CI", "DI", "MDPE", "PVC"]);
    // ω = 2πf both ways (tolerance: a few ulps of 2π·100).
    let (w, f): (f64, f64) = conn
        .query_row(
            "SELECT omega_rad_s, frequency_hz FROM measurements \
             WHERE segment_id = 'CI-0001' AND frequency_hz = 100",
            [],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .unwrap();
    assert!(
        (w - 2.0 * std::f64::consts::PI * 100.0).abs() < 1e-12,
        "{w} {f}"
    );
    let f: f64 = conn
        .query_row(
            "SELECT frequency_hz FROM measurements WHERE segment_id = 'DI-0002' ORDER BY omega_rad_s",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert!((f - 100.0).abs() < 1e-9, "{f}");
    // Blank optional cells are NULL; geometry stored in canonical form.
    let (e, wkt, srid): (Option<f64>, Option<String>, Option<i64>) = conn
        .query_row(
            "SELECT pipe_youngs_modulus_pa, geometry_wkt, srid FROM segments WHERE segment_id = 'CI-0001'",
            [],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
        )
        .unwrap();
    assert_eq!(e, None);
    assert_eq!(
        wkt.as_deref(),
        Some("LINESTRING (531200.5 181300.25, 531320 181310)")
    );
    assert_eq!(srid, Some(27700));
    for (id, h) in s.hashes() {
        assert!(
            h.len() == 16 && h.chars().all(|c| c.is_ascii_hexdigit()),
            "{id}: {h}"
        );
    }
}

#[test]
fn migrations_create_every_table_and_the_view_and_set_user_version() {
    let s = Scratch::new();
    s.import_fixtures();
    let conn = s.conn();
    let objects: Vec<(String, String)> = conn
        .prepare(
            "SELECT type, name FROM sqlite_master WHERE type IN ('table', 'view') ORDER BY name",
        )
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    for (kind, name) in [
        ("table", "segments"),
        ("table", "measurements"),
        ("table", "runs"),
        ("table", "fits"),
        ("table", "curves"),
        ("table", "run_lock"),
        ("table", "segment_effects"),
        ("view", "latest_fits"),
    ] {
        assert!(
            objects.contains(&(kind.to_string(), name.to_string())),
            "{kind} {name} missing from {objects:?}"
        );
    }
    let version: i64 = conn
        .query_row("PRAGMA user_version", [], |r| r.get(0))
        .unwrap();
    let files = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/migrations"))
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "sql")
        })
        .count();
    assert_eq!(version, files as i64);
    let mode: String = conn
        .query_row("PRAGMA journal_mode", [], |r| r.get(0))
        .unwrap();
    assert_eq!(mode, "wal");
}

/// A database pipewave opens commits without waiting for the disk (`synchronous = NORMAL`,
/// 1; SQLite's default is FULL, 2), which WAL keeps consistent through a power cut.
#[test]
fn the_database_commits_without_an_fsync_per_transaction() {
    let dir = tempfile::tempdir().unwrap();
    let db = pipewave::db::Database::open(dir.path().join("p.sqlite")).unwrap();
    let level: i64 = db
        .conn()
        .query_row("PRAGMA synchronous", [], |r| r.get(0))
        .unwrap();
    assert_eq!(level, 1);
}

/// Header and rows of a small valid segments file; bad cases append or replace lines.
const SEGS_HEAD: &str =
    "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,geometry_wkt,srid";
const SEGS_OK: &str =
    "N-1,CI,150,8,1900,,\nN-2,PVC,110,5.3,1800,\"LINESTRING (0 0, 10 0)\",27700\n";
const MEAS_HEAD: &str =
    "segment_id,frequency_hz,omega_rad_s,k_re_rad_per_m,attenuation_np_per_m,measured_on";
const MEAS_OK: &str = "N-1,100,,0.55,0.002,2024-05-01\n";

fn segs(bad_line: &str) -> Vec<u8> {
    format!("{SEGS_HEAD}\n{SEGS_OK}{bad_line}\n").into_bytes()
}

fn meas(bad_line: &str) -> Vec<u8> {
    format!("{MEAS_HEAD}\n{MEAS_OK}{bad_line}\n").into_bytes()
}

/// A bad input: the files (valid ones where not the point) and what stderr must name.
struct BadCase {
    what: &'static str,
    segments: Vec<u8>,
    measurements: Vec<u8>,
    /// `file:line[:col]: column NAME`, or `file:line:` for a problem with the whole header.
    location: &'static str,
    reason: &'static str,
}

fn bad_cases() -> Vec<BadCase> {
    let ok_s = || format!("{SEGS_HEAD}\n{SEGS_OK}").into_bytes();
    let ok_m = || format!("{MEAS_HEAD}\n{MEAS_OK}").into_bytes();
    let mut non_utf8 = format!("{SEGS_HEAD}\n{SEGS_OK}").into_bytes();
    non_utf8.extend_from_slice(b"N-3,CI,150,8,1900,,\nN-4,CI,150,8,19\xff0,,\n");
    vec![
        BadCase {
            what: "unknown material",
            segments: segs("N-3,BRASS,150,8,1900,,"),
            measurements: ok_m(),
            location: "segments.csv:4:2: column material:",
            reason: "unknown material 'BRASS'",
        },
        BadCase {
            what: "negative diameter",
            segments: segs("N-3,CI,-150,8,1900,,"),
            measurements: ok_m(),
            location: "segments.csv:4:3: column outer_diameter_mm:",
            reason: "greater than 0",
        },
        BadCase {
            what: "wall too thick for the thin-shell model (h/a > 0.25)",
            segments: segs("N-3,CI,100,20,1900,,"),
            measurements: ok_m(),
            location: "segments.csv:4:4: column wall_thickness_mm:",
            reason: "thin-shell",
        },
        BadCase {
            what: "wall thicker than the radius",
            segments: segs("N-3,CI,100,60,1900,,"),
            measurements: ok_m(),
            location: "segments.csv:4:4: column wall_thickness_mm:",
            reason: "less than half the outer diameter",
        },
        BadCase {
            what: "soil density out of range",
            segments: segs("N-3,CI,150,8,900,,"),
            measurements: ok_m(),
            location: "segments.csv:4:5: column soil_density_kg_m3:",
            reason: "1000 - 2600",
        },
        BadCase {
            what: "text in a number column",
            segments: segs("N-3,CI,150,8,heavy,,"),
            measurements: ok_m(),
            location: "segments.csv:4:5: column soil_density_kg_m3:",
            reason: "expected a number, found 'heavy'",
        },
        BadCase {
            what: "missing required header",
            segments: b"segment_id,material,outer_diameter_mm,wall_thickness_mm\nN-1,CI,150,8\n".to_vec(),
            measurements: ok_m(),
            location: "segments.csv:1: ",
            reason: "missing required column 'soil_density_kg_m3'",
        },
        BadCase {
            what: "duplicate header",
            segments: b"segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,Material\nN-1,CI,150,8,1900,CI\n".to_vec(),
            measurements: ok_m(),
            location: "segments.csv:1:6: column material:",
            reason: "duplicate column",
        },
        BadCase {
            what: "empty file",
            segments: b"".to_vec(),
            measurements: ok_m(),
            location: "segments.csv:1: ",
            reason: "the file is empty",
        },
        BadCase {
            what: "non-UTF-8 bytes",
            segments: non_utf8,
            measurements: ok_m(),
            location: "segments.csv:5:5: column soil_density_kg_m3:",
            reason: "UTF-8",
        },
        BadCase {
            what: "duplicate segment id",
            segments: segs("N-1,DI,150,8,1900,,"),
            measurements: ok_m(),
            location: "segments.csv:4:1: column segment_id:",
            reason: "duplicate segment_id 'N-1': it is also on line 2",
        },
        BadCase {
            what: "bad WKT",
            segments: segs("N-3,CI,150,8,1900,\"LINESTRING (1 2, 3)\",27700"),
            measurements: ok_m(),
            location: "segments.csv:4:6: column geometry_wkt:",
            reason: "two numbers",
        },
        BadCase {
            what: "geometry without srid",
            segments: segs("N-3,CI,150,8,1900,\"LINESTRING (1 2, 3 4)\","),
            measurements: ok_m(),
            location: "segments.csv:4:7: column srid:",
            reason: "EPSG",
        },
        BadCase {
            what: "measurement for an unknown segment",
            segments: ok_s(),
            measurements: meas("NOPE,100,,0.55,0.002,"),
            location: "measurements.csv:3:1: column segment_id:",
            reason: "segment 'NOPE' is not in the inventory",
        },
        BadCase {
            what: "both frequency columns",
            segments: ok_s(),
            measurements: meas("N-1,200,1256.6,1.1,0.004,"),
            location: "measurements.csv:3:3: column omega_rad_s:",
            reason: "not both",
        },
        BadCase {
            what: "neither frequency column",
            segments: ok_s(),
            measurements: meas("N-1,,,1.1,0.004,"),
            location: "measurements.csv:3:2: column frequency_hz:",
            reason: "frequency is missing",
        },
        BadCase {
            what: "negative attenuation",
            segments: ok_s(),
            measurements: meas("N-1,200,,1.1,-0.004,"),
            location: "measurements.csv:3:5: column attenuation_np_per_m:",
            reason: "0 or more",
        },
        BadCase {
            what: "same segment and frequency twice",
            segments: ok_s(),
            measurements: meas("N-1,,628.3185307179586,0.56,0.002,"),
            location: "measurements.csv:3:3: column omega_rad_s:",
            reason: "already has a measurement at this frequency on line 2",
        },
        BadCase {
            what: "impossible date",
            segments: ok_s(),
            measurements: meas("N-1,200,,1.1,0.004,2023-02-29"),
            location: "measurements.csv:3:6: column measured_on:",
            reason: "YYYY-MM-DD",
        },
    ]
}

fn assert_rejected(case: &BadCase, out: &Output, when: &str) {
    let stderr = text(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(2),
        "{} ({when}): {stderr}",
        case.what
    );
    let line = stderr
        .lines()
        .find(|l| l.contains(case.location))
        .unwrap_or_else(|| {
            panic!(
                "{} ({when}): no line with {:?} in\n{stderr}",
                case.what, case.location
            )
        });
    assert!(
        line.contains(case.reason),
        "{} ({when}): {line:?} should say {:?}",
        case.what,
        case.reason
    );
    assert!(
        stderr.contains("nothing was written"),
        "{} ({when}): {stderr}",
        case.what
    );
    assert_eq!(text(&out.stdout), "", "{} ({when})", case.what);
}

#[test]
fn each_kind_of_bad_row_rejects_the_whole_import_and_names_file_line_and_column() {
    for case in bad_cases() {
        // Into an empty database: nothing at all is imported, not even the valid rows.
        let s = Scratch::new();
        let sp = s.write("segments.csv", &case.segments);
        let mp = s.write("measurements.csv", &case.measurements);
        let out = s.import(Some(&sp), Some(&mp), &[]);
        assert_rejected(&case, &out, "empty database");
        assert_eq!(s.count("segments"), 0, "{}", case.what);
        assert_eq!(s.count("measurements"), 0, "{}", case.what);

        // Into a database holding data: it is left exactly as it was.
        let s = Scratch::new();
        s.import_fixtures();
        let before = s.snapshot();
        let sp = s.write("segments.csv", &case.segments);
        let mp = s.write("measurements.csv", &case.measurements);
        let out = s.import(Some(&sp), Some(&mp), &[]);
        assert_rejected(&case, &out, "database with data");
        assert_eq!(s.snapshot(), before, "{}", case.what);
    }
}

#[test]
fn skip_invalid_imports_the_valid_rows_and_reports_the_others() {
    let s = Scratch::new();
    let sp = s.write("segments.csv", &segs("N-3,CI,100,20,1900,,"));
    let mp = s.write(
        "measurements.csv",
        format!(
            "{MEAS_HEAD}\n{MEAS_OK}N-3,100,,0.6,0.003,\nNOPE,100,,0.6,0.003,\nN-2,100,,0.9,0.05,\n"
        )
        .as_bytes(),
    );
    let out = s.import(Some(&sp), Some(&mp), &["--skip-invalid"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("segments.csv:4:4: column wall_thickness_mm:"),
        "{stderr}"
    );
    assert!(
        stderr
            .contains("measurements.csv:3:1: column segment_id: segment 'N-3' cannot be imported"),
        "{stderr}"
    );
    assert!(
        stderr.contains("measurements.csv:4:1: column segment_id:"),
        "{stderr}"
    );
    assert!(stderr.contains("skipped 3 invalid rows"), "{stderr}");
    assert!(
        text(&out.stdout).contains("segments 2 new"),
        "{}",
        text(&out.stdout)
    );
    let ids: Vec<String> = s.hashes().into_keys().collect();
    assert_eq!(ids, ["N-1", "N-2"]);
    assert_eq!(s.count("measurements"), 2);
}

#[test]
fn unknown_columns_are_ignored_with_one_note_and_rejected_with_strict() {
    let s = Scratch::new();
    let sp = s.write(
        "segments.csv",
        format!("{SEGS_HEAD},colour,Street\nN-1,CI,150,8,1900,,,red,High St\n").as_bytes(),
    );
    let out = s.import(Some(&sp), None, &[]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    let notes: Vec<&str> = stderr.lines().filter(|l| l.starts_with("note:")).collect();
    assert_eq!(
        notes,
        [format!(
            "note: {}: ignored 2 columns pipewave does not use: colour, Street (--map \
             COLUMN=FIELD uses one; --strict rejects them)",
            sp.display()
        )]
    );
    assert_eq!(s.count("segments"), 1);
    // --strict: the whole file is rejected, each unknown column named where it is.
    let s = Scratch::new();
    let sp = s.write(
        "segments.csv",
        format!("{SEGS_HEAD},colour\nN-1,CI,150,8,1900,,,red\n").as_bytes(),
    );
    let out = s.import(Some(&sp), None, &["--strict"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    let line = stderr
        .lines()
        .find(|l| l.contains("segments.csv:1:8: column colour:"))
        .unwrap_or_else(|| panic!("{stderr}"));
    assert!(
        line.contains("allowed columns are: segment_id, material"),
        "{line}"
    );
    assert_eq!(s.count("segments"), 0);
}

#[test]
fn skip_invalid_does_not_import_a_file_whose_header_is_bad() {
    let s = Scratch::new();
    let sp = s.write(
        "segments.csv",
        format!("{SEGS_HEAD},colour\nN-1,CI,150,8,1900,,,red\n").as_bytes(),
    );
    let out = s.import(Some(&sp), None, &["--skip-invalid", "--strict"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("segments.csv:1:8: column colour:"));
    assert!(
        text(&out.stderr).contains("--skip-invalid does not help"),
        "{}",
        text(&out.stderr)
    );
    assert_eq!(s.count("segments"), 0);
}

#[test]
fn reimporting_identical_files_changes_nothing() {
    let s = Scratch::new();
    s.import_fixtures();
    let before = s.snapshot();
    let ids_before: Vec<i64> = s
        .conn()
        .prepare("SELECT id FROM measurements ORDER BY id")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let out = s.import_fixtures();
    assert_eq!(
        text(&out.stdout).trim(),
        "imported: segments 0 new, 0 updated, 4 unchanged; measurements 0 written for 0 segments; \
         fit inputs changed for 0 segments; campaign spring-2024: 0 rows added, 0 updated, 5 kept; \
         campaign unnamed: 0 rows added, 0 updated, 3 kept"
    );
    // Same values, same import times, same hashes, and the measurement rows not rewritten.
    assert_eq!(s.snapshot(), before);
    let ids_after: Vec<i64> = s
        .conn()
        .prepare("SELECT id FROM measurements ORDER BY id")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(ids_after, ids_before);
}

#[test]
fn changing_one_measurement_changes_only_that_segments_hash() {
    let s = Scratch::new();
    s.import_fixtures();
    let before = s.hashes();
    let original = std::fs::read_to_string(fixture("measurements.csv")).unwrap();
    let changed = original.replace("CI-0001,100,,0.5625,", "CI-0001,100,,0.5626,");
    assert_ne!(changed, original, "fixture line to change not found");
    // Measurements alone: the segments are already in the database.
    let mp = s.write("measurements.csv", changed.as_bytes());
    let out = s.import(None, Some(&mp), &[]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains(
            "measurements 1 written for 1 segment; fit inputs changed for 1 segment; \
                       campaign spring-2024: 0 rows added, 1 updated, 4 kept"
        ),
        "{}",
        text(&out.stdout)
    );
    let after = s.hashes();
    for (id, h) in &before {
        if id == "CI-0001" {
            assert_ne!(&after[id], h, "{id}");
        } else {
            assert_eq!(&after[id], h, "{id}");
        }
    }
    assert_eq!(s.count("measurements"), data_lines("measurements.csv"));
}

#[test]
fn a_changed_segment_row_is_updated_and_only_its_hash_changes() {
    let s = Scratch::new();
    s.import_fixtures();
    let before = s.hashes();
    let original = std::fs::read_to_string(fixture("segments.csv")).unwrap();
    let changed = original.replace("DI-0002,di,170,6,", "DI-0002,di,170,6.5,");
    assert_ne!(changed, original);
    let sp = s.write("segments.csv", changed.as_bytes());
    let out = s.import(Some(&sp), None, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("segments 0 new, 1 updated, 3 unchanged"),
        "{}",
        text(&out.stdout)
    );
    let wall: f64 = s
        .conn()
        .query_row(
            "SELECT wall_thickness_mm FROM segments WHERE segment_id = 'DI-0002'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(wall, 6.5);
    let after = s.hashes();
    for (id, h) in &before {
        assert_eq!(&after[id] != h, id == "DI-0002", "{id}");
    }
    // Its measurements were kept: the file had none for it.
    assert_eq!(s.count("measurements"), data_lines("measurements.csv"));
}

#[test]
fn measurements_alone_into_an_empty_database_are_rejected() {
    let s = Scratch::new();
    let out = s.import(None, Some(&fixture("measurements.csv")), &[]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains(
            "measurements.csv:2:1: column segment_id: segment 'CI-0001' is not in the inventory"
        ),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn a_corrupt_database_file_is_refused_and_left_alone() {
    let s = Scratch::new();
    // Deterministic "random" bytes (an LCG), long enough to look like a database page.
    let mut x: u64 = 0x2545_f491_4f6c_dd1d;
    let junk: Vec<u8> = (0..8192)
        .map(|_| {
            x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            x.to_be_bytes()[0]
        })
        .collect();
    std::fs::write(&s.db, &junk).unwrap();
    let out = s.import_raw(&fixture("segments.csv"));
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("is not a pipewave database"), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
    assert_eq!(std::fs::read(&s.db).unwrap(), junk);
}

impl Scratch {
    fn import_raw(&self, segments: &Path) -> Output {
        self.import(Some(segments), None, &[])
    }
}

#[test]
fn a_database_from_a_newer_pipewave_is_refused() {
    let s = Scratch::new();
    s.import_fixtures();
    s.conn().pragma_update(None, "user_version", 99).unwrap();
    let out = s.import_raw(&fixture("segments.csv"));
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("newer pipewave (schema version 99"),
        "{stderr}"
    );
}

#[test]
fn a_missing_input_file_is_reported_and_creates_no_database() {
    let s = Scratch::new();
    let out = s.import_raw(&s.dir.path().join("nope.csv"));
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("cannot read"),
        "{}",
        text(&out.stderr)
    );
    assert!(!s.db.exists());
}

#[test]
fn a_directory_as_database_is_explained() {
    let s = Scratch::new();
    let out = pipewave(&[
        "import",
        "--db",
        s.dir.path().to_str().unwrap(),
        "--segments",
        fixture("segments.csv").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("is a directory"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn import_needs_at_least_one_file() {
    let s = Scratch::new();
    let out = pipewave(&["import", "--db", s.db()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("--segments"),
        "{}",
        text(&out.stderr)
    );
}

// --- GIS layers --------------------------------------------------------------------------------

fn gis(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/gis")
        .join(name)
}

/// The `--map` pairs of the utility's field names (tests/data/gis/README.md).
const UTILITY_MAP: [&str; 11] = [
    "segment_id=ASSET_ID",
    "outer_diameter_mm=DIAM_MM",
    "wall_thickness_mm=WALL_MM",
    "soil_density_kg_m3=SOIL_RHO",
    "pipe_youngs_modulus_pa=E_PIPE",
    "pipe_poisson=NU_PIPE",
    "pipe_density_kg_m3=RHO_PIPE",
    "pipe_loss_factor=ETA_PIPE",
    "length_m=LENGTH",
    "soil_type=SOIL",
    "install_year=YEAR_LAID",
];

fn map_args(extra: &[&'static str]) -> Vec<&'static str> {
    let mut v: Vec<&str> = UTILITY_MAP.iter().flat_map(|m| ["--map", *m]).collect();
    v.extend(extra);
    v
}

/// Every stored segment, less its import time.
fn stored(db: &Path) -> Vec<pipewave::db::SegmentRecord> {
    let d = pipewave::db::Database::open(db).unwrap();
    let mut v = pipewave::db::load_segments(d.conn(), None).unwrap();
    for s in &mut v {
        s.imported_at.clear();
    }
    v
}

/// The sample network's inventory, imported from its CSV.
fn sample_segments() -> Vec<pipewave::db::SegmentRecord> {
    let s = Scratch::new();
    let csv = Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_network/segments.csv");
    let out = s.import(Some(&csv), None, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let v = stored(&s.db);
    assert_eq!(v.len(), 202);
    v
}

/// Import a utility layer with the map; it must give exactly `want`, with one note naming the
/// two ignored fields.
fn check_utility_layer(layer: &Path, extra: &[&'static str], want: &[pipewave::db::SegmentRecord]) {
    let s = Scratch::new();
    let out = s.import(Some(layer), None, &map_args(extra));
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{}: {stderr}", layer.display());
    let notes: Vec<&str> = stderr.lines().filter(|l| l.starts_with("note:")).collect();
    assert_eq!(notes.len(), 1, "{stderr}");
    // GeoJSON properties come in alphabetical order.
    assert!(
        notes[0].contains("ignored 2 fields pipewave does not use: STREET, OWNER (")
            || notes[0].contains("ignored 2 fields pipewave does not use: OWNER, STREET ("),
        "{}",
        notes[0]
    );
    let got = stored(&s.db);
    assert_eq!(got.len(), want.len(), "{}", layer.display());
    for (g, w) in got.iter().zip(want) {
        assert_eq!(g, w, "{}: segment {}", layer.display(), w.segment_id);
    }
}

#[test]
fn a_utility_geopackage_shapefile_and_csv_import_to_exactly_the_sample_inventory() {
    let want = sample_segments();
    // Committed fixtures, made with GDAL's ogr2ogr from utility_pipes.csv (README beside them):
    // other field names, alias spellings (Cast Iron, uPVC, PE80, PE100, ...), two extra fields.
    check_utility_layer(&gis("pipes.shp"), &[], &want);
    check_utility_layer(&gis("pipes.gpkg"), &["--layer", "water_mains"], &want);
    // The same lines written as one-part MultiLineStrings.
    check_utility_layer(&gis("pipes.gpkg"), &["--layer", "WATER_MAINS_MULTI"], &want);
}

#[test]
#[ignore = "needs gdal-bin"]
fn layers_gdal_writes_afresh_import_to_exactly_the_sample_inventory() {
    let want = sample_segments();
    let v = Command::new("ogr2ogr")
        .arg("--version")
        .output()
        .expect("GDAL's ogr2ogr (apt-get install gdal-bin)");
    assert!(v.status.success());
    let dir = tempfile::tempdir().unwrap();
    for (driver, file, nlt) in [
        ("GPKG", "fresh.gpkg", "LINESTRING"),
        ("ESRI Shapefile", "fresh.shp", "MULTILINESTRING"),
        ("GeoJSON", "fresh.geojson", "LINESTRING"),
    ] {
        let out = dir.path().join(file);
        let o = Command::new("ogr2ogr")
            .args(["-f", driver])
            .arg(&out)
            .arg(gis("utility_pipes.csv"))
            .args([
                "-oo",
                "GEOM_POSSIBLE_NAMES=WKT",
                "-oo",
                "KEEP_GEOM_COLUMNS=NO",
                "-oo",
                "AUTODETECT_TYPE=YES",
                "-a_srs",
                "EPSG:27700",
                "-nlt",
                nlt,
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o.stderr));
        check_utility_layer(&out, &[], &want);
    }
}

#[test]
fn layer_problems_name_the_layer_the_feature_and_the_field() {
    // Several layers and no --layer: the choice is asked for.
    let s = Scratch::new();
    let out = s.import(Some(&gis("pipes.gpkg")), None, &map_args(&[]));
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains(
            "has 2 feature layers (water_mains, water_mains_multi); choose one with --layer NAME"
        ),
        "{stderr}"
    );
    assert_eq!(s.count("segments"), 0);

    // A GeoJSON with a bad diameter, an unknown material, a two-part line.
    let geojson = r#"{"type":"FeatureCollection","name":"mains","crs":{"type":"name","properties":{"name":"urn:ogc:def:crs:EPSG::27700"}},"features":[
 {"type":"Feature","id":7,"properties":{"ASSET_ID":"A1","MATERIAL":"Cast Iron","DIAM_MM":1e308,"WALL_MM":8,"SOIL_RHO":1900},"geometry":{"type":"LineString","coordinates":[[0,0],[10,0]]}},
 {"type":"Feature","id":8,"properties":{"ASSET_ID":"A2","MATERIAL":"Brass","DIAM_MM":150,"WALL_MM":8,"SOIL_RHO":1900},"geometry":null},
 {"type":"Feature","id":9,"properties":{"ASSET_ID":"A3","MATERIAL":"PE100","DIAM_MM":125,"WALL_MM":11.4,"SOIL_RHO":1900},"geometry":{"type":"MultiLineString","coordinates":[[[0,0],[1,0]],[[2,0],[3,0]]]}},
 {"type":"Feature","id":10,"properties":{"ASSET_ID":"A4","MATERIAL":"PVC-U","DIAM_MM":110,"WALL_MM":5.3,"SOIL_RHO":1800},"geometry":{"type":"MultiLineString","coordinates":[[[0,0],[1,0]]]}}
]}"#;
    let s = Scratch::new();
    let p = s.write("mains.geojson", geojson.as_bytes());
    let out = s.import(Some(&p), None, &map_args(&[]));
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    let f = p.display().to_string();
    for want in [
        format!("{f}: layer mains: feature 7: field DIAM_MM (outer_diameter_mm): an outer diameter of 1e308 mm with a wall of 8 mm is outside what the model takes: its mean radius (D - h)/2 = 5e307 mm must be 5 - 1500 mm"),
        format!("{f}: layer mains: feature 8: field MATERIAL: unknown material 'Brass'"),
        format!("{f}: layer mains: feature 9: field geometry: the MultiLineString has 2 parts"),
    ] {
        assert!(stderr.lines().any(|l| l.starts_with(&want)), "no {want:?} in\n{stderr}");
    }
    assert!(stderr.len() < 2000, "short numbers: {stderr}");
    // With --skip-invalid the two good rows go in, the one-part MultiLineString with geometry.
    let out = s.import(Some(&p), None, &map_args(&["--skip-invalid"]));
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let got = stored(&s.db);
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(got[0].segment_id, "A4");
    assert_eq!(got[0].material, pipewave::physics::Material::Pvc);
    assert_eq!(
        got[0].geometry_wkt.as_deref(),
        Some("LINESTRING (0 0, 1 0)")
    );
    assert_eq!(got[0].srid, Some(27700));
}

// --- risk_weight and soil_class_override -------------------------------------------------------

/// `risk_weight` must be a finite number ≥ 0; each bad cell is named by file, line and column
/// (CSV) or layer, feature and field (GIS), and nothing is written.
#[test]
fn a_bad_risk_weight_is_named_by_file_line_and_column() {
    let head = "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,risk_weight,soil_class_override";
    for (cell, reason) in [
        ("-1", "must be 0 or more"),
        ("inf", "is not a finite number"),
        ("high", "expected a number, found 'high'"),
    ] {
        let s = Scratch::new();
        let p = s.write(
            "segments.csv",
            format!("{head}\nN-1,CI,150,8,1900,2,\nN-2,PVC,110,5.3,1800,{cell},clay\n").as_bytes(),
        );
        let out = s.import(Some(&p), None, &[]);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{cell}: {stderr}");
        let line = stderr
            .lines()
            .find(|l| l.contains("segments.csv:3:6: column risk_weight:"))
            .unwrap_or_else(|| panic!("{cell}: {stderr}"));
        assert!(line.contains(reason), "{cell}: {line}");
        assert!(stderr.contains("nothing was written"), "{stderr}");
    }

    // A GIS layer: the field mapped to risk_weight is named with the feature.
    let geojson = r#"{"type":"FeatureCollection","name":"mains","crs":{"type":"name","properties":{"name":"urn:ogc:def:crs:EPSG::27700"}},"features":[
 {"type":"Feature","id":3,"properties":{"ASSET_ID":"A1","MATERIAL":"Cast Iron","DIAM_MM":150,"WALL_MM":8,"SOIL_RHO":1900,"RISK":-0.5,"CHECKED":"clay"},"geometry":{"type":"LineString","coordinates":[[0,0],[10,0]]}},
 {"type":"Feature","id":4,"properties":{"ASSET_ID":"A2","MATERIAL":"PVC-U","DIAM_MM":110,"WALL_MM":5.3,"SOIL_RHO":1800,"RISK":4,"CHECKED":"sand"},"geometry":{"type":"LineString","coordinates":[[10,0],[20,0]]}}
]}"#;
    let s = Scratch::new();
    let p = s.write("mains.geojson", geojson.as_bytes());
    let mut args = map_args(&[]);
    args.extend([
        "--map",
        "risk_weight=RISK",
        "--map",
        "soil_class_override=CHECKED",
    ]);
    let out = s.import(Some(&p), None, &args);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    let want = format!(
        "{}: layer mains: feature 3: field RISK (risk_weight): must be 0 or more",
        p.display()
    );
    assert!(
        stderr.lines().any(|l| l.starts_with(&want)),
        "no {want:?} in\n{stderr}"
    );
    // The good feature goes in with --skip-invalid, its weight and override stored.
    args.push("--skip-invalid");
    let out = s.import(Some(&p), None, &args);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let got = stored(&s.db);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].risk_weight, Some(4.0));
    assert_eq!(got[0].soil_class_override.as_deref(), Some("sand"));
}

/// Both columns are stored; a later file without them keeps them, a blank cell clears them.
/// Like every stored column they are inputs of staleness (src/db/staleness.rs): setting them
/// changes the segment's inputs hash, and a file without them leaves it as it was.
#[test]
fn risk_weight_and_class_override_are_stored_kept_and_cleared() {
    let s = Scratch::new();
    let base = "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3";
    let p = s.write(
        "plain.csv",
        format!("{base}\nN-1,CI,150,8,1900\n").as_bytes(),
    );
    let out = s.import(Some(&p), None, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let hash = s.hashes()["N-1"].clone();
    let p = s.write(
        "with.csv",
        format!("{base},risk_weight,soil_class_override\nN-1,CI,150,8,1900,0,clay\n").as_bytes(),
    );
    let out = s.import(Some(&p), None, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let got = stored(&s.db);
    assert_eq!(got[0].risk_weight, Some(0.0));
    assert_eq!(got[0].soil_class_override.as_deref(), Some("clay"));
    assert_ne!(s.hashes()["N-1"], hash);
    let hash = s.hashes()["N-1"].clone();
    // A file without the columns says nothing about them.
    let p = s.write(
        "plain2.csv",
        format!("{base}\nN-1,CI,150,8,1900\n").as_bytes(),
    );
    let out = s.import(Some(&p), None, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let got = stored(&s.db);
    assert_eq!(got[0].risk_weight, Some(0.0));
    assert_eq!(got[0].soil_class_override.as_deref(), Some("clay"));
    assert_eq!(s.hashes()["N-1"], hash);
    // Blank cells clear them.
    let p = s.write(
        "blank.csv",
        format!("{base},risk_weight,soil_class_override\nN-1,CI,150,8,1900,,\n").as_bytes(),
    );
    let out = s.import(Some(&p), None, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let got = stored(&s.db);
    assert_eq!(got[0].risk_weight, None);
    assert_eq!(got[0].soil_class_override, None);
}
