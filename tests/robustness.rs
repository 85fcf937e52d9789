//! Broken and hostile inputs, run as a user would: the real binary on files made here. Each test
//! is one defect found by trying the program as an attacker and a careless user would; each
//! checks the program names the problem (file, line, column or segment), exits with the
//! contract's code, never panics (101) or aborts (134), and replaces nothing it should not.

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

    /// `pipewave import --db DB --segments SEGMENTS --measurements MEASUREMENTS`.
    fn import(&self, segments: &str, measurements: &str) -> Output {
        self.import_segments(segments, &["--measurements", measurements])
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

const SEG_HEADER: &str =
    "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3";

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
            let mut body = if bom {
                "\u{feff}".to_string()
            } else {
                String::new()
            };
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
                err.contains(
                    "segments.csv:6:3: column outer_diameter_mm: expected a number, found 'x'"
                ),
                "{what}: {err}"
            );
            assert!(
                err.contains(
                    "segments.csv:7:4: column wall_thickness_mm: expected a number, found 'y'"
                ),
                "{what}: {err}"
            );
            assert_eq!(
                err.lines().filter(|l| l.contains("segments.csv:")).count(),
                2,
                "{what}: {err}"
            );
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
        conn.execute_batch(&format!("DROP TRIGGER \"{t}\""))
            .unwrap();
    }
    conn.execute_batch(edit).unwrap();
    p.to_str().unwrap().to_string()
}

const UTILITY_MAP: [&str; 22] = [
    "--map",
    "segment_id=ASSET_ID",
    "--map",
    "outer_diameter_mm=DIAM_MM",
    "--map",
    "wall_thickness_mm=WALL_MM",
    "--map",
    "soil_density_kg_m3=SOIL_RHO",
    "--map",
    "pipe_youngs_modulus_pa=E_PIPE",
    "--map",
    "pipe_poisson=NU_PIPE",
    "--map",
    "pipe_density_kg_m3=RHO_PIPE",
    "--map",
    "pipe_loss_factor=ETA_PIPE",
    "--map",
    "length_m=LENGTH",
    "--map",
    "soil_type=SOIL",
    "--map",
    "install_year=YEAR_LAID",
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
    let segs = s.write(
        "segments.csv",
        format!("{SEG_HEADER}\nA,DI,170,6,1900\n").as_bytes(),
    );
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
    let out = s.import(&segs, &meas);
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
        assert!(
            err.contains(&format!("measurements.csv:{line}:{col}")),
            "line {line}: {err}"
        );
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
    let bare = s.write(
        "bare.csv",
        format!("{SEG_HEADER}\nA,DI,170,6,1900\n").as_bytes(),
    );
    let out = s.import_segments(&bare, &[]);
    assert_code(&out, 0);
    assert!(
        text(&out.stdout).contains("0 updated, 1 unchanged"),
        "{}",
        text(&out.stdout)
    );
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
    assert!(
        text(&out.stdout).contains("1 updated"),
        "{}",
        text(&out.stdout)
    );
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
    let listed: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("segments.csv:"))
        .collect();
    assert_eq!(
        listed.len(),
        1000,
        "{}",
        &err[err.len().saturating_sub(500)..]
    );
    assert!(listed[0].starts_with(&format!("{f}:2:3:")), "{}", listed[0]);
    assert!(
        listed[999].starts_with(&format!("{f}:1001:3:")),
        "{}",
        listed[999]
    );
    assert!(
        err.contains("and 1500 more problems"),
        "{}",
        &err[err.len() - 400..]
    );
    assert!(
        err.contains("2500 problems found"),
        "{}",
        &err[err.len() - 400..]
    );
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
    let geographic = PROJECTED_GEOJSON.replace(
        "[441800, 111900], [441920, 111900]",
        "[-1.5, 51.2], [-1.49, 51.2]",
    );
    let f = s.write("pipes.geojson", format!("\u{feff}{geographic}").as_bytes());
    let out = s.import_segments(&f, &[]);
    assert_code(&out, 0);
    let f = s.write(
        "empty.geojson",
        br#"{"type": "FeatureCollection", "features": []}"#,
    );
    let out = s.import_segments(&f, &[]);
    assert_code(&out, 2);
    let err = text(&out.stderr);
    assert!(err.contains("no features"), "{err}");
    assert!(!err.contains("missing required"), "{err}");
}

