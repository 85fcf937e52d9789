//! Defects 3, 4, 5, 7, 9, 10 and 13 of issue 62 (the command line: a closed stdout, a hang, a
//! crash, a wrong answer, raw control characters, unbounded errors, an unbounded thread count),
//! one test each, and the fuzz harness over every numeric option of every command.
//!
//! Every test runs the real binary on one small calibrated network made once per run of the
//! test binary ([`fixture`]); a test whose command writes to a database works on its own copy.

use std::path::{Path, PathBuf};
use std::process::{ExitStatus, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::common::cli::pipewave;

/// Longest any invocation may run before it counts as a hang and is killed.
const HANG: Duration = Duration::from_secs(60);

/// The shared network: `synth` 20 segments (half measured, two leak recordings, hydrant-test
/// recordings of WM10001), imported and calibrated.
struct Fixture {
    /// Kept for the test binary's life (its files are read by every test).
    _dir: tempfile::TempDir,
    net: PathBuf,
    db: PathBuf,
}

fn fixture() -> &'static Fixture {
    static FIXTURE: OnceLock<Fixture> = OnceLock::new();
    FIXTURE.get_or_init(|| {
        let dir = tempfile::Builder::new()
            .prefix("issue62-cli-")
            .tempdir_in(env!("CARGO_TARGET_TMPDIR"))
            .unwrap();
        let net = dir.path().join("net");
        let db = dir.path().join("a.sqlite");
        let s = |p: &Path| p.to_str().unwrap().to_string();
        for args in [
            vec![
                "synth".to_string(),
                "--out".into(),
                s(&net),
                "--segments".into(),
                "20".into(),
                "--seed".into(),
                "3".into(),
                "--measured-fraction".into(),
                "0.5".into(),
                "--no-real-cases".into(),
                "--leaks".into(),
                "2".into(),
                "--leak-seconds".into(),
                "1".into(),
                "--recordings".into(),
                "WM10001".into(),
                "--recording-seconds".into(),
                "6".into(),
            ],
            vec![
                "import".into(),
                "--db".into(),
                s(&db),
                "--segments".into(),
                s(&net.join("segments.csv")),
                "--measurements".into(),
                s(&net.join("measurements.csv")),
            ],
            vec![
                "calibrate".into(),
                "--db".into(),
                s(&db),
                "--jobs".into(),
                "2".into(),
            ],
        ] {
            let out = pipewave().args(&args).output().unwrap();
            assert!(
                out.status.success(),
                "{args:?}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        Fixture { _dir: dir, net, db }
    })
}

/// A copy of the fixture's database in `dir` (for commands that write to it).
fn db_copy(dir: &Path) -> PathBuf {
    let to = dir.join("copy.sqlite");
    std::fs::copy(&fixture().db, &to).unwrap();
    to
}

/// What one invocation did.
struct Run {
    status: Option<ExitStatus>,
    stdout: String,
    stderr: String,
    took: Duration,
}

impl Run {
    fn code(&self) -> Option<i32> {
        self.status.and_then(|s| s.code())
    }
    fn hung(&self) -> bool {
        self.status.is_none()
    }
}

/// Run `pipewave args…` with its output in files (a chatty command cannot block on a full
/// pipe), killed if it runs past [`HANG`].
fn run_in(scratch: &Path, args: &[String]) -> Run {
    let (o, e) = (scratch.join("stdout"), scratch.join("stderr"));
    let mut child = pipewave()
        .args(args)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&o).unwrap())
        .stderr(std::fs::File::create(&e).unwrap())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if start.elapsed() > HANG {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let took = start.elapsed();
    let read =
        |p: &Path| String::from_utf8_lossy(&std::fs::read(p).unwrap_or_default()).into_owned();
    Run {
        status,
        stdout: read(&o),
        stderr: read(&e),
        took,
    }
}

fn run(args: &[&str]) -> Run {
    let scratch = tempfile::tempdir().unwrap();
    run_in(
        scratch.path(),
        &args.iter().map(|s| s.to_string()).collect::<Vec<_>>(),
    )
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A single correlation on the fixture, `extra` appended.
fn locate_args<'a>(db: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec![
        "locate",
        "--db",
        db,
        "--sensor1",
        "WM10001:10",
        "--sensor2",
        "WM10002:20",
        "--delay",
        "0.001",
        "--delay-std",
        "0.0001",
    ];
    a.extend_from_slice(extra);
    a
}

