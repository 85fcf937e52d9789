//! Measurements keep their history: a campaign is identified by segment, campaign and
//! frequency; importing a campaign again updates it, a new campaign adds rows beside the
//! earlier ones, nothing stored is deleted unless a campaign is replaced by name, and the fit
//! uses each segment's latest campaign.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::cli::{ok, pipewave};
use rusqlite::Connection;

/// A synthetic network (its own 12 segments, every one measured) in a temporary folder.
struct Net {
    dir: tempfile::TempDir,
}

impl Net {
    fn new(seed: &str) -> Net {
        let dir = tempfile::tempdir().unwrap();
        let net = dir.path().join("net");
        ok(&[
            "synth",
            "--out",
            net.to_str().unwrap(),
            "--segments",
            "12",
            "--seed",
            seed,
            "--no-real-cases",
            "--defects",
            "0",
        ]);
        Net { dir }
    }
    fn p(&self, rel: &str) -> PathBuf {
        self.dir.path().join(rel)
    }
    fn s(&self, rel: &str) -> String {
        self.p(rel).to_str().unwrap().to_string()
    }
    /// The network's measurements.csv with its campaign set to `campaign` and every Re k
    /// multiplied by `k_scale` (a pipe whose speed changed), written to `rel`.
    fn campaign_file(&self, rel: &str, campaign: &str, k_scale: f64) -> PathBuf {
        let text = std::fs::read_to_string(self.p("net/measurements.csv")).unwrap();
        let mut lines = text.lines();
        let header = lines.next().unwrap();
        let cols: Vec<&str> = header.split(',').collect();
        let at = |name: &str| cols.iter().position(|c| *c == name).unwrap();
        let (k, c) = (at("k_re_rad_per_m"), at("campaign"));
        let mut out = vec![header.to_string()];
        for l in lines {
            let mut cells: Vec<String> = l.split(',').map(str::to_string).collect();
            let v: f64 = cells[k].parse().unwrap();
            cells[k] = (v * k_scale).to_string();
            cells[c] = campaign.to_string();
            out.push(cells.join(","));
        }
        let p = self.p(rel);
        std::fs::write(&p, out.join("\n") + "\n").unwrap();
        p
    }
    fn import(&self, db: &str, measurements: &Path, extra: &[&str]) -> String {
        let mut args = vec![
            "import",
            "--db",
            db,
            "--segments",
            self.p("net/segments.csv")
                .to_str()
                .unwrap()
                .to_owned()
                .leak(),
            "--measurements",
            measurements.to_str().unwrap().to_owned().leak(),
        ];
        args.extend_from_slice(extra);
        String::from_utf8(ok(&args).stdout).unwrap()
    }
}

/// Every stored measurement as (segment, campaign, ω) → (Re k, attenuation).
fn rows(db: &str) -> BTreeMap<(String, String, String), (f64, f64)> {
    let conn = Connection::open(db).unwrap();
    let mut st = conn
        .prepare(
            "SELECT segment_id, campaign, omega_rad_s, k_re_rad_per_m, attenuation_np_per_m \
             FROM measurements",
        )
        .unwrap();
    st.query_map([], |r| {
        Ok((
            (r.get(0)?, r.get(1)?, r.get::<_, f64>(2)?.to_string()),
            (r.get(3)?, r.get(4)?),
        ))
    })
    .unwrap()
    .collect::<Result<_, _>>()
    .unwrap()
}

fn only_campaign(
    all: &BTreeMap<(String, String, String), (f64, f64)>,
    c: &str,
) -> BTreeMap<(String, String, String), (f64, f64)> {
    all.iter()
        .filter(|(k, _)| k.1 == c)
        .map(|(k, v)| (k.clone(), *v))
        .collect()
}

