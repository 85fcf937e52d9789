//! Defects of issue 62 (see main.rs) in what import accepts and in how the commands that read
//! stored geometry (locate, export, audit) treat one bad geometry: defects 6, 14 and 15, and
//! the bounds of every numeric CSV field.
//!
//! Each test starts from the reliability pass's set-up: a synthetic network of 40 segments
//! imported and calibrated.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common::cli::pipewave;
use crate::common::data_path;
use pipewave::db::{Connection, Database, SegmentRecord};

/// A network of 40 segments (half measured) imported into `a.sqlite` and calibrated.
struct Net {
    dir: tempfile::TempDir,
}

impl Net {
    fn new() -> Net {
        let dir = tempfile::tempdir().unwrap();
        let net = Net { dir };
        net.ok(&[
            "synth",
            "--out",
            &net.path("net"),
            "--segments",
            "40",
            "--seed",
            "3",
            "--measured-fraction",
            "0.5",
            "--no-real-cases",
        ]);
        net.ok(&[
            "import",
            "--db",
            &net.db(),
            "--segments",
            &net.path("net/segments.csv"),
            "--measurements",
            &net.path("net/measurements.csv"),
        ]);
        net.ok(&["calibrate", "--db", &net.db()]);
        net
    }

    fn path(&self, rel: &str) -> String {
        self.dir.path().join(rel).display().to_string()
    }

    fn db(&self) -> String {
        self.path("a.sqlite")
    }

    fn run(&self, args: &[&str]) -> Output {
        pipewave().args(args).output().unwrap()
    }

    fn ok(&self, args: &[&str]) -> Output {
        let out = self.run(args);
        assert!(
            out.status.success(),
            "pipewave {args:?}:\n{}\n{}",
            text(&out.stdout),
            text(&out.stderr)
        );
        out
    }

    /// `net/segments.csv` with `edit` applied to the cells of each row (header excluded),
    /// written to `name`.
    fn segments_with(&self, name: &str, edit: impl Fn(&mut Vec<String>)) -> String {
        edit_csv(&self.path("net/segments.csv"), &self.path(name), edit)
    }

    fn measurements_with(&self, name: &str, edit: impl Fn(&mut Vec<String>)) -> String {
        edit_csv(&self.path("net/measurements.csv"), &self.path(name), edit)
    }

    /// Import `args` (after `import --db a.sqlite`): it must be refused with exit 2, leaving the
    /// stored inventory as it was. Its stderr.
    fn refused(&self, args: &[&str]) -> String {
        let before = self.stored();
        let db = self.db();
        let mut all = vec!["import", "--db", &db];
        all.extend(args);
        let out = self.run(&all);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert_eq!(
            self.stored(),
            before,
            "a refused import changed the database"
        );
        stderr
    }

    fn stored(&self) -> Vec<SegmentRecord> {
        let d = Database::open(Path::new(&self.db())).unwrap();
        pipewave::db::load_segments(d.conn(), None).unwrap()
    }