/// A jobs file of a good row and the given one (its cells after job_id), both on the fixture.
fn jobs_file(dir: &Path, bad: &str) -> PathBuf {
    let f = dir.join("jobs.csv");
    std::fs::write(
        &f,
        format!(
            "job_id,sensor1_segment,sensor1_chainage_m,sensor2_segment,sensor2_chainage_m,\
             delay_s,delay_std_s,band_lo_hz,band_hi_hz,path\n\
             good,WM10001,10,WM10002,20,0.001,0.0001,,,\n\
             bad,{bad}\n"
        ),
    )
    .unwrap();
    f
}

/// `locate --input` on [`jobs_file`]: exit 1, the good row located, the bad one failed with
/// `why` in its message.
fn only_the_row_fails(bad: &str, why: &str) {
    let d = tempfile::tempdir().unwrap();
    let jobs = jobs_file(d.path(), bad);
    let out = d.path().join("located.csv");
    let r = run(&[
        "locate",
        "--db",
        p(&fixture().db),
        "--input",
        p(&jobs),
        "--out",
        p(&out),
    ]);
    assert!(!r.hung(), "locate --input with the row {bad} hung");
    assert_eq!(r.code(), Some(1), "{}{}", r.stdout, r.stderr);
    assert!(
        r.stdout.contains("1 of 2 jobs located, 1 failed"),
        "{}",
        r.stdout
    );
    assert!(
        r.stderr.contains("job bad:") && r.stderr.contains(why),
        "{}",
        r.stderr
    );
    let csv = std::fs::read_to_string(&out).unwrap();
    assert!(
        csv.lines().any(|l| l.starts_with("\"good\",\"ok\"")),
        "{csv}"
    );
}

/// `args` are refused with exit 2, `why` in the message, without a panic or a hang.
fn refused(args: &[&str], why: &str) {
    let r = run(args);
    assert!(!r.hung(), "{args:?} hung");
    assert_eq!(r.code(), Some(2), "{args:?}: {}{}", r.stdout, r.stderr);
    assert!(r.stderr.contains(why), "{args:?}: {}", r.stderr);
    assert!(!r.stderr.contains("panicked"), "{args:?}: {}", r.stderr);
}

#[test]
fn defect_03_a_closed_stdout_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let db = p(&fixture().db).to_string();
    // A pipe whose reader is gone before the command starts: its first write is refused.
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = pipewave()
        .args(locate_args(&db, &[]))
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("panicked") && !stderr.contains("Broken pipe"),
        "{stderr}"
    );
    // Ended as `cat` or `grep` end when their reader leaves: by SIGPIPE (141 in a shell).
    assert_eq!(out.status.signal(), Some(libc::SIGPIPE), "{:?}", out.status);
    assert!(stderr.is_empty(), "{stderr}");
}

#[test]
fn defect_04_a_narrow_band_is_refused_not_computed() {
    let db = p(&fixture().db).to_string();
    refused(
        &locate_args(&db, &["--band", "100,100.0000001"]),
        "at least 5 Hz wide",
    );
    refused(&locate_args(&db, &["--band", "100,30000"]), "≤ 20000 Hz");
    // In a jobs file, the row alone fails; the batch goes on.
    only_the_row_fails(
        "WM10001,10,WM10002,20,0.001,0.0001,100,100.0000001,",
        "at least 5 Hz wide",
    );
}

