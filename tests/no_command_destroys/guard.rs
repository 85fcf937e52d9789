//! Defects 1, 8, 11 and 12: what a command writes never replaces what it was given, and the
//! property test over every command and option that writes a file.

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::OnceLock;

use crate::common::cli::{ok, pipewave};

/// A small calibrated network shared by the tests of this module: `net/` (synth, half the
/// segments measured), its database `a.sqlite`, a second pipewave database `b.sqlite`, a plain
/// SQLite database `c.sqlite`, a read-only file, a jobs file, a forward input, and recordings.
struct World {
    _dir: tempfile::TempDir,
    root: PathBuf,
}

impl World {
    fn p(&self, rel: &str) -> PathBuf {
        self.root.join(rel)
    }
    fn s(&self, rel: &str) -> String {
        self.p(rel).to_str().unwrap().to_string()
    }
}

fn world() -> &'static World {
    static W: OnceLock<World> = OnceLock::new();
    W.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().to_path_buf();
        let w = World { _dir: dir, root };
        ok(&[
            "synth",
            "--out",
            &w.s("net"),
            "--segments",
            "12",
            "--seed",
            "3",
            "--measured-fraction",
            "0.5",
            "--no-real-cases",
        ]);
        for db in ["a.sqlite", "b.sqlite"] {
            ok(&[
                "import",
                "--db",
                &w.s(db),
                "--segments",
                &w.s("net/segments.csv"),
                "--measurements",
                &w.s("net/measurements.csv"),
            ]);
        }
        ok(&["calibrate", "--db", &w.s("a.sqlite"), "--jobs", "2"]);
        let c = rusqlite::Connection::open(w.p("c.sqlite")).unwrap();
        c.execute_batch("CREATE TABLE notes (x TEXT); INSERT INTO notes VALUES ('keep');")
            .unwrap();
        drop(c);
        std::fs::write(w.p("readonly.csv"), "a read-only file\n").unwrap();
        std::fs::set_permissions(w.p("readonly.csv"), std::fs::Permissions::from_mode(0o444))
            .unwrap();
        std::fs::write(
            w.p("jobs.csv"),
            "job_id,sensor1_segment,sensor1_chainage_m,sensor2_segment,sensor2_chainage_m,delay_s,delay_std_s\n\
             j1,WM10001,1,WM10001,20,0.001,1e-4\n",
        )
        .unwrap();
        std::fs::write(
            w.p("cases.csv"),
            "case_id,omega_rad_s,fluid_density_kg_m3,fluid_bulk_modulus_pa,pipe_youngs_modulus_pa,\
             pipe_poisson,pipe_density_kg_m3,pipe_loss_factor,mean_radius_m,wall_thickness_m,\
             soil_youngs_modulus_pa,soil_poisson,soil_density_kg_m3,soil_loss_factor,contact,\
             model,contact_mode\n\
             good,3121.958,1000,2.25e9,1.22e11,0.25,7800,0.01,0.069,0.006,4.79e7,0.3326,1999,0,0,full,reciprocal\n",
        )
        .unwrap();
        ok(&[
            "synth",
            "--out",
            &w.s("rec"),
            "--segments",
            "2",
            "--recordings",
            "WM10001",
            "--recordings-only",
        ]);
        w
    })
}

/// The files no command may change, with their bytes now.
fn snapshot(files: &[PathBuf]) -> Vec<(PathBuf, Vec<u8>)> {
    files
        .iter()
        .map(|p| (p.clone(), std::fs::read(p).unwrap()))
        .collect()
}

fn protected_files(w: &World) -> Vec<PathBuf> {
    [
        "a.sqlite",
        "b.sqlite",
        "c.sqlite",
        "readonly.csv",
        "jobs.csv",
        "cases.csv",
        "net/segments.csv",
        "net/measurements.csv",
        "rec/recordings/layout.csv",
        "rec/recordings/WM10001.wav",
    ]
    .iter()
    .map(|r| w.p(r))
    .collect()
}

/// One writing option of one command: the arguments with `{OUT}` where the output goes, the
/// path of the file that `{OUT}` makes the command write (the option's value itself, or a file
/// inside the directory it names), and the command's own input (its database where it reads
/// no other file: `synth` reads none).
struct Case {
    name: &'static str,
    args: Vec<String>,
    /// Where the command writes, relative to `{OUT}`: "" for a file option, a file name for a
    /// directory option.
    file_in_out: &'static str,
    input: &'static str,
}