    /// Edit the stored inventory directly, as a user with an SQL shell may.
    fn sql(&self, statement: &str) {
        let c = Connection::open(self.db()).unwrap();
        assert_eq!(c.execute(statement, []).unwrap(), 1, "{statement}");
    }
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Column `name`'s index in `header` (0-based).
fn col(header: &[String], name: &str) -> usize {
    header.iter().position(|h| h == name).unwrap()
}

fn edit_csv(from: &str, to: &str, edit: impl Fn(&mut Vec<String>)) -> String {
    let mut r = csv::Reader::from_path(from).unwrap();
    let mut w = csv::Writer::from_path(to).unwrap();
    w.write_record(r.headers().unwrap()).unwrap();
    for rec in r.records() {
        let mut cells: Vec<String> = rec.unwrap().iter().map(str::to_string).collect();
        edit(&mut cells);
        w.write_record(&cells).unwrap();
    }
    w.flush().unwrap();
    to.to_string()
}

fn header(path: &str) -> Vec<String> {
    let mut r = csv::Reader::from_path(path).unwrap();
    r.headers().unwrap().iter().map(str::to_string).collect()
}

/// `FILE:LINE:COL: column NAME:` of segment `id`'s row of a copy of the synthetic segments
/// file (header `names`): WM100NN is on line NN + 1.
fn at(file: &str, id: &str, names: &[String], column: &str) -> String {
    let line = id.trim_start_matches("WM100").parse::<u64>().unwrap() + 1;
    format!("{file}:{line}:{}: column {column}:", col(names, column) + 1)
}

fn set(cells: &mut [String], id: &str, index: usize, value: &str) {
    if cells[0] == id {
        cells[index] = value.to_string();
    }
}

#[test]
fn defect_06_an_unknown_epsg_code_is_refused_at_import() {
    let net = Net::new();
    let names = header(&net.path("net/segments.csv"));
    let (srid, wkt) = (col(&names, "srid"), col(&names, "geometry_wkt"));

    // CSV: srid 999999 on one row, named by file, line and column.
    let f = net.segments_with("net/unknown.csv", |c| set(c, "WM10005", srid, "999999"));
    let stderr = net.refused(&["--segments", &f]);
    let want = at(&f, "WM10005", &names, "srid");
    assert!(
        stderr.contains(&format!("{want} EPSG:999999 is not a coordinate system")),
        "no {want:?} in {stderr}"
    );

    // CSV: WGS 84 with projected coordinates (what a GeoJSON is refused for).
    let f = net.segments_with("net/lonlat.csv", |c| {
        if c[0] == "WM10006" {
            c[wkt] = "LINESTRING (530000 180000, 530100 180000)".into();
            c[srid] = "4326".into();
        }
    });
    let stderr = net.refused(&["--segments", &f]);
    let want = at(&f, "WM10006", &names, "geometry_wkt");
    assert!(
        stderr.contains(&format!(
            "{want} the vertex (530000 180000) is not a longitude"
        )),
        "no {want:?} in {stderr}"
    );

    // GeoJSON naming EPSG::999999.
    let geojson = net.path("net/unknown.geojson");
    std::fs::write(
        &geojson,
        r#"{"type":"FeatureCollection","name":"mains","crs":{"type":"name","properties":{"name":"urn:ogc:def:crs:EPSG::999999"}},"features":[
 {"type":"Feature","id":1,"properties":{"segment_id":"G1","material":"DI","outer_diameter_mm":170,"wall_thickness_mm":6,"soil_density_kg_m3":1900},"geometry":{"type":"LineString","coordinates":[[0,0],[10,0]]}}]}"#,
    )
    .unwrap();
    let stderr = net.refused(&["--segments", &geojson]);
    assert!(
        stderr.contains(&format!(
            "{geojson}: layer mains: the layer's coordinate system: EPSG:999999 is not"
        )),
        "{stderr}"
    );

    // GeoPackage whose layer's srs is EPSG 2^62.
    let gpkg = net.path("net/huge_srs.gpkg");
    std::fs::copy(data_path("gis/pipes.gpkg"), &gpkg).unwrap();
    let c = Connection::open(&gpkg).unwrap();
    c.execute(
        "UPDATE gpkg_spatial_ref_sys SET organization_coordsys_id = ?1 WHERE srs_id = \
         (SELECT srs_id FROM gpkg_geometry_columns WHERE table_name = 'water_mains')",
        [1i64 << 62],
    )
    .unwrap();
    drop(c);
    let mut args = vec!["--segments", &gpkg, "--layer", "water_mains"];
    let map = [
        "segment_id=ASSET_ID",
        "outer_diameter_mm=DIAM_MM",
        "wall_thickness_mm=WALL_MM",
        "soil_density_kg_m3=SOIL_RHO",
    ];
    for m in &map {
        args.extend(["--map", m]);
    }
    let stderr = net.refused(&args);
    assert!(
        stderr.contains(
            "layer water_mains: the layer's coordinate system: EPSG:4611686018427387904 is not"
        ),
        "{stderr}"
    );

    // Shapefile whose .prj names EPSG 999999.
    let shp = net.path("net/pipes.shp");
    for ext in ["shp", "shx", "dbf"] {
        std::fs::copy(
            data_path(&format!("gis/pipes.{ext}")),
            Path::new(&shp).with_extension(ext),
        )
        .unwrap();
    }
    std::fs::write(
        PathBuf::from(&shp).with_extension("prj"),
        r#"PROJCS["Local",GEOGCS["x"],AUTHORITY["EPSG","999999"]]"#,
    )
    .unwrap();
    let mut args = vec!["--segments", shp.as_str()];
    for m in &map {
        args.extend(["--map", m]);
    }
    let stderr = net.refused(&args);
    assert!(
        stderr.contains("layer pipes: the layer's coordinate system: EPSG:999999 is not"),
        "{stderr}"
    );
}

