//! `pipewave calibrate`, `run` and `synth`, run as a user would: the real binary on temporary
//! databases, with small synthetic networks (6-12 segments) made by `pipewave synth`.

mod cli_run;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use cli_run::run_ok;
use pipewave::db::{self, Database};
use rusqlite::types::Value;
use rusqlite::Connection;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// `pipewave synth` into `dir/net`: `n` synthetic segments, no defects, no published cases.
fn synth(dir: &Path, n: usize, seed: u64) -> PathBuf {
    let net = dir.join("net");
    run_ok(&[
        "synth",
        "--out",
        s(&net),
        "--segments",
        &n.to_string(),
        "--seed",
        &seed.to_string(),
        "--defects",
        "0",
        "--no-real-cases",
    ]);
    net
}

fn import(db: &Path, net: &Path) {
    run_ok(&[
        "import",
        "--db",
        s(db),
        "--segments",
        s(&net.join("segments.csv")),
        "--measurements",
        s(&net.join("measurements.csv")),
    ]);
}

fn calibrate(db: &Path, extra: &[&str]) -> String {
    let mut args = vec!["calibrate", "--db", s(db)];
    args.extend_from_slice(extra);
    run_ok(&args)
}

fn count(db: &Path, sql: &str) -> i64 {
    let c = Connection::open(db).unwrap();
    c.query_row(sql, [], |r| r.get(0)).unwrap()
}

/// Fits per segment id.
fn fits_per_segment(db: &Path) -> Vec<(String, i64)> {
    let c = Connection::open(db).unwrap();
    let mut st = c
        .prepare("SELECT segment_id, count(*) FROM fits GROUP BY segment_id ORDER BY segment_id")
        .unwrap();
    let rows = st
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    rows
}

/// Columns that legitimately differ between two runs of the same fits.
const RUN_COLUMNS: [&str; 4] = ["id", "run_id", "elapsed_ms", "created_at"];

/// One fit: (column, value) for every compared column.
type FitColumns = Vec<(String, Value)>;

/// Every column of every fit except [`RUN_COLUMNS`], by segment, and every curve point; the
/// values as SQLite holds them (bit-exact REALs).
fn stored_fits(db: &Path) -> (Vec<FitColumns>, Vec<Vec<Value>>) {
    let c = Connection::open(db).unwrap();
    let mut st = c
        .prepare("SELECT * FROM latest_fits ORDER BY segment_id")
        .unwrap();
    let names: Vec<String> = st.column_names().iter().map(|n| n.to_string()).collect();
    let fits = st
        .query_map([], |r| {
            let mut row = Vec::new();
            for (i, n) in names.iter().enumerate() {
                if !RUN_COLUMNS.contains(&n.as_str()) {
                    row.push((n.clone(), r.get::<_, Value>(i)?));
                }
            }
            Ok(row)
        })
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .unwrap();
    let mut st = c
        .prepare(
            "SELECT c.segment_id, c.frequency_hz, c.phase_speed_m_per_s, c.attenuation_db_per_m \
             FROM curves c JOIN latest_fits f ON f.segment_id = c.segment_id AND f.run_id = c.run_id \
             ORDER BY c.segment_id, c.frequency_hz",
        )
        .unwrap();
    let curves = st
        .query_map([], |r| {
            (0..4)
                .map(|i| r.get::<_, Value>(i))
                .collect::<Result<Vec<_>, _>>()
        })
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .unwrap();
    (fits, curves)
}