#[test]
fn defect_05_synth_refuses_what_it_cannot_make() {
    let d = tempfile::tempdir().unwrap();
    let out = p(d.path()).to_string();
    let base = ["synth", "--out", &out, "--segments", "5", "--no-real-cases"];
    let with = |extra: &[&'static str]| [&base[..], extra].concat();
    refused(
        &with(&["--units", "2", "--correlation-length", "5e-324"]),
        "outside 1 – 100000 m",
    );
    refused(
        &with(&["--leaks", "1", "--leak-seconds", "inf"]),
        "outside 1 – 600 s",
    );
    refused(
        &with(&["--leaks", "1", "--leak-seconds", "1e12"]),
        "outside 1 – 600 s",
    );
    refused(
        &with(&["--leaks", "1001", "--leak-seconds", "1"]),
        "1..=1000",
    );
    refused(&with(&["--leaks", "0"]), "1..=1000");
}

#[test]
fn defect_07_a_path_that_visits_a_segment_twice_is_refused() {
    let db = p(&fixture().db).to_string();
    refused(
        &locate_args(&db, &["--path", "WM10001,WM10002,WM10001,WM10002"]),
        "segment WM10001 is on the path twice",
    );
    // The path as it is, once each, is still located.
    let r = run(&locate_args(&db, &["--path", "WM10001,WM10002"]));
    assert_eq!(r.code(), Some(0), "{}", r.stderr);
    assert!(r.stdout.contains("span 130.0 m"), "{}", r.stdout);
    only_the_row_fails(
        "WM10001,10,WM10002,20,0.001,0.0001,,,WM10001;WM10002;WM10001;WM10002",
        "is on the path twice",
    );
}

/// No control character but the line ends.
fn no_controls(what: &str, text: &str) {
    assert!(
        !text.chars().any(|c| c.is_control() && c != '\n'),
        "{what} prints raw control characters: {text:?}"
    );
}

#[test]
fn defect_09_locate_escapes_control_characters_of_ids() {
    let d = tempfile::tempdir().unwrap();
    let evil = "W\u{1b}[31mX";
    let f = fixture();
    for name in ["segments.csv", "measurements.csv"] {
        let text = std::fs::read_to_string(f.net.join(name)).unwrap();
        std::fs::write(d.path().join(name), text.replace("WM10001", evil)).unwrap();
    }
    let db = d.path().join("cc.sqlite");
    for args in [
        vec![
            "import",
            "--db",
            p(&db),
            "--segments",
            p(&d.path().join("segments.csv")),
            "--measurements",
            p(&d.path().join("measurements.csv")),
        ],
        vec!["calibrate", "--db", p(&db), "--jobs", "1"],
    ] {
        let r = run(&args);
        assert_eq!(r.code(), Some(0), "{args:?}: {}", r.stderr);
    }
    let sensor = format!("{evil}:10");
    let r = run(&[
        "locate",
        "--db",
        p(&db),
        "--sensor1",
        &sensor,
        "--sensor2",
        "WM10002:20",
        "--delay",
        "0.001",
        "--delay-std",
        "0.0001",
    ]);
    assert_eq!(r.code(), Some(0), "{}", r.stderr);
    assert!(r.stdout.contains(r"W\u{1b}[31mX"), "{}", r.stdout);
    no_controls("locate", &r.stdout);
    // A jobs file: an id of a job that fails, and a segment id, both echoed.
    let jobs = d.path().join("jobs.csv");
    std::fs::write(
        &jobs,
        format!(
            "job_id,sensor1_segment,sensor1_chainage_m,sensor2_segment,sensor2_chainage_m,\
             delay_s,delay_std_s\n\
             \"j\u{1b}]0;title\u{7}\",{evil},10,WM10002,20,5,0.0001\n\
             ok,{evil},10,WM10002,20,0.001,0.0001\n"
        ),
    )
    .unwrap();
    let out = d.path().join("located.csv");
    let r = run(&[
        "locate",
        "--db",
        p(&db),
        "--input",
        p(&jobs),
        "--out",
        p(&out),
    ]);
    assert_eq!(r.code(), Some(1), "{}{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains(r"job j\u{1b}]0;title\u{7}:"),
        "{}",
        r.stderr
    );
    no_controls("locate --input (stderr)", &r.stderr);
    no_controls("locate --input (stdout)", &r.stdout);
}