/// The first failure, and its second: importing a second campaign keeps every row of
/// the first, says what it added per campaign, and the fit then uses the latest campaign.
#[test]
fn a_second_campaign_adds_rows_and_keeps_every_row_of_the_first() {
    let n = Net::new("21");
    let db = n.s("a.sqlite");
    let first = n.campaign_file("fd2026.csv", "FD-2026", 1.0);
    let out = n.import(&db, &first, &[]);
    let before = rows(&db);
    let count = before.len();
    assert!(count >= 24, "{count}");
    assert!(
        out.contains(&format!(
            "campaign FD-2026: {count} rows added, 0 updated, 0 kept"
        )),
        "{out}"
    );
    ok(&["calibrate", "--db", &db, "--jobs", "2"]);
    let second = n.campaign_file("fd2027.csv", "FD-2027", 1.03);
    let out = n.import(&db, &second, &[]);
    assert!(
        out.contains(&format!(
            "campaign FD-2027: {count} rows added, 0 updated, 0 kept"
        )),
        "{out}"
    );
    let after = rows(&db);
    assert_eq!(after.len(), 2 * count);
    assert_eq!(only_campaign(&after, "FD-2026"), before);
    // The current fit is made from the latest campaign alone where the pipe changed (every
    // wavenumber is 3 % higher), and from both where the test finds no change (P96).
    ok(&["calibrate", "--db", &db, "--jobs", "2"]);
    let conn = Connection::open(&db).unwrap();
    let fits: Vec<(String, String, String, i64)> = conn
        .prepare(
            "SELECT segment_id, f.campaigns, c.status, f.n_measurements FROM latest_fits f \
             JOIN latest_changes c USING (segment_id)",
        )
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    let own = |id: &str| before.keys().filter(|k| k.0 == id).count() as i64;
    assert_eq!(fits.iter().map(|f| own(&f.0)).sum::<i64>() as usize, count);
    for (id, campaigns, status, n) in &fits {
        // Pooled, the two campaigns' rows at one frequency merge into one (P96).
        let want = if status == "changed" {
            "FD-2027"
        } else {
            "FD-2027,FD-2026"
        };
        assert_eq!((campaigns.as_str(), *n), (want, own(id)), "{id}: {status}");
    }
    let changed = fits.iter().filter(|f| f.2 == "changed").count();
    assert!(
        2 * changed > fits.len(),
        "{changed} of {} changed",
        fits.len()
    );
}

/// Re-importing a campaign's file changes nothing (no row added, updated or refitted), and a
/// file without a campaign column is the one campaign `unnamed`, so the nightly `run` that
/// imports it every night adds nothing.
#[test]
fn reimporting_a_campaign_changes_nothing_and_blank_is_unnamed() {
    let n = Net::new("22");
    let db = n.s("b.sqlite");
    let file = n.campaign_file("fd.csv", "FD-2026", 1.0);
    n.import(&db, &file, &[]);
    ok(&["calibrate", "--db", &db, "--jobs", "2"]);
    let before = rows(&db);
    let out = n.import(&db, &file, &[]);
    assert!(
        out.contains(&format!(
            "campaign FD-2026: 0 rows added, 0 updated, {} kept",
            before.len()
        )),
        "{out}"
    );
    assert!(out.contains("fit inputs changed for 0 segments"), "{out}");
    assert_eq!(rows(&db), before);
    let fits = |db: &str| -> Vec<i64> {
        let conn = Connection::open(db).unwrap();
        let mut st = conn
            .prepare("SELECT id FROM latest_fits ORDER BY id")
            .unwrap();
        st.query_map([], |r| r.get(0))
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap()
    };
    let fitted = fits(&db);
    ok(&["calibrate", "--db", &db]);
    assert_eq!(fits(&db), fitted, "a re-import made fits stale");
    // No campaign column at all: `unnamed`, twice over the same rows.
    let blank = n.p("blank.csv");
    let text = std::fs::read_to_string(n.p("net/measurements.csv")).unwrap();
    let stripped: Vec<String> = text
        .lines()
        .map(|l| l.rsplit_once(',').unwrap().0.to_string())
        .collect();
    assert!(stripped[0].ends_with("attenuation_std"), "{}", stripped[0]);
    std::fs::write(&blank, stripped.join("\n") + "\n").unwrap();
    n.import(&db, &blank, &[]);
    let once = rows(&db);
    n.import(&db, &blank, &[]);
    assert_eq!(rows(&db), once);
    assert_eq!(only_campaign(&once, "unnamed").len(), before.len());
    assert_eq!(once.len(), 2 * before.len());
}