fn cases(w: &World) -> Vec<Case> {
    let a = w.s("a.sqlite");
    let v = |xs: &[&str]| xs.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    vec![
        Case {
            name: "export --format csv --out",
            args: v(&["export", "--db", &a, "--format", "csv", "--out", "{OUT}"]),
            file_in_out: "",
            input: "a.sqlite",
        },
        Case {
            name: "export --format geojson --out",
            args: v(&[
                "export", "--db", &a, "--format", "geojson", "--out", "{OUT}",
            ]),
            file_in_out: "",
            input: "a.sqlite",
        },
        Case {
            name: "export --format gpkg --out",
            args: v(&["export", "--db", &a, "--format", "gpkg", "--out", "{OUT}"]),
            file_in_out: "",
            input: "a.sqlite",
        },
        Case {
            name: "audit --out",
            args: v(&["audit", "--db", &a, "--out", "{OUT}"]),
            file_in_out: "",
            input: "a.sqlite",
        },
        Case {
            name: "plan --out",
            args: v(&["plan", "--db", &a, "--count", "1", "--out", "{OUT}"]),
            file_in_out: "",
            input: "a.sqlite",
        },
        Case {
            name: "locate --out",
            args: v(&[
                "locate",
                "--db",
                &a,
                "--jobs",
                &w.s("jobs.csv"),
                "--out",
                "{OUT}",
            ]),
            file_in_out: "",
            input: "jobs.csv",
        },
        Case {
            name: "locate --geojson",
            args: v(&[
                "locate",
                "--db",
                &a,
                "--jobs",
                &w.s("jobs.csv"),
                "--out",
                &w.s("fresh-located.csv"),
                "--geojson",
                "{OUT}",
            ]),
            file_in_out: "",
            input: "jobs.csv",
        },
        Case {
            name: "locate --gpkg",
            args: v(&[
                "locate",
                "--db",
                &a,
                "--jobs",
                &w.s("jobs.csv"),
                "--out",
                &w.s("fresh-located.csv"),
                "--gpkg",
                "{OUT}",
            ]),
            file_in_out: "",
            input: "jobs.csv",
        },
        Case {
            name: "locate (one correlation) --geojson",
            args: v(&[
                "locate",
                "--db",
                &a,
                "--sensor1",
                "WM10001:1",
                "--sensor2",
                "WM10001:20",
                "--delay",
                "0.001",
                "--delay-std",
                "1e-4",
                "--geojson",
                "{OUT}",
            ]),
            file_in_out: "",
            input: "a.sqlite",
        },
        Case {
            name: "forward --output",
            args: v(&["forward", "--input", &w.s("cases.csv"), "--output", "{OUT}"]),
            file_in_out: "",
            input: "cases.csv",
        },
        Case {
            name: "forward --out",
            args: v(&["forward", "--input", &w.s("cases.csv"), "--out", "{OUT}"]),
            file_in_out: "",
            input: "cases.csv",
        },
        Case {
            name: "wavenumbers --out",
            args: v(&[
                "wavenumbers",
                "--layout",
                &w.s("rec/recordings/layout.csv"),
                "--out",
                "{OUT}",
            ]),
            file_in_out: "",
            input: "rec/recordings/layout.csv",
        },
        Case {
            name: "wavenumbers --out (a recording)",
            args: v(&[
                "wavenumbers",
                "--layout",
                &w.s("rec/recordings/layout.csv"),
                "--out",
                "{OUT}",
            ]),
            file_in_out: "",
            input: "rec/recordings/WM10001.wav",
        },
        Case {
            name: "fit --out",
            args: v(&[
                "fit",
                "--segments",
                &w.s("net/segments.csv"),
                "--measurements",
                &w.s("net/measurements.csv"),
                "--out",
                "{OUT}",
            ]),
            file_in_out: "",
            input: "net/segments.csv",
        },
        Case {
            name: "synth --campaign-out",
            args: v(&[
                "synth",
                "--out",
                &w.s("fresh-synth"),
                "--segments",
                "2",
                "--no-real-cases",
                "--campaign-out",
                "{OUT}",
            ]),
            file_in_out: "",
            input: "a.sqlite",
        },
        Case {
            name: "synth --out (segments.csv)",
            args: v(&[
                "synth",
                "--out",
                "{OUT}",
                "--segments",
                "2",
                "--no-real-cases",
                "--force",
            ]),
            file_in_out: "segments.csv",
            input: "a.sqlite",
        },
        Case {
            name: "synth --out (truth.csv)",
            args: v(&[
                "synth",
                "--out",
                "{OUT}",
                "--segments",
                "2",
                "--no-real-cases",
                "--force",
            ]),
            file_in_out: "truth.csv",
            input: "a.sqlite",
        },
        Case {
            name: "diagnose --out (diagnosis.csv)",
            args: v(&["diagnose", "--db", &a, "--out", "{OUT}"]),
            file_in_out: "diagnosis.csv",
            input: "a.sqlite",
        },
        Case {
            name: "diagnose --out (diagnosis.html)",
            args: v(&["diagnose", "--db", &a, "--out", "{OUT}"]),
            file_in_out: "diagnosis.html",
            input: "a.sqlite",
        },
        Case {
            name: "run DIR (out/segments.csv)",
            args: v(&["run", "{OUT}", "--db", &w.s("b.sqlite")]),
            file_in_out: "out/segments.csv",
            input: "net/segments.csv",
        },
        Case {
            name: "run DIR (out/segments.gpkg)",
            args: v(&["run", "{OUT}", "--db", &w.s("b.sqlite")]),
            file_in_out: "out/segments.gpkg",
            input: "net/segments.csv",
        },
        Case {
            name: "run DIR (out/report.html)",
            args: v(&["run", "{OUT}", "--db", &w.s("b.sqlite")]),
            file_in_out: "out/report.html",
            input: "net/segments.csv",
        },
    ]
}