#[test]
fn defect_10_error_sizes_are_bounded() {
    let db = p(&fixture().db).to_string();
    for f in ["1e308", "1e150", "0.6", "inf", "nan"] {
        refused(
            &locate_args(&db, &["--span-std-fraction", f]),
            "for '--span-std-fraction <F>'",
        );
    }
    let with_delay_std = |s: &'static str| {
        let mut a = locate_args(&db, &[]);
        let i = a.iter().position(|x| *x == "--delay-std").unwrap();
        a[i + 1] = s;
        a
    };
    refused(&with_delay_std("1e308"), "outside 0 – 10 s");
    // At the ends of the ranges the interval is finite and printed in metres.
    let mut ends = with_delay_std("10");
    ends.extend(["--span-std-fraction", "0.5"]);
    let r = run(&ends);
    assert_eq!(r.code(), Some(0), "{}", r.stderr);
    assert!(!r.stdout.contains("inf"), "{}", r.stdout);
    // A jobs row with such an error fails alone.
    only_the_row_fails(
        "WM10001,10,WM10002,20,0.001,1e308,,,",
        "an error of 0 – 10 s",
    );
}

#[test]
fn defect_13_plan_bounds_its_threads_as_calibrate_does() {
    let d = tempfile::tempdir().unwrap();
    let db = db_copy(d.path());
    let out = d.path().join("next.csv");
    let plan = |jobs: &'static str| {
        vec![
            "plan".to_string(),
            "--db".into(),
            p(&db).into(),
            "--count".into(),
            "2".into(),
            "--out".into(),
            p(&out).into(),
            "--jobs".into(),
            jobs.into(),
        ]
    };
    let calibrate = |jobs: &'static str| {
        vec![
            "calibrate".to_string(),
            "--db".into(),
            p(&db).into(),
            "--jobs".into(),
            jobs.into(),
        ]
    };
    // 513 first: the old code ran plan with any number of threads, and 100000 of them take
    // the machine for minutes.
    for jobs in ["513", "0", "100000"] {
        for args in [plan(jobs), calibrate(jobs)] {
            let r = run_in(d.path(), &args);
            assert_eq!(r.code(), Some(2), "{args:?}: {}", r.stderr);
            assert!(
                r.stderr.contains("is not in 1..=512"),
                "{args:?}: {}",
                r.stderr
            );
        }
    }
    for args in [plan("512"), calibrate("512")] {
        let r = run_in(d.path(), &args);
        assert_eq!(r.code(), Some(0), "{args:?}: {}", r.stderr);
    }
}

/// How a fuzzed value is put on the command line.
#[derive(Debug, Clone, Copy)]
enum Shape {
    /// The value itself.
    Plain,
    /// `LO,HI`: the value and another of the list.
    Pair,
    /// `WM10001:VALUE` (a chainage) or `VALUE,VALUE` (map coordinates), alternately.
    Sensor,
    /// `FILE:VALUE` (a channel).
    Channel,
}

/// One numeric option of one command, with the other arguments it needs (small counts).
struct Target {
    command: &'static str,
    option: &'static str,
    shape: Shape,
    /// Options whose work grows with their value by design (a network's size, a number of
    /// recordings): an in-range value above this is replaced by it, so one invocation stays
    /// small; values out of range and malformed ones are passed as they are.
    cheap_ceiling: Option<f64>,
    /// The other arguments; `{db}`, `{net}` and `{tmp}` are replaced.
    rest: &'static [&'static str],
}

const fn t(
    command: &'static str,
    option: &'static str,
    shape: Shape,
    cheap_ceiling: Option<f64>,
    rest: &'static [&'static str],
) -> Target {
    Target {
        command,
        option,
        shape,
        cheap_ceiling,
        rest,
    }
}

