//! `pipewave locate` (model §11, P84–P87): the closed-form single-pipe limit, multi-segment
//! delays, recovery of known leaks from synthetic delays and recordings made from the true
//! soils, coverage of the 95 % interval, and the messages for bad input, through the library and
//! the binary.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use pipewave::db::Database;
use pipewave::locate::gcc::RecordingPair;
use pipewave::locate::{DelayInput, LocateOptions, Locator, DEFAULT_BAND_HZ};
use pipewave::physics::{ContactMode, Fluid, Material, Model, Pipe, Soil, System};
use pipewave::stats::normal;
use pipewave::synth::locate::{
    calibrated_database, case_job, draw_case, leak_recording, network_of, segment_truth,
    true_delay, LeakCase, LeakSpec,
};
use pipewave::synth::recordings::{headroom_gain, write_wav, WavFormat};
use pipewave::synth::{generate, SynthOptions};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
}

fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("run pipewave")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A small street in EPSG:27700: A (PVC) → B (DI, drawn backwards) → C (DI), F (DI) beyond C
/// without a speed, D far away, E without geometry. Speeds are predictions with flat curves
/// (the soil field's table, migration 0008), so the delays have closed forms.
struct Street {
    _dir: tempfile::TempDir,
    db: PathBuf,
    dir: PathBuf,
}

const SPEED_A: f64 = 400.0;
const SPEED_B: f64 = 1200.0;
const SPEED_C: f64 = 1250.0;
const SPEED_E: f64 = 1000.0;
/// Relative one-sigma error of the flat curves.
const REL_STD: f64 = 0.01;

/// The slowness a stored speed `c` ± REL_STD enters the delay by: its median 1/c (model §11).
fn slowness(c: f64) -> f64 {
    1.0 / c
}

fn street() -> Street {
    let dir = tempfile::tempdir().unwrap();
    let segs = "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,length_m,geometry_wkt,srid\n\
        A,PVC,160,9.5,1900,100,\"LINESTRING (1000 1000, 1050 1000, 1100 1000)\",27700\n\
        B,DI,222,6.4,1900,150,\"LINESTRING (1250 1000, 1100.4 1000)\",27700\n\
        C,DI,222,6.4,1900,80,\"LINESTRING (1250 1000, 1250 1080)\",27700\n\
        F,DI,222,6.4,1900,50,\"LINESTRING (1250 1080, 1300 1080)\",27700\n\
        D,DI,222,6.4,1900,100,\"LINESTRING (5000 5000, 5100 5000)\",27700\n\
        E,DI,222,6.4,1900,50,,\n";
    std::fs::write(dir.path().join("segments.csv"), segs).unwrap();
    let db = dir.path().join("street.sqlite");
    let o = run(&[
        "import",
        "--db",
        db.to_str().unwrap(),
        "--segments",
        dir.path().join("segments.csv").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let database = Database::open(&db).unwrap();
    let conn = database.conn();
    for (id, c, att_db) in [
        ("A", SPEED_A, 0.5),
        ("B", SPEED_B, 0.02),
        ("C", SPEED_C, 0.02),
        ("D", SPEED_B, 0.02),
        ("E", SPEED_E, 0.02),
    ] {
        conn.execute("INSERT INTO predictions (segment_id) VALUES (?1)", [id])
            .unwrap();
        for f in [10.0, 100.0, 500.0, 1000.0, 2000.0] {
            conn.execute(
                "INSERT INTO prediction_curves (segment_id, frequency_hz, phase_speed_m_per_s, \
                 phase_speed_std_m_per_s, attenuation_db_per_m, attenuation_std_db_per_m) \
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                rusqlite::params![id, f, c, REL_STD * c, att_db, 0.1 * att_db],
            )
            .unwrap();
        }
    }
    Street {
        db,
        dir: dir.path().to_path_buf(),
        _dir: dir,
    }
}

fn korteweg(material: Material, od_mm: f64, wall_mm: f64) -> f64 {
    let pipe =
        Pipe::from_outside_diameter(material.typical(), od_mm * 1e-3, wall_mm * 1e-3).unwrap();
    let sys = System::new(
        Fluid::water(),
        pipe,
        Soil::none(),
        0.0,
        Model::Full,
        ContactMode::default(),
    )
    .unwrap();
    pipewave::physics::dispersion::korteweg_speed(&sys)
}

fn csv_rows(path: &Path) -> Vec<std::collections::HashMap<String, String>> {
    let mut r = csv::Reader::from_path(path).unwrap();
    let h: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            h.iter()
                .cloned()
                .zip(rec.iter().map(String::from))
                .collect()
        })
        .collect()
}