fn run_case(case: &Case, out: &Path) -> Output {
    let args: Vec<String> = case
        .args
        .iter()
        .map(|a| a.replace("{OUT}", out.to_str().unwrap()))
        .collect();
    pipewave().args(&args).output().unwrap()
}

/// Make the place the command writes (`file_in_out` under a fresh `{OUT}`) lead to `target`,
/// by a symlink, and return the `{OUT}` value. For a file option `{OUT}` is `target` itself
/// unless `via_link` asks for a link to it. A directory option gets a fresh directory whose
/// file is a link to `target` (with the network's inputs beside it for `run`).
fn place(w: &World, case: &Case, target: &Path, via_link: bool, k: usize) -> PathBuf {
    if case.file_in_out.is_empty() {
        if !via_link {
            return target.to_path_buf();
        }
        let link = w.p(&format!("link-{k}"));
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(target, &link).unwrap();
        return link;
    }
    let dir = w.p(&format!("dir-{k}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    if case.args[0] == "run" {
        // The network's files, linked: `run`'s inputs are then net/'s files themselves.
        for f in ["segments.csv", "measurements.csv"] {
            std::os::unix::fs::symlink(w.p(&format!("net/{f}")), dir.join(f)).unwrap();
        }
    }
    let file = dir.join(case.file_in_out);
    std::fs::create_dir_all(file.parent().unwrap()).unwrap();
    std::os::unix::fs::symlink(target, &file).unwrap();
    dir
}

/// Defect 1 and the property test: every writing command and option, new names and
/// aliases included, × {the database, another pipewave database, another SQLite database, a
/// symlink to the database, its own input, a read-only file}. The protected file is
/// byte-identical afterwards, the exit is 2, and the message names the path.
#[test]
fn defect_01_no_writing_command_overwrites_a_database_an_input_or_a_read_only_file() {
    let w = world();
    let files = protected_files(w);
    let before = snapshot(&files);
    let mut k = 0;
    let mut tried = 0;
    for case in cases(w) {
        let targets: [(&str, &str, bool); 6] = [
            ("the database", "a.sqlite", false),
            ("another pipewave database", "b.sqlite", false),
            ("another SQLite database", "c.sqlite", false),
            ("a symlink to the database", "a.sqlite", true),
            ("its own input", case.input, false),
            ("a read-only file", "readonly.csv", false),
        ];
        for (what, rel, via_link) in targets {
            k += 1;
            let out = place(w, &case, &w.p(rel), via_link, k);
            let o = run_case(&case, &out);
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(
                o.status.code(),
                Some(2),
                "{} over {what}: exit {:?}\n{err}",
                case.name,
                o.status.code()
            );
            let named = if case.file_in_out.is_empty() {
                out.clone()
            } else {
                out.join(case.file_in_out)
            };
            assert!(
                err.contains("refusing") && err.contains(&named.display().to_string()),
                "{} over {what}: the message does not name {}:\n{err}",
                case.name,
                named.display()
            );
            tried += 1;
        }
    }
    assert_eq!(tried, 22 * 6);
    for (p, bytes) in &before {
        assert!(
            &std::fs::read(p).unwrap() == bytes,
            "{} changed",
            p.display()
        );
    }
}

/// Defect 1, import's side: the database named by `--db` may not be the file being imported.
#[test]
fn defect_01_import_refuses_a_database_path_that_is_its_input() {
    let w = world();
    let seg = w.p("net/segments.csv");
    let before = std::fs::read(&seg).unwrap();
    for db in [seg.clone(), {
        let link = w.p("seg-link.sqlite");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&seg, &link).unwrap();
        link
    }] {
        let o = pipewave()
            .args(["import", "--db"])
            .arg(&db)
            .arg("--segments")
            .arg(&seg)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains("refusing to use") && err.contains("input"),
            "{err}"
        );
    }
    assert_eq!(std::fs::read(&seg).unwrap(), before);
}