const LOCATE: &[&str] = &[
    "--db",
    "{db}",
    "--sensor1",
    "WM10001:10",
    "--sensor2",
    "WM10002:20",
    "--delay",
    "0.001",
    "--delay-std",
    "0.0001",
];
const LOCATE_SENSOR1: &[&str] = &[
    "--db",
    "{db}",
    "--sensor2",
    "WM10002:20",
    "--delay",
    "0.001",
    "--delay-std",
    "0.0001",
];
const LOCATE_SENSOR2: &[&str] = &[
    "--db",
    "{db}",
    "--sensor1",
    "WM10001:10",
    "--delay",
    "0.001",
    "--delay-std",
    "0.0001",
];
const LOCATE_DELAY: &[&str] = &[
    "--db",
    "{db}",
    "--sensor1",
    "WM10001:10",
    "--sensor2",
    "WM10002:20",
    "--delay-std",
    "0.0001",
];
const LOCATE_DELAY_STD: &[&str] = &[
    "--db",
    "{db}",
    "--sensor1",
    "WM10001:10",
    "--sensor2",
    "WM10002:20",
    "--delay",
    "0.001",
];
const LOCATE_RECORDINGS: &[&str] = &[
    "--db",
    "{db}",
    "--sensor1",
    "WM10005:63.41",
    "--sensor2",
    "WM10005:105.79",
    "--recording2",
    "{net}/leaks/L001.wav:1",
];
const LOCATE_RECORDING2: &[&str] = &[
    "--db",
    "{db}",
    "--sensor1",
    "WM10005:63.41",
    "--sensor2",
    "WM10005:105.79",
    "--recording1",
    "{net}/leaks/L001.wav:0",
];
const LOCATE_JOBS: &[&str] = &[
    "--db",
    "{db}",
    "--input",
    "{net}/leaks/jobs.csv",
    "--out",
    "{tmp}/located.csv",
];
const SYNTH: &[&str] = &["--out", "{tmp}/synth", "--force", "--no-real-cases"];
const SYNTH_20: &[&str] = &[
    "--out",
    "{tmp}/synth",
    "--force",
    "--no-real-cases",
    "--segments",
    "20",
];
const BENCH: &[&str] = &["--calibrate", "2", "--jobs", "1"];
const WAVENUMBERS: &[&str] = &[
    "--layout",
    "{net}/recordings/layout.csv",
    "--out",
    "{tmp}/measurements.csv",
];
const PLAN: &[&str] = &["--db", "{db}", "--out", "{tmp}/next.csv"];
const FIT: &[&str] = &[
    "--segments",
    "{net}/segments.csv",
    "--measurements",
    "{net}/measurements.csv",
    "--out",
    "{tmp}/fits.csv",
];