fn num(row: &std::collections::HashMap<String, String>, col: &str) -> f64 {
    row[col]
        .parse()
        .unwrap_or_else(|_| panic!("{col}: {:?}", row[col]))
}

/// One pipe: x = (D − cτ)/2 (P84), its interval from the three terms in closed form, the
/// table-speed answer with the pipe's Korteweg speed, and the terminal line.
#[test]
fn single_pipe_is_the_correlators_formula_through_the_binary() {
    let s = street();
    let (d, x) = (80.0, 25.0);
    let tau = (d - 2.0 * x) * slowness(SPEED_A);
    let out = s.dir.join("one.csv");
    let o = run(&[
        "locate",
        "--db",
        s.db.to_str().unwrap(),
        "--sensor1",
        "A:10",
        "--sensor2",
        "A:90",
        "--delay",
        &tau.to_string(),
        "--delay-std",
        "1e-4",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    let table = (d - korteweg(Material::Pvc, 160.0, 9.5) * tau) / 2.0;
    let first = text.lines().next().unwrap();
    assert!(
        first.starts_with(
            "leak at 25.0 m from sensor 1 (95 %: 24.2–25.8 m) on A; table speed would say "
        ),
        "{first}"
    );
    assert!(
        first.ends_with(&format!("{table:.1} m")),
        "{first} / {table}"
    );
    let r = &csv_rows(&out)[0];
    assert!((num(r, "distance_from_sensor1_m") - x).abs() < 0.01);
    assert!((num(r, "leak_chainage_m") - 35.0).abs() < 0.01);
    // σ: delay c σ_τ/2, speed (D − 2x)/2 · (1 − c/(c + σ_c)), span σ_D/2 with σ_D = 1 % of D.
    let sd = SPEED_A * 1e-4 / 2.0;
    let sc = tau * (REL_STD * SPEED_A) / 2.0;
    let sspan = 0.01 * d / 2.0;
    let sigma = (sd * sd + sc * sc + sspan * sspan).sqrt();
    assert!(
        (num(r, "distance_std_m") - sigma).abs() < 2e-3,
        "{} {sigma}",
        r["distance_std_m"]
    );
    assert!((num(r, "distance_from_sensor1_lo_m") - (x - 1.96 * sigma)).abs() < 0.01);
    assert!((num(r, "distance_from_sensor1_hi_m") - (x + 1.96 * sigma)).abs() < 0.01);
    assert!((num(r, "table_distance_from_sensor1_m") - table).abs() < 0.01);
    assert_eq!(r["largest_term"], "span");
    assert_eq!(r["speed_sources"], "prediction");
}

/// Three segments routed through the junction graph (B drawn backwards, its end 0.4 m from A's):
/// the delay is the sum of the pieces' travel times, the leak is found in B at the right
/// chainage, and the speed terms of the segments on either side of the leak have opposite signs.
#[test]
fn multi_segment_delay_is_consistent_and_routed_along_the_geometry() {
    let s = street();
    // Sensor 1 at A:20 (80 m to the junction), sensor 2 at C:30; leak 70 m into B from A.
    let lb = 149.6;
    let (t1, t2) = (
        80.0 * slowness(SPEED_A) + 70.0 * slowness(SPEED_B),
        (lb - 70.0) * slowness(SPEED_B) + 30.0 * slowness(SPEED_C),
    );
    let tau = t2 - t1;
    let out = s.dir.join("multi.csv");
    let gj = s.dir.join("multi.geojson");
    let gp = s.dir.join("multi.gpkg");
    let o = run(&[
        "locate",
        "--db",
        s.db.to_str().unwrap(),
        "--sensor1",
        "A:20",
        "--sensor2",
        "C:30",
        "--delay",
        &tau.to_string(),
        "--delay-std",
        "1e-4",
        "--span-std-fraction",
        "0",
        "--out",
        out.to_str().unwrap(),
        "--geojson",
        gj.to_str().unwrap(),
        "--gpkg",
        gp.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = &csv_rows(&out)[0];
    assert_eq!(r["path"], "A;B;C");
    assert!((num(r, "span_m") - (80.0 + lb + 30.0)).abs() < 1e-6);
    assert!(
        (num(r, "distance_from_sensor1_m") - 150.0).abs() < 0.01,
        "{}",
        r["distance_from_sensor1_m"]
    );
    assert_eq!(r["leak_segment"], "B");
    assert!((num(r, "leak_chainage_m") - (lb - 70.0)).abs() < 0.01);
    // The map point: 70 m along B from its end at A (B runs east to west from x = 1250).
    assert!((num(r, "leak_x") - 1170.4).abs() < 0.01 && (num(r, "leak_y") - 1000.0).abs() < 1e-6);
    let terms: std::collections::HashMap<String, f64> = r["error_speed_terms_m"]
        .split(';')
        .map(|t| {
            let (id, v) = t.split_once(':').unwrap();
            (id.to_string(), v.parse().unwrap())
        })
        .collect();
    // A lies wholly on sensor 1's side, C on sensor 2's: a faster A moves the leak away from
    // sensor 1, a faster C towards it.
    assert!(terms["A"] > 0.0 && terms["C"] < 0.0, "{terms:?}");
    // Closed form of A's term: δx = −δT/(∂T/∂x) with δT = 80 (1/c − 1/c') and ∂T/∂x = −2/c_B.
    let dt = 80.0 * (slowness(SPEED_A) - slowness(SPEED_A) / (1.0 + REL_STD));
    assert!(
        (terms["A"] - dt * SPEED_B / 2.0).abs() < 0.01,
        "{} {}",
        terms["A"],
        dt * SPEED_B / 2.0
    );
    // Outputs for GIS: a point and the interval along the pipe; the layers in a GeoPackage.
    let g: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&gj).unwrap()).unwrap();
    let kinds: Vec<&str> = g["features"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["geometry"]["type"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, vec!["Point", "LineString"]);
    let lon = g["features"][0]["geometry"]["coordinates"][0]
        .as_f64()
        .unwrap();
    assert!((-10.0..2.0).contains(&lon), "{lon}");
    let c = rusqlite::Connection::open(&gp).unwrap();
    let n: i64 = c
        .query_row(
            "SELECT COUNT(*) FROM leaks WHERE geom IS NOT NULL",
            [],
            |r| r.get(0),
        )
        .unwrap();
    let m: i64 = c
        .query_row(
            "SELECT COUNT(*) FROM gpkg_contents WHERE table_name IN ('leaks', 'leak_intervals')",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!((n, m), (1, 2));
    // A segment without geometry in an explicit path counts with its length_m.
    let o = run(&[
        "locate",
        "--db",
        s.db.to_str().unwrap(),
        "--sensor1",
        "A:20",
        "--sensor2",
        "A:90",
        "--delay",
        "0.1",
        "--delay-std",
        "1e-4",
        "--path",
        "A,E,C",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stdout(&o));
    assert!(
        stderr(&o).contains("must run from sensor 1's segment A to sensor 2's segment A"),
        "{}",
        stderr(&o)
    );
}

/// Each kind of bad input: a clear message and exit 2 for one correlation; a failed row and
/// exit 1 in a batch; exit 2 for an unusable jobs file.
#[test]
fn bad_input_is_reported_never_a_panic() {
    let s = street();
    let db = s.db.to_str().unwrap();
    let fails = |args: &[&str], want: &str| {
        let mut a = vec!["locate", "--db", db];
        a.extend_from_slice(args);
        let o = run(&a);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stdout(&o));
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
        assert!(!stderr(&o).contains("panicked"));
    };
    let delay = ["--delay", "0.01", "--delay-std", "1e-4"];
    let with = |a: &[&'static str]| -> Vec<&'static str> {
        a.iter().chain(delay.iter()).copied().collect()
    };
    fails(&with(&["--sensor1", "1030,1020", "--sensor2", "A:90"]), "sensor 1: the sensor at (1030, 1020) is off the network: the nearest segment, A, is 20.0 m away, beyond the snap tolerance of 5 m");
    fails(
        &with(&["--sensor1", "A:130", "--sensor2", "A:90"]),
        "chainage 130 m is off segment A",
    );
    fails(
        &with(&["--sensor1", "Q:1", "--sensor2", "A:90"]),
        "segment Q is not in the inventory",
    );
    fails(
        &with(&["--sensor1", "A:10", "--sensor2", "D:10"]),
        "not connected through the network",
    );
    fails(
        &with(&["--sensor1", "A:10", "--sensor2", "C:10", "--path", "A,C"]),
        "the path is not contiguous: segments A and C do not meet",
    );
    fails(
        &with(&["--sensor1", "C:10", "--sensor2", "F:10"]),
        "segment F on the path has no speed",
    );
    fails(
        &[
            "--sensor1",
            "A:10",
            "--sensor2",
            "A:90",
            "--delay",
            "0.5",
            "--delay-std",
            "1e-4",
        ],
        "is longer than the span allows",
    );
    // Recordings of different rates, lengths and channel counts.
    let wav = |name: &str, rate: u32, n: usize, ch: usize| -> String {
        let p = s.dir.join(name);
        let sig: Vec<f64> = (0..n).map(|i| ((i * 7919) % 97) as f64 / 200.0).collect();
        let chans: Vec<&[f64]> = (0..ch).map(|_| sig.as_slice()).collect();
        write_wav(&p, rate, &chans, WavFormat::Pcm16, 1.0).unwrap();
        p.to_str().unwrap().to_string()
    };
    let a = wav("a.wav", 8000, 80_000, 1);
    let b = wav("b.wav", 4000, 80_000, 1);
    let c = wav("c.wav", 8000, 70_000, 1);
    let d = wav("d.wav", 8000, 80_000, 2);
    let rec = |x: &str, y: &str, want: &str| {
        let r1 = format!("{x}:0");
        let r2 = format!("{y}:0");
        fails(
            &[
                "--sensor1",
                "A:10",
                "--sensor2",
                "A:90",
                "--recording1",
                &r1,
                "--recording2",
                &r2,
            ],
            want,
        );
    };
    rec(&a, &b, "is at 8000 Hz but");
    rec(&a, &c, "holds 80000 samples per channel but");
    rec(&a, &d, "has 1 channels but");
    let missing = s.dir.join("missing.wav").to_str().unwrap().to_string();
    rec(&a, &missing, "not a readable WAV file");
    // A channel the file does not have.
    fails(
        &[
            "--sensor1",
            "A:10",
            "--sensor2",
            "A:90",
            "--recording1",
            &format!("{d}:0"),
            "--recording2",
            &format!("{d}:5"),
        ],
        "column channel names channel 5 but the file has 2 channels",
    );
    // A delay that is not a number, or a negative error.
    fails(
        &[
            "--sensor1",
            "A:10",
            "--sensor2",
            "A:90",
            "--delay",
            "NaN",
            "--delay-std",
            "1e-4",
        ],
        "for '--delay <S>': NaN is outside -10 – 10 s",
    );
    fails(
        &[
            "--sensor1",
            "A:10",
            "--sensor2",
            "A:90",
            "--delay",
            "0.01",
            "--delay-std=-1e-4",
        ],
        "for '--delay-std <S>': -0.0001 is outside 0 – 10 s",
    );
    // A segment without geometry can be on a path only when the path is given.
    fails(
        &with(&["--sensor1", "E:10", "--sensor2", "A:90"]),
        "segment E has no geometry, so no path can be routed from it",
    );
    // The batch: a good row, a row with a bad cell, a row off the network.
    let jobs = s.dir.join("jobs.csv");
    std::fs::write(
        &jobs,
        "job_id,sensor1_segment,sensor1_chainage_m,sensor2_segment,sensor2_chainage_m,delay_s,delay_std_s,band_lo_hz,band_hi_hz,path\n\
         j1,A,10,A,90,0.075,1e-4,,,\n\
         j2,A,ten,A,90,0.075,1e-4,,,\n\
         j3,A,10,C,30,0.075,1e-4,200,600,A;B;C\n\
         j4,A,10,A,90,0.075,1e-4,600,200,\n\
         j5,A,10,A,90,0.5,1e-4,,,\n\
         j6,A,10,A,130,0.075,1e-4,,,\n\
         j7,C,10,F,10,0.01,1e-4,,,\n",
    )
    .unwrap();
    let out = s.dir.join("located.csv");
    let o = run(&[
        "locate",
        "--db",
        db,
        "--input",
        jobs.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--jobs",
        "3",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("2 of 7 jobs located, 5 failed"),
        "{}",
        stdout(&o)
    );
    assert!(!stderr(&o).contains("panicked"));
    let rows = csv_rows(&out);
    let status: Vec<&str> = rows.iter().map(|r| r["status"].as_str()).collect();
    assert_eq!(
        status,
        vec!["ok", "failed", "ok", "failed", "failed", "failed", "failed"]
    );
    for (row, want) in [
        (4, "is longer than the span allows"),
        (5, "chainage 130 m is off segment A"),
        (6, "segment F on the path has no speed"),
    ] {
        assert!(
            rows[row]["message"].contains(want),
            "{}",
            rows[row]["message"]
        );
    }
    assert!(
        rows[1]["message"]
            .contains("jobs.csv line 3, column sensor1_chainage_m: 'ten' is not a number"),
        "{}",
        rows[1]["message"]
    );
    assert!(
        rows[3]["message"].contains("line 5, column band_lo_hz"),
        "{}",
        rows[3]["message"]
    );
    assert!((num(&rows[2], "band_lo_hz_used") - 200.0).abs() < 1e-9);
    // Unusable files.
    let unusable = |content: &str, want: &str| {
        std::fs::write(&jobs, content).unwrap();
        let o = run(&[
            "locate",
            "--db",
            db,
            "--input",
            jobs.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(2));
        assert!(stderr(&o).contains(want), "{}", stderr(&o));
    };
    unusable(
        "job_id,sensor1_segment,sensor2_segment\nj1,A,A\n",
        "missing columns sensor1_chainage_m, sensor2_chainage_m",
    );
    unusable(
        "job_id,sensor1_segment,sensor1_chainage_m,sensor2_segment,sensor2_chainage_m\nj1,A,1,A,2\n",
        "no delay: give the columns delay_s, delay_std_s",
    );
}

/// A calibrated synthetic network: speeds from the segments' own fits (which never see the
/// truth), delays and recordings from the true soils.
#[test]
fn known_leaks_are_recovered_with_honest_intervals() {
    let dir = tempfile::tempdir().unwrap();
    let seed = 0x42_2026;
    let opts = SynthOptions {
        segments: 60,
        seed,
        defect_fraction: 0.0,
        ..SynthOptions::default()
    };
    let network = generate(&opts);
    let database = calibrated_database(dir.path(), &network, &opts, 2).unwrap();
    let net = network_of(&network, &opts);
    let options = LocateOptions {
        span_std_fraction: 0.0,
        ..LocateOptions::default()
    };
    let mut locator = Locator::new(database.conn(), options, 1.0).unwrap();
    let mut truths = std::collections::HashMap::new();
    let fill = |truths: &mut std::collections::HashMap<_, _>, case: &LeakCase| {
        for &s in &case.segments {
            truths
                .entry(s)
                .or_insert_with(|| segment_truth(&network[s], &opts, 8000).unwrap());
        }
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let sigma_tau = 1e-4;
    let (mut covered, mut errors) = (0, Vec::new());
    let n = 150;
    for c in 0..n {
        let case = draw_case(&net, &mut rng, 4, 400.0, &|_| true).unwrap();
        fill(&mut truths, &case);
        let tau = true_delay(&case, &truths, DEFAULT_BAND_HZ, true).unwrap()
            + sigma_tau * normal(&mut rng);
        let delay = DelayInput::Given {
            delay_s: tau,
            std_s: sigma_tau,
        };
        let l = locator
            .locate(&case_job(&net, &case, format!("G{c}"), delay))
            .unwrap();
        covered += usize::from(l.lo_m <= case.leak_m && case.leak_m <= l.hi_m);
        errors.push((l.distance_m - case.leak_m).abs());
    }
    errors.sort_by(|a, b| a.total_cmp(b));
    let coverage = covered as f64 / n as f64;
    assert!((0.85..=0.99).contains(&coverage), "coverage {coverage}");
    assert!(errors[n / 2] < 0.3, "median error {} m", errors[n / 2]);
    // From recordings made from the true soils: a metal and a plastic path.
    for (plastic, max_span, tol) in [(false, 300.0, 1.0), (true, 150.0, 2.0)] {
        let filter = |s: usize| network[s].material.is_plastic() == plastic;
        let case = draw_case(&net, &mut rng, 3, max_span, &filter).unwrap();
        fill(&mut truths, &case);
        let pieces = case.truth_pieces(&truths);
        let spec = LeakSpec {
            sample_rate: 8000,
            seconds: 60.0,
            noise_fraction: 0.3,
            seed: 7,
        };
        let rec = leak_recording(&pieces, case.leak_m, &spec).unwrap();
        let file = dir.path().join("leak.wav");
        let gain = headroom_gain(&[rec.x1.clone(), rec.x2.clone()]);
        write_wav(&file, 8000, &[&rec.x1, &rec.x2], WavFormat::Pcm16, gain).unwrap();
        let delay = DelayInput::Recordings(RecordingPair {
            file1: file.clone(),
            channel1: 0,
            file2: file.clone(),
            channel2: 1,
        });
        let l = locator
            .locate(&case_job(&net, &case, "R".into(), delay))
            .unwrap();
        assert!(
            (l.distance_m - case.leak_m).abs() < tol,
            "plastic {plastic}: {} vs {} ({})",
            l.distance_m,
            case.leak_m,
            l.band_note
        );
        assert!(
            l.delay_std_s > 0.0 && l.delay_std_s < 1e-3,
            "{}",
            l.delay_std_s
        );
    }
}

/// `synth --leaks` writes recordings and a jobs file that `locate` reads as they are, with the
/// leaks found where the truth file says.
#[test]
fn synthetic_leak_recordings_go_through_the_binary() {
    let dir = tempfile::tempdir().unwrap();
    let net = dir.path().join("net");
    let d = dir.path();
    let o = run(&[
        "synth",
        "--out",
        net.to_str().unwrap(),
        "--segments",
        "40",
        "--seed",
        "5",
        "--defects",
        "0",
        "--no-real-cases",
        "--leaks",
        "3",
        "--leak-seconds",
        "30",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let db = d.join("db.sqlite");
    let db = db.to_str().unwrap();
    let o = run(&[
        "import",
        "--db",
        db,
        "--segments",
        net.join("segments.csv").to_str().unwrap(),
        "--measurements",
        net.join("measurements.csv").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(&["calibrate", "--db", db, "--jobs", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = d.join("located.csv");
    let o = run(&[
        "locate",
        "--db",
        db,
        "--input",
        net.join("leaks/jobs.csv").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--jobs",
        "1",
    ]);
    assert!(o.status.success(), "{} {}", stdout(&o), stderr(&o));
    assert!(!stderr(&o).contains("note:"), "{}", stderr(&o));
    let truth = csv_rows(&net.join("leaks/leaks_truth.csv"));
    let got = csv_rows(&out);
    assert_eq!(got.len(), 3);
    // `--jobs N` is the number of worker threads, as in every other command: the answers do
    // not depend on it. The jobs file under its old name, `--jobs FILE`, is still read, with a
    // note that the option is now `--input`; a whole number out of range is refused.
    let one = std::fs::read(&out).unwrap();
    let threaded = d.join("located3.csv");
    let o = run(&[
        "locate",
        "--db",
        db,
        "--input",
        net.join("leaks/jobs.csv").to_str().unwrap(),
        "--out",
        threaded.to_str().unwrap(),
        "--jobs",
        "3",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        std::fs::read(&threaded).unwrap() == one,
        "--jobs 3 changed the answers"
    );
    let old = d.join("located_old.csv");
    let o = run(&[
        "locate",
        "--db",
        db,
        "--jobs",
        net.join("leaks/jobs.csv").to_str().unwrap(),
        "--out",
        old.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("that option is now --input FILE"),
        "{}",
        stderr(&o)
    );
    assert!(
        std::fs::read(&old).unwrap() == one,
        "--jobs FILE changed the answers"
    );
    let o = run(&[
        "locate",
        "--db",
        db,
        "--input",
        net.join("leaks/jobs.csv").to_str().unwrap(),
        "--out",
        old.to_str().unwrap(),
        "--jobs",
        "0",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("the range is 1 – 512"),
        "{}",
        stderr(&o)
    );
    for (t, g) in truth.iter().zip(&got) {
        assert_eq!(t["job_id"], g["job_id"]);
        let err = (num(t, "distance_from_sensor1_m") - num(g, "distance_from_sensor1_m")).abs();
        assert!(err < 2.0, "{}: {err} m ({})", g["job_id"], g["band_note"]);
    }
}

/// A network with few measured segments, in geological units: the speed errors of predicted
/// neighbours on one path are combined through the soil field's joint posterior. The combined
/// speed error is sᵀ R s of the budget's signed speed terms with the correlation the locator
/// reports, neighbours are correlated, and the independent answer is the identity's.
#[test]
fn predicted_neighbours_speed_errors_are_combined_through_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let seed = 0x42_2027;
    let opts = SynthOptions {
        segments: 80,
        seed,
        defect_fraction: 0.0,
        measured_fraction: 0.2,
        units: 2,
        ..SynthOptions::default()
    };
    let network = generate(&opts);
    let database = calibrated_database(dir.path(), &network, &opts, 2).unwrap();
    let net = network_of(&network, &opts);
    let joint = LocateOptions {
        span_std_fraction: 0.0,
        ..LocateOptions::default()
    };
    let independent = LocateOptions {
        joint_speeds: false,
        ..joint.clone()
    };
    let mut with = Locator::new(database.conn(), joint, 1.0).unwrap();
    let mut without = Locator::new(database.conn(), independent, 1.0).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut checked, mut strongest) = (0, 0.0f64);
    for c in 0..200 {
        let Some(case) = draw_case(&net, &mut rng, 4, 400.0, &|_| true) else {
            continue;
        };
        let job = case_job(
            &net,
            &case,
            format!("J{c}"),
            DelayInput::Given {
                delay_s: 0.0,
                std_s: 1e-4,
            },
        );
        // A delay of zero: a leak near the middle of the span.
        let Ok(probe) = with.locate(&job) else {
            continue;
        };
        if probe
            .sources
            .iter()
            .filter(|s| s.as_str() == "prediction")
            .count()
            < 2
        {
            continue;
        }
        let segs: Vec<usize> = probe
            .path_ids
            .iter()
            .map(|id| with.network.segment(id).unwrap())
            .collect();
        let Some((corr, pairs)) = with.speed_correlation(&segs, &probe.sources).unwrap() else {
            continue;
        };
        let shift = |id: &str| {
            probe
                .budget
                .iter()
                .find(|t| t.segment_id.as_deref() == Some(id))
                .map_or(0.0, |t| t.shift_m)
        };
        let s: Vec<f64> = probe.path_ids.iter().map(|id| shift(id)).collect();
        let mut v = 0.0;
        for a in 0..s.len() {
            for b in 0..s.len() {
                v += s[a] * s[b] * corr[(a, b)];
            }
        }
        assert!(
            (v.sqrt() - probe.speeds_std_m).abs() < 1e-9,
            "{} vs {}",
            v.sqrt(),
            probe.speeds_std_m
        );
        assert!(probe
            .notes
            .iter()
            .any(|n| n.contains("correlated through the soil field")));
        let alone = without.locate(&job).unwrap();
        let indep = s.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!((alone.speeds_std_m - indep).abs() < 1e-9);
        assert!((alone.distance_m - probe.distance_m).abs() < 1e-12);
        for (_, _, r) in pairs {
            assert!((-1.0..=1.0).contains(&r));
            strongest = strongest.max(r);
        }
        checked += 1;
    }
    assert!(checked >= 5, "{checked} paths with two predicted segments");
    assert!(strongest > 0.3, "strongest correlation {strongest}");
}
