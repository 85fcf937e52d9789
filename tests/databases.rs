//! Which commands create a database and which need one (exit 2, nothing created), and what an
//! interrupted `calibrate --force` leaves for the next run. The real binary on temporary
//! databases, with a small synthetic network.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicBool, Ordering};

use pipewave::batch::{calibrate, CalibrateOptions, RunObserver, SegmentDone};
use pipewave::db::Database;
use rusqlite::Connection;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("run pipewave")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn ok(args: &[&str]) -> Output {
    let out = run(args);
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    out
}

fn synth(dir: &Path, n: usize) -> PathBuf {
    let net = dir.join("net");
    ok(&[
        "synth",
        "--out",
        s(&net),
        "--segments",
        &n.to_string(),
        "--seed",
        "5",
        "--defects",
        "0",
        "--no-real-cases",
    ]);
    net
}

fn import(db: &Path, net: &Path) {
    ok(&[
        "import",
        "--db",
        s(db),
        "--segments",
        s(&net.join("segments.csv")),
        "--measurements",
        s(&net.join("measurements.csv")),
    ]);
}

/// Every file in `dir`, by name.
fn files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn commands_other_than_import_and_run_need_an_existing_database() {
    let tmp = tempfile::tempdir().unwrap();
    let typo = tmp.path().join("typo.sqlite");
    let out = tmp.path().join("out");
    let t = s(&typo);
    let o = s(&out);
    let commands: [Vec<&str>; 4] = [
        vec!["calibrate", "--db", t],
        vec!["export", "--db", t, "--format", "csv", "--out", o],
        vec!["audit", "--db", t, "--out", o],
        vec!["diagnose", "--db", t, "--out", o],
    ];
    for args in &commands {
        let r = run(args);
        assert_eq!(r.status.code(), Some(2), "{args:?}: {}", stderr(&r));
        let e = stderr(&r);
        assert!(
            e.contains("no pipewave database at") && e.contains("nothing was created"),
            "{args:?}: {e}"
        );
        assert_eq!(e.lines().count(), 1, "one error line: {e}");
        assert!(
            files(tmp.path()).is_empty(),
            "{args:?} created {:?}",
            files(tmp.path())
        );
    }
    // An empty file (touched, never imported into) is not a pipewave database either, and is
    // left as it was.
    std::fs::write(&typo, b"").unwrap();
    for args in &commands {
        let r = run(args);
        assert_eq!(r.status.code(), Some(2), "{args:?}: {}", stderr(&r));
        assert!(stderr(&r).contains("it is empty"), "{}", stderr(&r));
        assert_eq!(files(tmp.path()), ["typo.sqlite"], "{args:?}");
        assert_eq!(std::fs::metadata(&typo).unwrap().len(), 0);
    }
}

#[test]
fn import_creates_and_diagnose_without_fits_is_one_error() {
    let tmp = tempfile::tempdir().unwrap();
    let net = synth(tmp.path(), 6);
    let db = tmp.path().join("new.sqlite");
    import(&db, &net);
    assert!(db.is_file());
    let out = tmp.path().join("diag");
    let r = run(&["diagnose", "--db", s(&db), "--out", s(&out)]);
    assert_eq!(r.status.code(), Some(2));
    let e = stderr(&r);
    assert_eq!(e.lines().count(), 1, "{e}");
    assert!(
        e.contains("nothing to diagnose") && e.contains("6 never fitted"),
        "{e}"
    );
    assert!(!out.exists(), "no report is written");
}

/// Stops the run once `after` fits are stored.
struct StopAfter<'a> {
    after: usize,
    done: usize,
    stop: &'a AtomicBool,
}

impl RunObserver for StopAfter<'_> {
    fn segment_done(&mut self, _: &SegmentDone<'_>) {
        self.done += 1;
        if self.done >= self.after {
            self.stop.store(true, Ordering::SeqCst);
        }
    }
}

#[test]
fn the_run_after_an_interrupted_forced_run_refits_the_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let net = synth(tmp.path(), 6);
    let db = tmp.path().join("a.sqlite");
    import(&db, &net);
    // Off a terminal (stderr piped, as under cron) progress comes as plain lines: here every
    // segment is more than 5 % of the run, so one line each.
    let first = ok(&["calibrate", "--db", s(&db), "--jobs", "1"]);
    let log = stderr(&first);
    assert!(
        log.contains("calibrate: fitting 6 segments (0 up to date) with 1 jobs"),
        "{log}"
    );
    let lines: Vec<&str> = log
        .lines()
        .filter(|l| l.starts_with("progress: "))
        .collect();
    assert_eq!(lines.len(), 6, "{log}");
    assert!(
        lines[5].starts_with("progress: 6/6 segments (100 %), ok "),
        "{log}"
    );
    let mut database = Database::open_existing(&db).unwrap();
    let stop = AtomicBool::new(false);
    let forced = CalibrateOptions {
        jobs: Some(1),
        force: true,
        ..CalibrateOptions::default()
    };
    let mut observer = StopAfter {
        after: 2,
        done: 0,
        stop: &stop,
    };
    let s1 = calibrate(database.conn_mut(), &forced, &mut observer, &stop).unwrap();
    assert!(s1.interrupted);
    let refitted = s1.stored();
    assert!((2..6).contains(&refitted), "{}", s1.line());
    assert!(
        s1.line().contains(&format!(
            "{} not fitted (the next run fits them)",
            6 - refitted
        )),
        "{}",
        s1.line()
    );
    // The next run, without --force, fits exactly the segments the forced run did not reach.
    let plain = CalibrateOptions {
        jobs: Some(1),
        ..CalibrateOptions::default()
    };
    let s2 = calibrate(
        database.conn_mut(),
        &plain,
        &mut (),
        &AtomicBool::new(false),
    )
    .unwrap();
    assert_eq!(
        (s2.stored(), s2.up_to_date),
        (6 - refitted, refitted),
        "{}",
        s2.line()
    );
    let conn = Connection::open(&db).unwrap();
    let per: Vec<i64> = conn
        .prepare("SELECT count(*) FROM fits GROUP BY segment_id")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(
        per,
        vec![2; 6],
        "every segment refitted once after its first fit"
    );
    let pending: i64 = conn
        .query_row("SELECT count(*) FROM forced_refits", [], |r| r.get(0))
        .unwrap();
    assert_eq!(pending, 0);
    // And then nothing is stale.
    let s3 = calibrate(
        database.conn_mut(),
        &plain,
        &mut (),
        &AtomicBool::new(false),
    )
    .unwrap();
    assert_eq!((s3.stored(), s3.up_to_date), (0, 6));
}