/// Every numeric option of every command (their clap definitions in src/cli/*.rs);
/// [`the_fuzz_targets_name_every_numeric_option`] checks the list against `--help`.
const TARGETS: &[Target] = &[
    t(
        "run",
        "--jobs",
        Shape::Plain,
        None,
        &["{net}", "--db", "{db}"],
    ),
    t(
        "run",
        "--seed",
        Shape::Plain,
        None,
        &["{net}", "--db", "{db}", "--jobs", "1"],
    ),
    t(
        "import",
        "--srid",
        Shape::Plain,
        None,
        &["--db", "{db}", "--segments", "{net}/segments.csv"],
    ),
    t(
        "calibrate",
        "--jobs",
        Shape::Plain,
        None,
        &["--db", "{db}", "--force"],
    ),
    t(
        "calibrate",
        "--seed",
        Shape::Plain,
        None,
        &["--db", "{db}", "--jobs", "1"],
    ),
    t("synth", "--segments", Shape::Plain, Some(300.0), SYNTH),
    t("synth", "--seed", Shape::Plain, None, SYNTH_20),
    t("synth", "--defects", Shape::Plain, None, SYNTH_20),
    t(
        "synth",
        "--hidden-range",
        Shape::Pair,
        None,
        &[
            "--out",
            "{tmp}/synth",
            "--force",
            "--no-real-cases",
            "--segments",
            "20",
            "--hidden-effect",
            "soil_damping",
        ],
    ),
    t(
        "synth",
        "--hidden-fraction",
        Shape::Plain,
        None,
        &[
            "--out",
            "{tmp}/synth",
            "--force",
            "--no-real-cases",
            "--segments",
            "20",
            "--hidden-effect",
            "air_in_water",
        ],
    ),
    t(
        "synth",
        "--recording-seconds",
        Shape::Plain,
        None,
        &[
            "--out",
            "{tmp}/synth",
            "--force",
            "--no-real-cases",
            "--segments",
            "3",
            "--recordings",
            "WM10001",
            "--recordings-only",
        ],
    ),
    t("synth", "--zones", Shape::Plain, None, SYNTH_20),
    t(
        "synth",
        "--leaks",
        Shape::Plain,
        Some(20.0),
        &[
            "--out",
            "{tmp}/synth",
            "--force",
            "--no-real-cases",
            "--segments",
            "20",
            "--leak-seconds",
            "1",
        ],
    ),
    t(
        "synth",
        "--leak-seconds",
        Shape::Plain,
        None,
        &[
            "--out",
            "{tmp}/synth",
            "--force",
            "--no-real-cases",
            "--segments",
            "20",
            "--leaks",
            "1",
        ],
    ),
    t("synth", "--units", Shape::Plain, None, SYNTH_20),
    t(
        "synth",
        "--correlation-length",
        Shape::Plain,
        None,
        &[
            "--out",
            "{tmp}/synth",
            "--force",
            "--no-real-cases",
            "--segments",
            "20",
            "--units",
            "2",
        ],
    ),
    t("synth", "--measured-fraction", Shape::Plain, None, SYNTH_20),
    t("synth", "--wrong-labels", Shape::Plain, None, SYNTH_20),
    t("synth", "--campaigns", Shape::Plain, None, SYNTH_20),
    t(
        "synth",
        "--changed-fraction",
        Shape::Plain,
        None,
        &[
            "--out",
            "{tmp}/synth",
            "--force",
            "--no-real-cases",
            "--segments",
            "20",
            "--campaigns",
            "2",
        ],
    ),
    t("bench", "--scale", Shape::Plain, None, BENCH),
    t("bench", "--fits", Shape::Plain, None, BENCH),
    t(
        "bench",
        "--calibrate",
        Shape::Plain,
        Some(3.0),
        &["--jobs", "1"],
    ),
    t(
        "bench",
        "--staleness",
        Shape::Plain,
        Some(1000.0),
        &["--fits", "0", "--scale", "0", "--network", "0"],
    ),
    t("bench", "--network", Shape::Plain, None, BENCH),
    t("bench", "--network-seed", Shape::Plain, None, BENCH),
    t(
        "bench",
        "--verify",
        Shape::Plain,
        Some(1.0),
        &["--jobs", "1"],
    ),
    t("bench", "--jobs", Shape::Plain, None, &["--calibrate", "2"]),
    t("bench", "--seed", Shape::Plain, None, BENCH),
    t(
        "diagnose",
        "--jobs",
        Shape::Plain,
        None,
        &["--db", "{db}", "--out", "{tmp}/diagnosis", "--no-apply"],
    ),
    t("fit", "--jobs", Shape::Plain, None, FIT),
    t("fit", "--seed", Shape::Plain, None, FIT),
    t("wavenumbers", "--band-hz", Shape::Plain, None, WAVENUMBERS),
    t(
        "wavenumbers",
        "--min-coherence",
        Shape::Plain,
        None,
        WAVENUMBERS,
    ),
    t("wavenumbers", "--fmin", Shape::Plain, None, WAVENUMBERS),
    t("wavenumbers", "--fmax", Shape::Plain, None, WAVENUMBERS),
    t("plan", "--count", Shape::Plain, None, PLAN),
    t(
        "plan",
        "--jobs",
        Shape::Plain,
        None,
        &["--db", "{db}", "--out", "{tmp}/next.csv", "--count", "2"],
    ),
    t("locate", "--sensor1", Shape::Sensor, None, LOCATE_SENSOR1),
    t("locate", "--sensor2", Shape::Sensor, None, LOCATE_SENSOR2),
    t("locate", "--delay", Shape::Plain, None, LOCATE_DELAY),
    t(
        "locate",
        "--delay-std",
        Shape::Plain,
        None,
        LOCATE_DELAY_STD,
    ),
    t(
        "locate",
        "--recording1",
        Shape::Channel,
        None,
        LOCATE_RECORDINGS,
    ),
    t(
        "locate",
        "--recording2",
        Shape::Channel,
        None,
        LOCATE_RECORDING2,
    ),
    t("locate", "--band", Shape::Pair, None, LOCATE),
    t("locate", "--band", Shape::Pair, None, LOCATE_JOBS),
    t("locate", "--jobs", Shape::Plain, None, LOCATE_JOBS),
    t("locate", "--snap-tolerance", Shape::Plain, None, LOCATE),
    t("locate", "--join-tolerance", Shape::Plain, None, LOCATE),
    t("locate", "--span-std-fraction", Shape::Plain, None, LOCATE),
];