#[test]
fn defect_06_a_bad_stored_geometry_costs_only_its_jobs() {
    let net = Net::new();
    // Edited in by SQL: an unknown system, and a vertex no system has.
    net.sql("UPDATE segments SET srid = 999999 WHERE segment_id = 'WM10005'");
    net.sql(
        "UPDATE segments SET geometry_wkt = 'LINESTRING (1e308 111900, 442160 111990)' \
         WHERE segment_id = 'WM10007'",
    );
    let jobs = net.path("jobs.csv");
    std::fs::write(
        &jobs,
        "job_id,sensor1_segment,sensor1_chainage_m,sensor2_segment,sensor2_chainage_m,delay_s,delay_std_s\n\
         J1,WM10002,10,WM10002,80,0.001,0.0001\n\
         J2,WM10005,10,WM10005,80,0.001,0.0001\n\
         J3,WM10007,10,WM10007,80,0.001,0.0001\n\
         J4,WM10003,10,WM10003,80,0.001,0.0001\n",
    )
    .unwrap();
    let answers = net.path("answers.csv");
    let out = net.run(&[
        "locate",
        "--db",
        &net.db(),
        "--jobs",
        &jobs,
        "--out",
        &answers,
    ]);
    let stderr = text(&out.stderr);
    // 1: done, some jobs failed (docs/interface.md); not 2, "could not run".
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let mut r = csv::Reader::from_path(&answers).unwrap();
    let names: Vec<String> = r.headers().unwrap().iter().map(str::to_string).collect();
    let (status, message) = (col(&names, "status"), col(&names, "message"));
    let rows: Vec<Vec<String>> = r
        .records()
        .map(|r| r.unwrap().iter().map(str::to_string).collect())
        .collect();
    assert_eq!(rows.len(), 4);
    for (row, bad) in rows
        .iter()
        .zip([None, Some("WM10005"), Some("WM10007"), None])
    {
        match bad {
            None => assert_eq!(row[status], "ok", "{row:?}"),
            Some(id) => {
                assert_eq!(row[status], "failed", "{row:?}");
                let m = &row[message];
                assert!(
                    m.contains(&format!("segment {id}: its stored geometry cannot be used")),
                    "{m}"
                );
            }
        }
    }
    assert!(stderr.contains("EPSG:999999"), "{stderr}");
    assert!(stderr.contains("than any point on Earth"), "{stderr}");
}

#[test]
fn defect_14_values_the_fit_cannot_use_are_refused_at_import() {
    let net = Net::new();
    let names = header(&net.path("net/segments.csv"));
    let (wall, wkt) = (
        col(&names, "wall_thickness_mm"),
        col(&names, "geometry_wkt"),
    );
    let cases: [(&str, usize, &str, &str, &str); 4] = [
        // A wall the thin-shell model cannot use (calibrate failed with |F| = NaN).
        (
            "WM10002",
            wall,
            "1e-300",
            "wall_thickness_mm",
            "too thin a wall",
        ),
        // 0.5 mm on a 323.9 mm steel main: h/a = 0.003, D/h = 650.
        (
            "WM10002",
            wall,
            "0.5",
            "wall_thickness_mm",
            "too thin a wall",
        ),
        (
            "WM10003",
            wkt,
            "LINESTRING (442040 111900, 442040 111900, 442040 111900)",
            "geometry_wkt",
            "zero length",
        ),
        (
            "WM10004",
            wkt,
            "LINESTRING (1e308 111900, 442160 111990)",
            "geometry_wkt",
            "than any point on Earth",
        ),
    ];
    for (i, (id, index, value, column, why)) in cases.into_iter().enumerate() {
        let f = net.segments_with(&format!("net/bad{i}.csv"), |c| set(c, id, index, value));
        let stderr = net.refused(&["--segments", &f]);
        let want = at(&f, id, &names, column);
        assert!(
            stderr
                .lines()
                .any(|l| l.starts_with(&want) && l.contains(why)),
            "no {want:?} ... {why:?} in {stderr}"
        );
    }
    // The thinnest walls of real water pipes still import: D/h = 290 on the steel main.
    let f = net.segments_with("net/thin.csv", |c| set(c, "WM10002", wall, "1.117"));
    net.ok(&["import", "--db", &net.db(), "--segments", &f]);
}