/// Defect 8: `plan`'s CSV neutralises a segment id that a spreadsheet would run as a formula.
#[test]
fn defect_08_plans_csv_is_spreadsheet_safe() {
    let dir = tempfile::tempdir().unwrap();
    let net = dir.path().join("net");
    ok(&[
        "synth",
        "--out",
        net.to_str().unwrap(),
        "--segments",
        "10",
        "--seed",
        "5",
        "--measured-fraction",
        "0.5",
        "--no-real-cases",
    ]);
    // Give every segment id a formula lead, in both files.
    for f in ["segments.csv", "measurements.csv"] {
        let p = net.join(f);
        let t = std::fs::read_to_string(&p).unwrap().replace("WM1", "=WM1");
        std::fs::write(&p, t).unwrap();
    }
    let db = dir.path().join("p.sqlite");
    ok(&["run", net.to_str().unwrap(), "--db", db.to_str().unwrap()]);
    let out = dir.path().join("next.csv");
    ok(&[
        "plan",
        "--db",
        db.to_str().unwrap(),
        "--count",
        "3",
        "--out",
        out.to_str().unwrap(),
    ]);
    let text = std::fs::read_to_string(&out).unwrap();
    let ids: Vec<&str> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap())
        .collect();
    assert_eq!(ids.len(), 3, "{text}");
    for id in ids {
        assert!(
            id.starts_with("\"'=WM1"),
            "a raw formula in plan's CSV: {id}"
        );
    }
}

/// Defect 11: a read-only output is refused by export, audit and the GeoPackage export, as by
/// `plan`, and left as it was.
#[test]
fn defect_11_a_read_only_output_is_refused_not_replaced() {
    let w = world();
    let dir = tempfile::tempdir().unwrap();
    for (i, args) in [
        vec!["export", "--format", "csv"],
        vec!["export", "--format", "gpkg"],
        vec!["audit"],
    ]
    .into_iter()
    .enumerate()
    {
        let out = dir.path().join(format!("ro-{i}"));
        std::fs::write(&out, "keep me").unwrap();
        std::fs::set_permissions(&out, std::fs::Permissions::from_mode(0o444)).unwrap();
        let o = pipewave()
            .args(&args)
            .args(["--db", &w.s("a.sqlite"), "--out"])
            .arg(&out)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(String::from_utf8_lossy(&o.stderr).contains("read-only"));
        assert_eq!(std::fs::read_to_string(&out).unwrap(), "keep me");
    }
}

/// Defect 12: temporary files that a killed export left beside its output are removed by the
/// next export to that output; a live writer's are kept.
#[test]
fn defect_12_a_killed_exports_temporary_files_are_cleaned_up() {
    let w = world();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fits.gpkg");
    // What `kill -9` during an export leaves: the temporary GeoPackage and its journal, named
    // after a process that no longer runs (ids above Linux's pid_max never run).
    let stale = [
        ".fits.gpkg.tmp-999999999",
        ".fits.gpkg.tmp-999999999-journal",
    ];
    for s in stale {
        std::fs::write(dir.path().join(s), "half an export").unwrap();
    }
    let live = dir.path().join(".fits.gpkg.tmp-1");
    std::fs::write(&live, "pid 1 always runs").unwrap();
    ok(&[
        "export",
        "--db",
        &w.s("a.sqlite"),
        "--format",
        "gpkg",
        "--out",
        out.to_str().unwrap(),
    ]);
    for s in stale {
        assert!(!dir.path().join(s).exists(), "{s} left behind");
    }
    assert!(
        live.exists(),
        "a running writer's temporary file was removed"
    );
    let mut names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, [".fits.gpkg.tmp-1", "fits.gpkg"]);
}