/// `pipewave run DIR` with both campaigns in one measurements.csv imports both (it used to
/// reject every row as a duplicate frequency).
#[test]
fn run_imports_two_campaigns_of_one_file() {
    let n = Net::new("23");
    let a = n.campaign_file("x.csv", "FD-2026", 1.0);
    let b = n.campaign_file("y.csv", "FD-2027", 0.98);
    let tb = std::fs::read_to_string(&b).unwrap();
    let both = std::fs::read_to_string(&a).unwrap() + tb.split_once('\n').unwrap().1;
    std::fs::write(n.p("net/measurements.csv"), both).unwrap();
    let db = n.s("run.sqlite");
    ok(&["run", &n.s("net"), "--db", &db]);
    let r = rows(&db);
    assert_eq!(
        only_campaign(&r, "FD-2026").len(),
        only_campaign(&r, "FD-2027").len()
    );
    assert!(!r.is_empty());
}

/// Only a campaign named by `--replace-campaign` loses the rows the file does not hold; the
/// other campaigns keep all of theirs.
#[test]
fn only_a_campaign_replaced_by_name_loses_rows() {
    let n = Net::new("24");
    let db = n.s("c.sqlite");
    n.import(&db, &n.campaign_file("a.csv", "A", 1.0), &[]);
    n.import(&db, &n.campaign_file("b.csv", "B", 1.01), &[]);
    let before = rows(&db);
    // A smaller B: the first data row only.
    let full = std::fs::read_to_string(n.p("b.csv")).unwrap();
    let small: Vec<&str> = full.lines().take(2).collect();
    let p = n.p("b-small.csv");
    std::fs::write(&p, small.join("\n") + "\n").unwrap();
    n.import(&db, &p, &[]);
    assert_eq!(
        rows(&db),
        before,
        "without --replace-campaign nothing is deleted"
    );
    let out = n.import(&db, &p, &["--replace-campaign", "B"]);
    let after = rows(&db);
    assert_eq!(only_campaign(&after, "B").len(), 1);
    assert_eq!(only_campaign(&after, "A"), only_campaign(&before, "A"));
    assert!(
        out.contains(&format!(
            "{} removed (--replace-campaign)",
            only_campaign(&before, "B").len() - 1
        )),
        "{out}"
    );
}