// --- 3 and 13. WAV files ------------------------------------------------------------------------

mod wav {
    use super::*;
    use pipewave::physics::{ContactMode, Fluid, Material, Model, Soil, System};
    use pipewave::synth::recordings::{hydrant_test, write_wav, RecordingSpec, WavFormat};

    /// Three channels of a 10 s hydrant test on a ductile-iron pipe, sensors at 0, -25, +40 m.
    pub fn recording() -> Vec<Vec<f64>> {
        let sys = System::new(
            Fluid::water(),
            pipewave::synth::pipe_of(
                Material::DuctileIron,
                &pipewave::synth::sizes(Material::DuctileIron)[1],
            ),
            Soil::new(5e7, 0.3, 1900.0, 0.0).unwrap(),
            0.5,
            Model::Full,
            ContactMode::Reciprocal,
        )
        .unwrap();
        let spec = RecordingSpec {
            sample_rate: 8000,
            seconds: 10.0,
            positions_m: vec![0.0, -25.0, 40.0],
            noise_fraction: 0.3,
            seed: 7,
        };
        hydrant_test(&sys, &spec).unwrap().channels
    }

    pub fn write(dir: &Path, name: &str, channels: &[&[f64]], format: WavFormat) {
        let gain = pipewave::synth::recordings::headroom_gain(
            &channels.iter().map(|c| c.to_vec()).collect::<Vec<_>>(),
        );
        write_wav(&dir.join(name), 8000, channels, format, gain).unwrap();
    }