/// The values every option is tried with first: zeros, signs, the subnormals, the largest
/// doubles and integers, the non-numbers, fractions, and the edges of the ranges.
const SPECIAL: &[&str] = &[
    "0",
    "-0",
    "-1",
    "1e-324",
    "5e-324",
    "1e308",
    "-1e308",
    "inf",
    "-inf",
    "nan",
    "9223372036854775808",
    "18446744073709551616",
    "340282366920938463463374607431768211457",
    "0.5",
    "1.5",
    "-0.5",
    "1e-9",
    "4294967296",
    "65536",
    "513",
    "1000001",
    "1",
    "2",
    "100",
    "601",
    "20000",
    "",
    "1e",
    "0x10",
];

/// A random value: a real with a random exponent and sign, or an integer of random size.
fn random_value(rng: &mut ChaCha8Rng) -> String {
    match rng.gen_range(0..4) {
        0 => {
            let e: f64 = rng.gen_range(-40.0..40.0);
            let sign = if rng.gen_bool(0.2) { -1.0 } else { 1.0 };
            format!("{}", sign * 10f64.powf(e))
        }
        1 => format!("{}", rng.gen_range(-2.0..2.0f64)),
        2 => format!("{}", rng.gen::<u64>() >> rng.gen_range(0..64)),
        _ => format!("{}", rng.gen_range(0..1500u32)),
    }
}

/// A value for the option of `target`, within its cheap ceiling.
fn cheap(target: &Target, v: String) -> String {
    match (target.cheap_ceiling, v.trim().parse::<f64>()) {
        (Some(c), Ok(x)) if x > c && x <= 1e6 && x.fract() == 0.0 => format!("{c}"),
        _ => v,
    }
}

/// The `case`-th invocation of the fuzz: the targets in turn, each trying the special values
/// (staggered, so a short run still tries every value on some option) and then random ones.
fn fuzz_case(case: usize, rng: &mut ChaCha8Rng, dirs: (&str, &str, &str)) -> Vec<String> {
    let (db, net, tmp) = dirs;
    let ti = case % TARGETS.len();
    let round = case / TARGETS.len();
    let target = &TARGETS[ti];
    let mut value = |k: usize| -> String {
        if round < SPECIAL.len() {
            SPECIAL[(round + 7 * ti + k) % SPECIAL.len()].to_string()
        } else {
            random_value(rng)
        }
    };
    let v = value(0);
    let value_text = match target.shape {
        Shape::Plain => cheap(target, v),
        Shape::Pair => format!("{v},{}", value(3)),
        Shape::Sensor if round % 2 == 0 => format!("WM10001:{v}"),
        Shape::Sensor => format!("{v},{}", value(5)),
        Shape::Channel => format!("{net}/leaks/L001.wav:{v}"),
    };
    let mut args = vec![target.command.to_string()];
    args.extend(target.rest.iter().map(|a| {
        a.replace("{db}", db)
            .replace("{net}", net)
            .replace("{tmp}", tmp)
    }));
    // `--option=VALUE`, so a value that begins with '-' is read as the value.
    args.push(format!("{}={value_text}", target.option));
    args
}