/// Wait until `pred` holds (polling), or panic after `limit`.
fn wait_until(limit: Duration, what: &str, mut pred: impl FnMut() -> bool) {
    let t = Instant::now();
    while !pred() {
        assert!(t.elapsed() < limit, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Fits stored so far (0 while the database cannot be read).
fn fits_so_far(db: &Path) -> i64 {
    Connection::open(db)
        .and_then(|c| c.query_row("SELECT count(*) FROM fits", [], |r| r.get(0)))
        .unwrap_or(0)
}

fn spawn_calibrate(db: &Path, extra: &[&str]) -> Child {
    bin()
        .args(["calibrate", "--db", s(db)])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn pipewave")
}

#[test]
fn only_stale_segments_are_refitted() {
    let tmp = tempfile::tempdir().unwrap();
    let net = synth(tmp.path(), 8, 11);
    let db = tmp.path().join("a.sqlite");
    import(&db, &net);

    let first = calibrate(&db, &["--jobs", "2"]);
    assert!(first.starts_with("calibrate: 8 fitted ("), "{first}");
    assert!(first.contains("0 failed), 0 up to date"), "{first}");
    assert_eq!(count(&db, "SELECT count(*) FROM fits"), 8);
    assert_eq!(count(&db, "SELECT count(*) FROM curves"), 8 * 32);
    assert_eq!(
        count(
            &db,
            "SELECT count(*) FROM runs WHERE status = 'finished' AND n_segments = 8"
        ),
        1
    );

    // Nothing changed: nothing is refitted (but the run is recorded).
    let second = calibrate(&db, &[]);
    assert!(second.starts_with("calibrate: 0 fitted"), "{second}");
    assert!(second.contains("8 up to date"), "{second}");
    assert_eq!(count(&db, "SELECT count(*) FROM fits"), 8);
    assert_eq!(count(&db, "SELECT count(*) FROM runs"), 2);

    // One changed measurement: only its segment is refitted.
    let path = net.join("measurements.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let i = lines
        .iter()
        .position(|l| l.starts_with("WM10003,"))
        .expect("a WM10003 row");
    let mut cells: Vec<String> = lines[i].split(',').map(str::to_string).collect();
    let k: f64 = cells[3].parse().unwrap();
    cells[3] = (k * 1.002).to_string();
    lines[i] = cells.join(",");
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    import(&db, &net);
    let third = calibrate(&db, &[]);
    assert!(third.starts_with("calibrate: 1 fitted"), "{third}");
    assert!(third.contains("7 up to date"), "{third}");
    let per = fits_per_segment(&db);
    for (id, n) in &per {
        assert_eq!(*n, if id == "WM10003" { 2 } else { 1 }, "{id}");
    }

    // --segment limits the run; with --force it refits a current segment.
    let named = calibrate(&db, &["--segment", "WM10001"]);
    assert!(named.starts_with("calibrate: 0 fitted"), "{named}");
    assert!(named.contains("1 up to date"), "{named}");
    let named = calibrate(&db, &["--segment", "WM10001", "--force"]);
    assert!(named.starts_with("calibrate: 1 fitted"), "{named}");

    // --force refits everything.
    let forced = calibrate(&db, &["--force"]);
    assert!(forced.starts_with("calibrate: 8 fitted"), "{forced}");
    assert_eq!(count(&db, "SELECT count(*) FROM fits"), 8 + 1 + 1 + 8);

    // Other settings make every fit stale; the same settings again refit nothing.
    let seed_model = calibrate(&db, &["--model", "seed"]);
    assert!(
        seed_model.starts_with("calibrate: 8 fitted"),
        "{seed_model}"
    );
    assert_eq!(
        count(&db, "SELECT count(*) FROM latest_fits WHERE model = 'seed'"),
        8
    );
    let again = calibrate(&db, &["--model", "seed", "--seed", "99"]);
    assert!(again.starts_with("calibrate: 0 fitted"), "{again}");

    // Effects: their names and parameters are stored in their columns, the others stay NULL.
    let effects = calibrate(
        &db,
        &[
            "--segment",
            "WM10002",
            "--effects",
            "pipe_loss,soil_damping",
        ],
    );
    assert!(effects.starts_with("calibrate: 1 fitted"), "{effects}");
    assert_eq!(
        count(
            &db,
            "SELECT count(*) FROM latest_fits WHERE segment_id = 'WM10002' AND \
             effects = 'soil_damping,pipe_loss' AND model = 'full' AND \
             soil_loss_factor BETWEEN 0 AND 0.3 AND pipe_loss_factor BETWEEN 0 AND 0.3 AND \
             air_fraction IS NULL AND wall_thickness_ratio IS NULL AND \
             json_array_length(correlations) = 5 AND evaluations > 0 AND misfit >= 0"
        ),
        1
    );

    // An unknown segment id is an error that names it.
    let bad = bin()
        .args(["calibrate", "--db", s(&db), "--segment", "NOPE-1"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
    assert!(stderr(&bad).contains("NOPE-1"), "{}", stderr(&bad));
    // So is an unknown effect name.
    let bad = bin()
        .args([
            "calibrate",
            "--db",
            s(&db),
            "--effects",
            "soil_damping,magic",
        ])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        stderr(&bad).contains("unknown effect 'magic'"),
        "{}",
        stderr(&bad)
    );
}

#[test]
fn jobs_do_not_change_the_stored_fits() {
    let tmp = tempfile::tempdir().unwrap();
    let net = synth(tmp.path(), 8, 12);
    let (a, b) = (tmp.path().join("a.sqlite"), tmp.path().join("b.sqlite"));
    import(&a, &net);
    import(&b, &net);
    calibrate(&a, &["--jobs", "1", "--seed", "7"]);
    calibrate(&b, &["--jobs", "2", "--seed", "7"]);
    let (fa, ca) = stored_fits(&a);
    let (fb, cb) = stored_fits(&b);
    assert_eq!(fa.len(), 8);
    assert_eq!(ca.len(), 8 * 32);
    assert_eq!(fa, fb);
    assert_eq!(ca, cb);
    // The runs record their thread counts, and the seeds are the per-segment ones.
    assert_eq!(count(&a, "SELECT jobs FROM runs"), 1);
    assert_eq!(count(&b, "SELECT jobs FROM runs"), 2);
    let seed: i64 = count(&a, "SELECT seed FROM fits WHERE segment_id = 'WM10001'");
    assert_eq!(seed as u64, pipewave::batch::segment_seed(7, "WM10001"));
    // A different run seed gives different fits (the seed does reach the optimiser).
    let c = tmp.path().join("c.sqlite");
    import(&c, &net);
    calibrate(&c, &["--jobs", "2", "--seed", "8"]);
    assert_ne!(stored_fits(&c).0, fa);
}

/// Streaming: a run reads the inventory a page at a time. Pages of 1 and of 5 segments (12 is
/// a multiple of the one and not of the other), with up-to-date segments among those to fit,
/// store exactly the fits of a run that reads everything in one page, each segment once, and
/// count the same segments.
#[test]
fn a_run_read_in_small_pages_stores_the_same_fits_as_one_page() {
    use pipewave::batch::{calibrate as run_calibrate, CalibrateOptions, DEFAULT_CHUNK_SIZE};
    use std::sync::atomic::AtomicBool;

    let tmp = tempfile::tempdir().unwrap();
    let net = synth(tmp.path(), 12, 16);
    let mut lines = Vec::new();
    for chunk_size in [1, 5, DEFAULT_CHUNK_SIZE] {
        let db = tmp.path().join(format!("chunk{chunk_size}.sqlite"));
        import(&db, &net);
        // Two segments already fitted, so pages mix segments to fit and up-to-date ones.
        calibrate(&db, &["--segment", "WM10002", "--segment", "WM10007"]);
        let mut database = Database::open(&db).unwrap();
        let opts = CalibrateOptions {
            jobs: Some(2),
            seed: 7,
            chunk_size,
            ..CalibrateOptions::default()
        };
        let summary =
            run_calibrate(database.conn_mut(), &opts, &mut (), &AtomicBool::new(false)).unwrap();
        assert_eq!(
            (summary.selected, summary.stored(), summary.up_to_date),
            (10, 10, 2),
            "chunk {chunk_size}: {}",
            summary.line()
        );
        assert!(!summary.interrupted, "chunk {chunk_size}");
        let per = fits_per_segment(&db);
        assert_eq!(per.len(), 12, "chunk {chunk_size}");
        assert!(
            per.iter().all(|(_, n)| *n == 1),
            "chunk {chunk_size}: {per:?}"
        );
        assert_eq!(
            count(
                &db,
                "SELECT count(*) FROM runs WHERE status = 'finished' AND n_segments = 10"
            ),
            1,
            "chunk {chunk_size}"
        );
        lines.push(stored_fits(&db));
    }
    assert_eq!(lines[0].0.len(), 12);
    assert_eq!(lines[0], lines[1]);
    assert_eq!(lines[0], lines[2]);
}

#[test]
fn a_killed_run_loses_nothing_and_the_next_run_finishes_it() {
    let tmp = tempfile::tempdir().unwrap();
    let net = synth(tmp.path(), 10, 13);
    let (a, b) = (tmp.path().join("a.sqlite"), tmp.path().join("b.sqlite"));
    import(&a, &net);
    import(&b, &net);

    let mut child = spawn_calibrate(&a, &["--jobs", "1"]);
    wait_until(Duration::from_secs(120), "the first fit", || {
        fits_so_far(&a) >= 1
    });
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let stored = fits_so_far(&a);
    assert!(
        (1..10).contains(&stored),
        "the kill should land mid-run: {stored} of 10 stored"
    );
    // Every stored fit has its whole curve (one transaction per segment).
    assert_eq!(count(&a, "SELECT count(*) FROM curves"), stored * 32);
    assert_eq!(
        count(&a, "SELECT count(*) FROM runs WHERE status = 'running'"),
        1
    );

    let resumed = bin()
        .args(["calibrate", "--db", s(&a), "--jobs", "2"])
        .output()
        .unwrap();
    assert!(resumed.status.success(), "{}", stderr(&resumed));
    let line = stdout(&resumed);
    assert!(
        line.starts_with(&format!("calibrate: {} fitted", 10 - stored)),
        "{line}"
    );
    assert!(
        stderr(&resumed).contains("no longer exists"),
        "the stale lock is reported: {}",
        stderr(&resumed)
    );
    // One fit per segment: nothing lost, nothing duplicated; the killed run is marked.
    let per = fits_per_segment(&a);
    assert_eq!(per.len(), 10);
    assert!(per.iter().all(|(_, n)| *n == 1), "{per:?}");
    assert_eq!(
        count(&a, "SELECT count(*) FROM runs WHERE status = 'interrupted'"),
        1
    );
    assert_eq!(count(&a, "SELECT count(*) FROM run_lock"), 0);

    // The same fits as an uninterrupted run.
    calibrate(&b, &["--jobs", "2"]);
    assert_eq!(stored_fits(&a), stored_fits(&b));
}

#[test]
fn ctrl_c_stops_the_run_marks_it_interrupted_and_keeps_its_fits() {
    let tmp = tempfile::tempdir().unwrap();
    let net = synth(tmp.path(), 10, 14);
    let db = tmp.path().join("a.sqlite");
    import(&db, &net);
    let child = spawn_calibrate(&db, &["--jobs", "1"]);
    wait_until(Duration::from_secs(120), "the first fit", || {
        fits_so_far(&db) >= 1
    });
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    assert!(stderr(&out).contains("interrupted"), "{}", stderr(&out));
    let line = stdout(&out);
    assert!(line.contains("interrupted:"), "{line}");
    let stored = fits_so_far(&db);
    assert!((1..10).contains(&stored), "{stored}");
    assert_eq!(
        count(
            &db,
            &format!(
                "SELECT count(*) FROM runs WHERE status = 'interrupted' AND n_ok + n_flagged + \
                 n_failed = {stored}"
            )
        ),
        1
    );
    assert_eq!(count(&db, "SELECT count(*) FROM run_lock"), 0);
    // The next run fits the rest.
    let rest = calibrate(&db, &[]);
    assert!(
        rest.starts_with(&format!("calibrate: {} fitted", 10 - stored)),
        "{rest}"
    );
    assert!(fits_per_segment(&db).iter().all(|(_, n)| *n == 1));
}

#[test]
fn a_second_concurrent_run_fails_at_once_or_waits_with_wait() {
    let tmp = tempfile::tempdir().unwrap();
    let net = synth(tmp.path(), 6, 15);
    let db = tmp.path().join("a.sqlite");
    import(&db, &net);

    // This test process holds the lock, as a running calibrate would.
    let mut holder = Database::open(&db).unwrap();
    let lock = db::try_acquire_run_lock(holder.conn_mut()).unwrap();

    let refused = bin().args(["calibrate", "--db", s(&db)]).output().unwrap();
    assert_eq!(refused.status.code(), Some(2));
    let msg = stderr(&refused);
    assert!(
        msg.contains(&format!(
            "another calibrate run (pid {}",
            std::process::id()
        )),
        "{msg}"
    );
    assert!(msg.contains("--wait"), "{msg}");
    assert_eq!(msg.lines().count(), 1, "one line: {msg}");
    assert_eq!(count(&db, "SELECT count(*) FROM runs"), 0);

    // With --wait it waits, then runs.
    let mut waiting = spawn_calibrate(&db, &["--wait"]);
    std::thread::sleep(Duration::from_millis(600));
    assert!(
        waiting.try_wait().unwrap().is_none(),
        "it should be waiting"
    );
    assert_eq!(fits_so_far(&db), 0);
    // The wait (2.5 s in all) is not fit time: the summary's time and rate, and the run's
    // stored time, count from when the lock was taken (6 fits take a fraction of a second).
    std::thread::sleep(Duration::from_millis(1900));
    db::release_run_lock(holder.conn(), &lock).unwrap();
    let out = waiting.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("waiting for another calibrate run"));
    let text = stdout(&out);
    assert!(text.starts_with("calibrate: 6 fitted"), "{text}");
    let seconds: f64 = text
        .split(", in ")
        .nth(1)
        .and_then(|t| t.split(" s").next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no time in {text}"));
    assert!(seconds < 1.5, "the wait was counted as fit time: {text}");
    let stored: f64 = Connection::open(&db)
        .unwrap()
        .query_row(
            "SELECT elapsed_s FROM runs ORDER BY id DESC LIMIT 1",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert!(stored < 1.5, "runs.elapsed_s {stored}");
}

#[test]
fn a_corrupt_or_foreign_database_is_refused_with_a_clear_message() {
    let tmp = tempfile::tempdir().unwrap();
    let net = synth(tmp.path(), 6, 16);

    let text = tmp.path().join("notes.sqlite");
    std::fs::write(&text, "these are my notes, not a database\n".repeat(50)).unwrap();
    let out = bin()
        .args(["calibrate", "--db", s(&text)])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("is not a pipewave database"),
        "{}",
        stderr(&out)
    );

    // A pipewave database whose pages after the header were overwritten.
    let db = tmp.path().join("damaged.sqlite");
    import(&db, &net);
    let mut bytes = std::fs::read(&db).unwrap();
    assert!(bytes.len() > 8192);
    for b in &mut bytes[4096..] {
        *b = 0xAB;
    }
    std::fs::write(&db, bytes).unwrap();
    let out = bin().args(["calibrate", "--db", s(&db)]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let msg = stderr(&out);
    assert!(msg.contains("damaged"), "{msg}");
    assert!(msg.contains("damaged.sqlite"), "{msg}");

    let out = bin()
        .args(["run", s(tmp.path()), "--db", s(&db)])
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(2),
        "no segments.csv in the directory"
    );
    assert!(
        stderr(&out).contains("segments.csv not found"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn run_does_everything_once_and_nothing_the_second_time() {
    let tmp = tempfile::tempdir().unwrap();
    let net = tmp.path().join("net");
    // 4 synthetic segments and the 2 published cases.
    run_ok(&[
        "synth",
        "--out",
        s(&net),
        "--segments",
        "4",
        "--seed",
        "17",
        "--defects",
        "0",
    ]);
    let first = bin()
        .args(["run", s(&net), "--jobs", "2"])
        .output()
        .unwrap();
    // Flagged fits are a success; only a failed fit makes the exit code 1.
    assert_eq!(first.status.code(), Some(0), "{}", stderr(&first));
    let out = stdout(&first);
    let lines: Vec<&str> = out.lines().collect();
    assert!(lines[0].starts_with("imported: segments 6 new"), "{out}");
    assert!(lines[1].starts_with("calibrate: 6 fitted"), "{out}");
    // The soil field learns from the six (model §7.12); every segment is measured.
    assert!(
        lines[2].starts_with("field: 0 segments predicted from 6 measured"),
        "{out}"
    );
    assert!(lines[3].starts_with("export: 6 segments -> "), "{out}");
    assert!(lines[3].ends_with("segments.gpkg"), "{out}");
    assert!(lines[4].ends_with("out/segments.csv"), "{out}");
    assert!(lines[5].starts_with("audit: 6 segments -> "), "{out}");
    for f in ["segments.gpkg", "segments.csv", "report.html"] {
        let p = net.join("out").join(f);
        assert!(
            std::fs::metadata(&p).unwrap().len() > 1000,
            "{}",
            p.display()
        );
    }
    let db = net.join("pipewave.sqlite");
    assert_eq!(count(&db, "SELECT count(*) FROM latest_fits"), 6);
    // The published cases were fitted like any other segment.
    assert_eq!(
        count(
            &db,
            "SELECT count(*) FROM fits WHERE segment_id IN ('LU2022-CI-DN125', \
             'MUGGLETON2004-MDPE') AND soil_youngs_modulus_pa > 0"
        ),
        2
    );
    assert_eq!(
        count(
            &db,
            "SELECT n_measurements FROM fits WHERE segment_id = 'MUGGLETON2004-MDPE'"
        ),
        13
    );

    let out = run_ok(&["run", s(&net)]);
    assert!(
        out.contains("segments 0 new, 0 updated, 6 unchanged"),
        "{out}"
    );
    assert!(out.contains("calibrate: 0 fitted"), "{out}");
    assert!(out.contains("6 up to date"), "{out}");
    assert!(out.contains("field: up to date"), "{out}");
    assert_eq!(count(&db, "SELECT count(*) FROM fits"), 6);
}

#[test]
fn synth_writes_a_network_that_imports_cleanly() {
    let tmp = tempfile::tempdir().unwrap();
    let net = tmp.path().join("net");
    let args = [
        "synth",
        "--out",
        s(&net),
        "--segments",
        "12",
        "--seed",
        "5",
        "--defects",
        "0.5",
    ];
    let out = run_ok(&args);
    assert!(
        out.starts_with("synth: wrote 14 segments (12 synthetic, "),
        "{out}"
    );
    let db = tmp.path().join("a.sqlite");
    let imported = run_ok(&[
        "import",
        "--db",
        s(&db),
        "--segments",
        s(&net.join("segments.csv")),
        "--measurements",
        s(&net.join("measurements.csv")),
    ]);
    assert!(imported.contains("segments 14 new"), "{imported}");
    assert_eq!(
        count(
            &db,
            "SELECT count(*) FROM segments WHERE geometry_wkt IS NOT NULL AND srid = 27700"
        ),
        12
    );
    // The cast-iron case is given in rad/s; the import derives Hz.
    assert_eq!(
        count(
            &db,
            "SELECT count(*) FROM measurements WHERE segment_id = 'LU2022-CI-DN125' AND \
             abs(frequency_hz * 6.283185307179586 - omega_rad_s) < 1e-9"
        ),
        4
    );
    let truth = pipewave::synth::network::read_truth(&net.join("truth.csv")).unwrap();
    assert_eq!(truth.len(), 14);
    assert!(truth.iter().filter(|t| t.defect.is_some()).count() >= 2);
    assert!(truth[12].soil_youngs_modulus_pa.is_none());
    // The published files are copied unchanged.
    for name in [
        "seed_cast_iron_table2.csv",
        "muggleton2004_buried_mdpe.csv",
        "README.md",
    ] {
        assert_eq!(
            std::fs::read(net.join("real").join(name)).unwrap(),
            std::fs::read(
                Path::new(env!("CARGO_MANIFEST_DIR"))
                    .join("tests/data/published")
                    .join(name)
            )
            .unwrap(),
            "{name}"
        );
    }
    // The files are not replaced without --force; with it, the same seed gives the same files.
    let before = std::fs::read(net.join("measurements.csv")).unwrap();
    let refused = bin().args(args).output().unwrap();
    assert_eq!(refused.status.code(), Some(2));
    assert!(stderr(&refused).contains("--force"));
    let mut forced = args.to_vec();
    forced.push("--force");
    run_ok(&forced);
    assert_eq!(std::fs::read(net.join("measurements.csv")).unwrap(), before);
}