#[test]
fn defect_15_a_segment_exported_without_geometry_is_not_counted_with_geometry() {
    let net = Net::new();
    net.sql("UPDATE segments SET srid = 999999 WHERE segment_id = 'WM10005'");
    net.sql("UPDATE segments SET srid = NULL WHERE segment_id = 'WM10009'");
    let gpkg = net.path("out.gpkg");
    let out = net.ok(&[
        "export",
        "--db",
        &net.db(),
        "--format",
        "gpkg",
        "--out",
        &gpkg,
    ]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(
        stdout.contains("40 segments") && stdout.contains("38 with geometry"),
        "{stdout}"
    );
    for id in ["WM10005", "WM10009"] {
        assert!(
            stderr.contains(&format!("segment {id}:")) && stderr.contains("without geometry"),
            "no warning for {id}: {stderr}"
        );
    }
    let c = Connection::open(&gpkg).unwrap();
    let written: i64 = c
        .query_row(
            "SELECT COUNT(*) FROM pipe_segments WHERE geom IS NOT NULL",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(written, 38);

    let html = net.path("audit.html");
    let out = net.ok(&["audit", "--db", &net.db(), "--out", &html]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(stdout.contains("38 with geometry"), "{stdout}");
    for id in ["WM10005", "WM10009"] {
        assert!(stderr.contains(&format!("segment {id}:")), "{stderr}");
    }
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(
        page.contains("<tr><th>with geometry</th><td class=\"n\">38</td></tr>"),
        "the summary's count"
    );
}

#[test]
fn every_numeric_csv_field_has_a_bound_checked_at_import() {
    let net = Net::new();
    let seg = header(&net.path("net/segments.csv"));
    for (i, (column, value, why)) in [
        ("length_m", "1e308", "longer than a segment can be"),
        ("install_year", "19470101", "is not a year"),
        ("install_year", "47", "is not a year"),
    ]
    .into_iter()
    .enumerate()
    {
        let k = col(&seg, column);
        let f = net.segments_with(&format!("net/b{i}.csv"), |c| set(c, "WM10008", k, value));
        let stderr = net.refused(&["--segments", &f]);
        let want = at(&f, "WM10008", &seg, column);
        assert!(
            stderr
                .lines()
                .any(|l| l.starts_with(&want) && l.contains(why)),
            "no {want:?} ... {why:?} in {stderr}"
        );
    }
    // risk_weight is not in the synthetic file: a file with it.
    let f = net.path("net/risk.csv");
    std::fs::write(
        &f,
        "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,risk_weight\n\
         R1,DI,170,6,1900,1e300\n",
    )
    .unwrap();
    let stderr = net.refused(&["--segments", &f]);
    assert!(
        stderr.contains(&format!("{f}:2:6: column risk_weight: 1e300 is more than")),
        "{stderr}"
    );

    // A standard deviation the fit cannot weight by.
    let meas = header(&net.path("net/measurements.csv"));
    for column in ["k_re_std", "attenuation_std"] {
        let k = col(&meas, column);
        let f = net.measurements_with(&format!("net/m_{column}.csv"), |c| {
            if c[0] == "WM10002" {
                c[k] = "1e-300".into();
            }
        });
        let stderr = net.refused(&["--measurements", &f]);
        assert!(
            stderr.lines().any(
                |l| l.starts_with(&format!("{f}:2:{}: column {column}:", k + 1))
                    && l.contains("no field wavenumber is known that well")
            ),
            "{stderr}"
        );
    }
}