/// Run `cases` fuzz invocations; return the failures (a panic, an abort, a signal, an exit code
/// other than 0, 1 and 2, or a run past [`HANG`]) and the longest run.
fn fuzz(cases: usize, seed: u64) -> (Vec<String>, Duration, [usize; 3]) {
    let f = fixture();
    let work = tempfile::tempdir().unwrap();
    let db = db_copy(work.path());
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut failures = Vec::new();
    let mut longest = (Duration::ZERO, String::new());
    let mut codes = [0usize; 3];
    for case in 0..cases {
        let args = fuzz_case(case, &mut rng, (p(&db), p(&f.net), p(work.path())));
        let r = run_in(work.path(), &args);
        if r.took > longest.0 {
            longest = (r.took, format!("{args:?}"));
        }
        let bad = match r.code() {
            _ if r.hung() => Some(format!("ran past {} s", HANG.as_secs())),
            Some(c @ 0..=2) => {
                codes[c as usize] += 1;
                r.stderr
                    .contains("panicked")
                    .then(|| "panicked".to_string())
            }
            Some(c) => Some(format!("exit {c}")),
            None => Some(format!("{:?}", r.status)),
        };
        if let Some(why) = bad {
            let tail: String = r
                .stderr
                .chars()
                .rev()
                .take(400)
                .collect::<Vec<_>>()
                .into_iter()
                .rev()
                .collect();
            failures.push(format!("case {case} {args:?}: {why}\n{tail}"));
        }
    }
    eprintln!(
        "fuzz: {cases} cases, seed {seed}; exits 0/1/2: {codes:?}; {} failures; longest {:.2} s: {}",
        failures.len(),
        longest.0.as_secs_f64(),
        longest.1
    );
    (failures, longest.0, codes)
}

/// Every numeric option of every command: no panic (101), no abort (134), no other signal or
/// exit code, nothing past a minute. `PIPEWAVE_FUZZ_CASES` sets the number of invocations (200
/// here), `PIPEWAVE_FUZZ_SEED` the seed of the random values.
#[test]
fn fuzz_every_numeric_option_of_every_command() {
    let cases = std::env::var("PIPEWAVE_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200);
    let seed = std::env::var("PIPEWAVE_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(62);
    let (failures, _, codes) = fuzz(cases, seed);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    // The harness reached the commands: some values ran them, some were refused.
    assert!(codes[0] > 0 && codes[2] > 0, "{codes:?}");
}

/// The options `--help` lists with a numeric value, by command.
fn numeric_options(command: &str) -> Vec<String> {
    let out = pipewave().args([command, "--help"]).output().unwrap();
    let help = String::from_utf8(out.stdout).unwrap();
    let numeric = [
        "<N>",
        "<S>",
        "<M>",
        "<F>",
        "<FRACTION>",
        "<W>",
        "<C>",
        "<HZ>",
        "<LO,HI>",
        "<ID:M | X,Y>",
        "<FILE[:CH]>",
    ];
    help.lines()
        .filter_map(|l| {
            let l = l.trim_start();
            let name = l.split([' ', '=']).find(|w| w.starts_with("--"))?;
            numeric
                .iter()
                .any(|v| l.contains(&format!("{name} {v}")))
                .then(|| name.to_string())
        })
        .collect()
}

#[test]
fn the_fuzz_targets_name_every_numeric_option() {
    let commands = [
        "run",
        "import",
        "calibrate",
        "synth",
        "forward",
        "bench",
        "export",
        "audit",
        "diagnose",
        "fit",
        "wavenumbers",
        "plan",
        "locate",
    ];
    for c in commands {
        for o in numeric_options(c) {
            assert!(
                TARGETS.iter().any(|t| t.command == c && t.option == o),
                "{c} {o} takes a number but the fuzz does not try it"
            );
        }
    }
    assert!(numeric_options("locate").contains(&"--span-std-fraction".to_string()));
}

/// Every numeric option's `--help` states its range.
#[test]
fn every_numeric_option_states_its_range() {
    for t in TARGETS {
        let out = pipewave().args([t.command, "--help"]).output().unwrap();
        let help = String::from_utf8(out.stdout).unwrap();
        let options = help.find("Options:").unwrap();
        let start = help[options..]
            .find(&format!("{} <", t.option))
            .map(|i| options + i)
            .unwrap_or_else(|| panic!("{} {} not in --help", t.command, t.option));
        // The option's block: up to the next line that starts another option.
        let rest = &help[start..];
        let end = rest
            .match_indices('\n')
            .map(|(i, _)| i)
            .find(|&i| {
                let line = &rest[i + 1..];
                let indent = line.len() - line.trim_start().len();
                line.trim_start().starts_with('-') && indent <= 6
            })
            .unwrap_or(rest.len());
        let text = &rest[..end];
        assert!(
            text.contains("Range")
                || text.contains(" - ")
                || text.contains(" – ")
                || text.contains("≤"),
            "{} {}: no range in its help: {text}",
            t.command,
            t.option
        );
    }
}