/// A database made before campaigns were kept (schema 13: measurements keyed by segment and
/// frequency, labels free or blank), opened by this version, keeps every row: labels as they
/// were, blanks as `unnamed`, and a segment whose frequencies had two labels has two campaigns.
#[test]
fn a_database_of_schema_13_keeps_every_row() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.sqlite");
    let conn = Connection::open(&path).unwrap();
    let mut files: Vec<PathBuf> =
        std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/migrations"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "sql"))
            .collect();
    files.sort();
    for f in &files[..13] {
        conn.execute_batch(&std::fs::read_to_string(f).unwrap())
            .unwrap();
    }
    conn.pragma_update(None, "user_version", 13).unwrap();
    conn.execute_batch(
        "INSERT INTO segments (segment_id, material, outer_diameter_mm, wall_thickness_mm, \
         soil_density_kg_m3, inputs_hash) VALUES ('A', 'DI', 170, 6, 1900, 'h'), \
         ('B', 'PVC', 110, 5.3, 1800, 'h');
         INSERT INTO measurements (segment_id, omega_rad_s, frequency_hz, k_re_rad_per_m, \
         attenuation_np_per_m, measured_on, campaign) VALUES \
         ('A', 628.3, 100, 0.5, 0.01, '2026-05-01', 'FD-2026'), \
         ('A', 1256.6, 200, 1.0, 0.02, '2026-05-01', 'FD-2026 (reflection_suspected)'), \
         ('B', 628.3, 100, 1.3, 0.05, NULL, NULL), ('B', 1256.6, 200, 2.6, 0.1, NULL, '');",
    )
    .unwrap();
    drop(conn);
    // Any command that opens the database migrates it.
    ok(&["calibrate", "--db", path.to_str().unwrap()]);
    let got = rows(path.to_str().unwrap());
    let keys: Vec<(String, String)> = got.keys().map(|k| (k.0.clone(), k.1.clone())).collect();
    assert_eq!(
        keys,
        [
            ("A".to_string(), "FD-2026".to_string()),
            ("A".into(), "FD-2026 (reflection_suspected)".into()),
            ("B".into(), "unnamed".into()),
            ("B".into(), "unnamed".into()),
        ]
    );
    let conn = Connection::open(&path).unwrap();
    let version: i64 = conn
        .query_row("PRAGMA user_version", [], |r| r.get(0))
        .unwrap();
    assert!(version >= 15);
    // The history view reads every row, with its campaign's place in the segment's history.
    let n: i64 = conn
        .query_row(
            "SELECT COUNT(*) FROM measurement_history WHERE segment_id = 'A' \
             AND campaign_import_order = 2",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(n, 1);
}

/// kill -9 during a second campaign's import loses nothing: whenever it is killed, the first
/// campaign is whole and the second is either all there or absent.
#[test]
fn kill_during_a_second_campaigns_import_loses_nothing() {
    let n = Net::new("25");
    let db = n.s("k.sqlite");
    n.import(&db, &n.campaign_file("a.csv", "FD-2026", 1.0), &[]);
    let first = rows(&db);
    // A large second campaign, so that an import takes long enough to be killed in flight:
    // the same rows repeated at other frequencies.
    let base = std::fs::read_to_string(n.campaign_file("b.csv", "FD-2027", 1.02)).unwrap();
    let mut lines = base.lines();
    let header = lines.next().unwrap().to_string();
    let data: Vec<&str> = lines.collect();
    let cols: Vec<&str> = header.split(',').collect();
    let f_at = cols.iter().position(|c| *c == "frequency_hz").unwrap();
    let w_at = cols.iter().position(|c| *c == "omega_rad_s").unwrap();
    let mut big = vec![header.clone()];
    for j in 0..400 {
        for l in &data {
            let mut cells: Vec<String> = l.split(',').map(str::to_string).collect();
            if cells[f_at].is_empty() {
                let w: f64 = cells[w_at].parse().unwrap();
                cells[w_at] = (w * (1.0 + 1e-3 * (j + 1) as f64)).to_string();
            } else {
                let f: f64 = cells[f_at].parse().unwrap();
                cells[f_at] = (f * (1.0 + 1e-3 * (j + 1) as f64)).to_string();
            }
            big.push(cells.join(","));
        }
    }
    let p = n.p("big.csv");
    std::fs::write(&p, big.join("\n") + "\n").unwrap();
    let whole = big.len() - 1;
    // Kills that found the import still running: without one the test would show nothing.
    let mut in_flight = 0;
    for delay_ms in [5u64, 20, 50, 100, 200] {
        let mut child = pipewave()
            .args(["import", "--db", &db, "--measurements"])
            .arg(&p)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        if child.try_wait().unwrap().is_none() {
            in_flight += 1;
        }
        let _ = child.kill();
        let _ = child.wait();
        let now = rows(&db);
        assert_eq!(
            only_campaign(&now, "FD-2026"),
            first,
            "killed after {delay_ms} ms"
        );
        let second = only_campaign(&now, "FD-2027").len();
        assert!(
            second == 0 || second == whole,
            "killed after {delay_ms} ms: {second} of {whole} rows of the second campaign"
        );
    }
    assert!(in_flight >= 1, "every import had finished before its kill");
}