    /// The bytes of a WAV file: PCM or float, its header's data length as given.
    pub fn bytes(rate: u32, bits: u16, float: bool, claimed: u32, data: &[u8]) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend(b"RIFF");
        b.extend(claimed.saturating_add(36).to_le_bytes());
        b.extend(b"WAVEfmt ");
        b.extend(16u32.to_le_bytes());
        b.extend((if float { 3u16 } else { 1u16 }).to_le_bytes());
        b.extend(1u16.to_le_bytes());
        b.extend(rate.to_le_bytes());
        let block = u32::from(bits / 8);
        b.extend((rate * block).to_le_bytes());
        b.extend((block as u16).to_le_bytes());
        b.extend(bits.to_le_bytes());
        b.extend(b"data");
        b.extend(claimed.to_le_bytes());
        b.extend(data);
        b
    }

    /// `wavenumbers` on `layout` in `dir`: its output and the measurements path.
    pub fn run(dir: &Path, layout: &str) -> (Output, PathBuf) {
        std::fs::write(dir.join("layout.csv"), layout).unwrap();
        let out = dir.join("m.csv");
        let o = pipewave(&[
            "wavenumbers",
            "--layout",
            dir.join("layout.csv").to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        (o, out)
    }

    pub const GOOD: &str = "segment_id,file,channel,position_m\n\
        GOOD,good.wav,0,0\nGOOD,good.wav,1,-25\nGOOD,good.wav,2,40\n";
}

#[test]
fn a_wav_header_overstating_its_length_fails_only_its_own_segment() {
    let dir = tempfile::tempdir().unwrap();
    let rec = wav::recording();
    let ch: Vec<&[f64]> = rec.iter().map(Vec::as_slice).collect();
    wav::write(
        dir.path(),
        "good.wav",
        &ch,
        pipewave::synth::recordings::WavFormat::Pcm16,
    );
    // 8-bit mono files whose headers claim 4 GB of samples, holding 4000.
    let liar = wav::bytes(8000, 8, false, 0xFFFF_FFF0, &[128u8; 4000]);
    std::fs::write(dir.path().join("bad1.wav"), &liar).unwrap();
    std::fs::write(dir.path().join("bad2.wav"), &liar).unwrap();
    let layout = format!("{}BAD,bad1.wav,0,0\nBAD,bad2.wav,0,20\n", wav::GOOD);
    let (out, m) = wav::run(dir.path(), &layout);
    assert_code(&out, 1);
    let err = text(&out.stderr);
    assert!(err.contains("segment BAD"), "{err}");
    assert!(!err.contains("segment GOOD"), "{err}");
    let rows = std::fs::read_to_string(m).unwrap();
    assert!(
        rows.lines().filter(|l| l.starts_with("\"GOOD\",")).count() >= 3,
        "{rows}"
    );
    assert!(!rows.contains("\"BAD\""), "{rows}");
}

#[test]
fn a_wav_at_rate_0_nan_samples_and_files_of_different_lengths_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let rec = wav::recording();
    // Rate 0.
    let zero = wav::bytes(0, 16, false, 16_000, &[0u8; 16_000]);
    std::fs::write(dir.path().join("zero1.wav"), &zero).unwrap();
    std::fs::write(dir.path().join("zero2.wav"), &zero).unwrap();
    let (out, _) = wav::run(
        dir.path(),
        "segment_id,file,channel,position_m\nZ,zero1.wav,0,0\nZ,zero2.wav,0,20\n",
    );
    assert_code(&out, 1);
    let err = text(&out.stderr);
    assert!(err.contains("sample rate of 0 Hz"), "{err}");
    assert!(!err.contains("inf"), "{err}");

    // NaN samples in a float file.
    let mut nan = rec.clone();
    for x in &mut nan[1][20_000..20_100] {
        *x = f64::NAN;
    }
    let ch: Vec<&[f64]> = nan.iter().map(Vec::as_slice).collect();
    wav::write(
        dir.path(),
        "good.wav",
        &ch,
        pipewave::synth::recordings::WavFormat::Float32,
    );
    let (out, _) = wav::run(dir.path(), wav::GOOD);
    assert_code(&out, 1);
    let err = text(&out.stderr);
    assert!(
        err.contains("channel 1 holds samples that are not numbers"),
        "{err}"
    );
    assert!(err.contains("the first at 2.50 s"), "{err}");

    // One file 10 s long, the two others 8 s.
    let f = pipewave::synth::recordings::WavFormat::Pcm16;
    wav::write(dir.path(), "a.wav", &[&rec[0][..]], f);
    wav::write(dir.path(), "b.wav", &[&rec[1][..64_000]], f);
    wav::write(dir.path(), "c.wav", &[&rec[2][..64_000]], f);
    let (out, _) = wav::run(
        dir.path(),
        "segment_id,file,channel,position_m\nL,a.wav,0,0\nL,b.wav,0,-25\nL,c.wav,0,40\n",
    );
    assert_code(&out, 1);
    let err = text(&out.stderr);
    assert!(
        err.contains("differ in length: this one is 8.00 s, a.wav (line 2) is 10.0 s"),
        "{err}"
    );
}

// --- 4. synth --recording-seconds -----------------------------------------------------------------

#[test]
fn synth_recording_seconds_must_be_a_length_wavenumbers_can_use() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("net");
    for bad in ["inf", "1e9", "5", "NaN", "0"] {
        let out = pipewave(&[
            "synth",
            "--out",
            out_dir.to_str().unwrap(),
            "--segments",
            "2",
            "--recordings",
            "WM10001",
            "--recordings-only",
            "--recording-seconds",
            bad,
        ]);
        assert_code(&out, 2);
        let err = text(&out.stderr);
        assert!(err.contains("--recording-seconds"), "{bad}: {err}");
        assert!(err.contains("needs at least 6 s"), "{bad}: {err}");
        assert!(!out_dir.join("recordings").exists(), "{bad}");
    }
}

// --- 5. export and audit --out on special files ------------------------------------------------

/// A new database with the repository's `segments` and `measurements` files imported.
fn imported_from(segments: &str, measurements: &str) -> Scratch {
    let s = Scratch::new();
    let (f, m) = (manifest(segments), manifest(measurements));
    assert_code(&s.import(f.to_str().unwrap(), m.to_str().unwrap()), 0);
    s
}

/// A database with the four fixture segments imported.
fn imported() -> Scratch {
    imported_from(
        "tests/data/import/segments.csv",
        "tests/data/import/measurements.csv",
    )
}

#[test]
fn export_and_audit_write_through_a_symlink_and_into_dev_null_without_replacing_them() {
    use std::os::unix::fs::FileTypeExt;
    let s = imported();
    let target = s.path("real.csv");
    std::fs::write(&target, "old").unwrap();
    let link = s.path("link.csv");
    std::os::unix::fs::symlink("real.csv", &link).unwrap();
    let out = pipewave(&[
        "export",
        "--db",
        s.db(),
        "--format",
        "csv",
        "--out",
        link.to_str().unwrap(),
    ]);
    assert_code(&out, 0);
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(std::fs::read_to_string(&target)
        .unwrap()
        .starts_with("\"segment_id\","));
    // The audit report through a link to a file that does not exist yet: created there.
    let link2 = s.path("report-link.html");
    std::os::unix::fs::symlink("report.html", &link2).unwrap();
    assert_code(
        &pipewave(&["audit", "--db", s.db(), "--out", link2.to_str().unwrap()]),
        0,
    );
    assert!(std::fs::symlink_metadata(&link2)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(std::fs::read_to_string(s.path("report.html"))
        .unwrap()
        .contains("<html"));
    for format in ["csv", "geojson", "gpkg"] {
        let out = pipewave(&[
            "export",
            "--db",
            s.db(),
            "--format",
            format,
            "--out",
            "/dev/null",
        ]);
        assert_code(&out, 0);
        let m = std::fs::symlink_metadata("/dev/null").unwrap();
        assert!(
            m.file_type().is_char_device(),
            "{format}: /dev/null replaced"
        );
    }
    assert_code(
        &pipewave(&["audit", "--db", s.db(), "--out", "/dev/null"]),
        0,
    );
    assert!(std::fs::symlink_metadata("/dev/null")
        .unwrap()
        .file_type()
        .is_char_device());
}

#[test]
fn export_into_a_fifo_writes_into_it_and_keeps_it() {
    use std::os::unix::fs::FileTypeExt;
    use std::os::unix::fs::OpenOptionsExt;
    let s = imported();
    let fifo = s.path("pipe.csv");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid path for the call.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    // The reader: opened without waiting for a writer, it drains the FIFO until the export
    // has ended and nothing more comes.
    let reader = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(&fifo)
        .unwrap();
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let done2 = done.clone();
    let drain = std::thread::spawn(move || {
        let mut reader = reader;
        let mut got = Vec::new();
        let mut buf = [0u8; 65536];
        loop {
            match std::io::Read::read(&mut reader, &mut buf) {
                Ok(n) if n > 0 => got.extend_from_slice(&buf[..n]),
                _ if done2.load(std::sync::atomic::Ordering::SeqCst) => break got,
                _ => std::thread::sleep(std::time::Duration::from_millis(5)),
            }
        }
    });
    let mut child = Command::new(env!("CARGO_BIN_EXE_pipewave"))
        .args([
            "export",
            "--db",
            s.db(),
            "--format",
            "csv",
            "--out",
            fifo.to_str().unwrap(),
        ])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break Some(st);
        }
        if start.elapsed().as_secs() > 60 {
            child.kill().unwrap();
            break None;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    std::thread::sleep(std::time::Duration::from_millis(50));
    done.store(true, std::sync::atomic::Ordering::SeqCst);
    let got = drain.join().unwrap();
    let status = status.expect("the export into a FIFO hung");
    assert!(status.success(), "{status:?}");
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());
    let got = text(&got);
    assert!(got.starts_with("\"segment_id\","), "{got}");
    assert_eq!(got.lines().count(), 5, "{got}");
}

// --- 6. a damaged database is not written to --------------------------------------------------

#[test]
fn a_damaged_database_is_refused_by_calibrate_and_left_as_it_is() {
    let s = imported();
    // Damage the b-tree page of the zone fits (a table calibrate of an unzoned network does not
    // read): 64 bytes of its header overwritten.
    let (page_size, root): (i64, i64) = {
        let c = s.conn();
        (
            c.query_row("PRAGMA page_size", [], |r| r.get(0)).unwrap(),
            c.query_row(
                "SELECT rootpage FROM sqlite_master WHERE name = 'zone_fits'",
                [],
                |r| r.get(0),
            )
            .unwrap(),
        )
    };
    let mut bytes = std::fs::read(&s.db).unwrap();
    let at = ((root - 1) * page_size) as usize;
    bytes[at..at + 64].fill(0xA5);
    std::fs::write(&s.db, &bytes).unwrap();
    let out = pipewave(&["calibrate", "--db", s.db(), "--force", "--jobs", "1"]);
    assert_code(&out, 2);
    let err = text(&out.stderr);
    assert!(err.contains("is damaged"), "{err}");
    assert!(err.contains("quick_check"), "{err}");
    assert_eq!(
        std::fs::read(&s.db).unwrap(),
        bytes,
        "the damaged file was written to"
    );
}

// --- 7 and 13. the run lock ---------------------------------------------------------------------

#[test]
fn a_stale_lock_whose_pid_was_reused_is_taken_over() {
    let s = imported();
    // A live process, started after the lock was taken: it reused the pid of a killed run.
    let mut sleeper = Command::new("sleep").arg("30").spawn().unwrap();
    s.conn()
        .execute(
            "INSERT INTO run_lock (id, pid, started_at) VALUES (1, ?1, '2020-01-01T00:00:00Z')",
            [sleeper.id()],
        )
        .unwrap();
    let out = pipewave(&["calibrate", "--db", s.db(), "--jobs", "1"]);
    sleeper.kill().unwrap();
    sleeper.wait().unwrap();
    assert_code(&out, 0);
    let n: i64 = s
        .conn()
        .query_row("SELECT count(*) FROM run_lock", [], |r| r.get(0))
        .unwrap();
    assert_eq!(n, 0);
}

/// Start `calibrate --force --jobs 1` on the sample network, wait until it has stored `fits`
/// fits, send it `signal`, and return its exit status.
fn calibrate_and_signal(s: &Scratch, signal: i32, fits: i64) -> std::process::ExitStatus {
    let count = || -> i64 {
        s.conn()
            .query_row("SELECT count(*) FROM fits", [], |r| r.get(0))
            .unwrap_or(0)
    };
    let fits = count() + fits;
    let mut child = Command::new(env!("CARGO_BIN_EXE_pipewave"))
        .args(["calibrate", "--db", s.db(), "--force", "--jobs", "1"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    loop {
        if count() >= fits || start.elapsed().as_secs() > 120 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, signal) };
    child.wait().unwrap()
}

fn sample_network() -> Scratch {
    imported_from(
        "sample_network/segments.csv",
        "sample_network/measurements.csv",
    )
}

#[test]
fn sigterm_stops_calibrate_like_ctrl_c_and_a_killed_run_gets_its_counts() {
    let s = sample_network();
    let status = calibrate_and_signal(&s, libc::SIGTERM, 2);
    assert_eq!(status.code(), Some(130), "{status:?}");
    let c = s.conn();
    let locks: i64 = c
        .query_row("SELECT count(*) FROM run_lock", [], |r| r.get(0))
        .unwrap();
    assert_eq!(locks, 0, "SIGTERM left the lock behind");
    let status: String = c
        .query_row(
            "SELECT status FROM runs ORDER BY id DESC LIMIT 1",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(status, "interrupted");
    drop(c);

    // kill -9: the next run takes the stale lock over and counts the killed run's fits.
    let killed = calibrate_and_signal(&s, libc::SIGKILL, 4);
    assert_eq!(killed.code(), None);
    let c = s.conn();
    let run: i64 = c
        .query_row("SELECT max(id) FROM runs", [], |r| r.get(0))
        .unwrap();
    drop(c);
    let again = calibrate_and_signal(&s, libc::SIGTERM, 1);
    assert_eq!(again.code(), Some(130));
    let c = s.conn();
    let (n_ok, n_flagged, n_failed): (i64, i64, i64) = c
        .query_row(
            "SELECT n_ok, n_flagged, n_failed FROM runs WHERE id = ?1",
            [run],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
        )
        .unwrap();
    let stored: i64 = c
        .query_row("SELECT count(*) FROM fits WHERE run_id = ?1", [run], |r| {
            r.get(0)
        })
        .unwrap();
    assert!(stored >= 4, "{stored}");
    assert_eq!(n_ok + n_flagged + n_failed, stored);
    let ok: i64 = c
        .query_row(
            "SELECT count(*) FROM fits WHERE run_id = ?1 AND status = 'ok'",
            [run],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(n_ok, ok);
}
