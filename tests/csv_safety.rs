//! Issue 17: every CSV pipewave writes is safe to open in a spreadsheet, and the HTML reports stay
//! escaped, for an inventory whose segment ids and soil types are hostile. Runs the real binary:
//! `run` (its CSV export and audit report), `export --format csv`, `fit --out`, `diagnose`
//! (every CSV of its output folder, and `diagnosis.html`) and `forward --output`.

mod report_check;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::{Command, Output};

use pipewave::export::record::Kind;
use pipewave::export::PROPERTIES;

/// Segment ids: formulas, and HTML.
const IDS: [&str; 6] = [
    "=HYPERLINK(\"http://x\")",
    "+1",
    "-2+3",
    "@SUM(A1)",
    "<script>alert(1)</script>",
    "\"><img onerror=alert(1)>",
];

/// Soil types: HTML, and formulas behind a tab or carriage return (the import trims cells, so
/// these arrive as `=tab()` and `@cr`).
const SOILS: [&str; 6] = [
    "<b>",
    "\t=tab()",
    "\r@cr",
    "-clay",
    "<script>alert(2)</script>",
    "\"><img onerror=alert(3)>",
];

/// `forward` case ids.
const CASES: [&str; 4] = ["=1+1", "\t-2", "@A1", "<b>case</b>"];

/// How they must read back (written out here, not computed with pipewave's own function):
/// trimmed by the import, a leading `'` on those a spreadsheet would take for a formula.
const IDS_SAFE: [&str; 6] = [
    "'=HYPERLINK(\"http://x\")",
    "'+1",
    "'-2+3",
    "'@SUM(A1)",
    "<script>alert(1)</script>",
    "\"><img onerror=alert(1)>",
];
const SOILS_SAFE: [&str; 6] = [
    "<b>",
    "'=tab()",
    "'@cr",
    "'-clay",
    "<script>alert(2)</script>",
    "\"><img onerror=alert(3)>",
];
const CASES_SAFE: [&str; 4] = ["'=1+1", "'-2", "'@A1", "<b>case</b>"];

/// What makes a spreadsheet read a cell as a formula (OWASP "CSV Injection").
const FORMULA_LEADS: [char; 6] = ['=', '+', '-', '@', '\t', '\r'];

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
}

fn ok(cmd: &mut Command) -> Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{cmd:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Header and rows of a CSV file.
fn read(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let mut r = csv::Reader::from_path(path).unwrap();
    let h = r.headers().unwrap().iter().map(str::to_string).collect();
    let rows = r
        .records()
        .map(|x| x.unwrap().iter().map(str::to_string).collect())
        .collect();
    (h, rows)
}

/// Check one CSV output: no cell that a spreadsheet would take for a formula (a cell beginning
/// with a formula character must be a number, like -0.5); every cell of `numeric` columns empty
/// or a number, written bare; the `text` columns exactly the neutralised hostile values.
fn check_csv(path: &Path, numeric: &[&str], text: &[(&str, &BTreeSet<String>)]) {
    let name = path.display();
    let raw = std::fs::read_to_string(path).unwrap();
    let (header, rows) = read(path);
    assert!(!rows.is_empty(), "{name}: no rows");
    let col = |c: &str| {
        header
            .iter()
            .position(|h| h == c)
            .unwrap_or_else(|| panic!("{name}: no column {c}"))
    };
    for (i, row) in rows.iter().enumerate() {
        for (j, cell) in row.iter().enumerate() {
            if cell.starts_with(FORMULA_LEADS) {
                assert!(
                    cell.parse::<f64>().is_ok(),
                    "{name} row {} column {}: {cell:?} would open as a formula",
                    i + 1,
                    header[j]
                );
            }
        }
    }
    let mut negatives = 0;
    for c in numeric {
        let j = col(c);
        for row in &rows {
            let v = &row[j];
            if v.is_empty() {
                continue;
            }
            assert!(v.parse::<f64>().is_ok(), "{name} column {c}: {v:?}");
            assert!(
                !raw.contains(&format!("\"{v}\"")),
                "{name} column {c}: the number {v} is quoted"
            );
            if v.starts_with('-') {
                negatives += 1;
                assert!(!raw.contains(&format!("'{v}")), "{name}: {v} was prefixed");
            }
        }
    }
    for (c, want) in text {
        let j = col(c);
        let got: BTreeSet<String> = rows.iter().map(|r| r[j].clone()).collect();
        assert_eq!(&got, *want, "{name} column {c}");
        for v in got {
            if v.starts_with('\'') {
                assert!(
                    raw.contains(&format!("\"{}\"", v.replace('"', "\"\""))),
                    "{name}: {v:?} not quoted"
                );
            }
        }
    }
    // Numbers' signs survive: the forward output has negative k_im; the others may.
    if path.ends_with("results.csv") {
        assert!(negatives > 0, "{name}: no negative number was checked");
    }
}

/// An HTML report keeps the hostile text escaped: no raw tag of it, its SVGs well-formed XML.
fn check_html(path: &Path) {
    let html = std::fs::read_to_string(path).unwrap();
    let lower = html.to_lowercase();
    let name = path.display();
    for bad in ["<script", "<img"] {
        assert!(!lower.contains(bad), "{name}: raw {bad}");
    }
    for v in IDS.iter().chain(&SOILS).map(|v| v.trim()) {
        if v.contains('<') && v != "<b>" {
            assert!(!html.contains(v), "{name}: raw {v}");
        }
    }
    // The reports use <b> themselves, always closed; a raw hostile "<b>" would be unclosed.
    assert_eq!(
        html.matches("<b>").count(),
        html.matches("</b>").count(),
        "{name}: an unclosed <b>"
    );
    assert!(
        html.contains("&lt;script&gt;alert(1)")
            && html.contains("&gt;&lt;img onerror=alert(1)&gt;"),
        "{name}: the hostile id is not shown escaped"
    );
    for svg in report_check::svgs(&html) {
        report_check::parse_xml(svg);
    }
}

/// Replace the synthetic ids (and soil types) of a network's CSVs with the hostile ones.
fn make_hostile(net: &Path) -> BTreeMap<String, String> {
    let seg = net.join("segments.csv");
    let (header, rows) = read(&seg);
    assert_eq!(rows.len(), IDS.len());
    let id = header.iter().position(|h| h == "segment_id").unwrap();
    let soil = header.iter().position(|h| h == "soil_type").unwrap();
    let map: BTreeMap<String, String> = rows
        .iter()
        .zip(IDS)
        .map(|(r, new)| (r[id].clone(), new.to_string()))
        .collect();
    let mut w = csv::Writer::from_path(&seg).unwrap();
    w.write_record(&header).unwrap();
    for (r, s) in rows.iter().zip(SOILS) {
        let mut r = r.clone();
        r[id] = map[&r[id]].clone();
        r[soil] = s.to_string();
        w.write_record(&r).unwrap();
    }
    w.flush().unwrap();

    let meas = net.join("measurements.csv");
    let (header, rows) = read(&meas);
    let id = header.iter().position(|h| h == "segment_id").unwrap();
    let mut w = csv::Writer::from_path(&meas).unwrap();
    w.write_record(&header).unwrap();
    for mut r in rows {
        r[id] = map[&r[id]].clone();
        w.write_record(&r).unwrap();
    }
    w.flush().unwrap();
    map
}

/// `forward` input: a few rows of the reference vectors with hostile case ids.
fn forward_input(path: &Path) {
    let src = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/vectors/dispersion_roots.csv");
    let (header, rows) = read(&src);
    let id = header.iter().position(|h| h == "case_id").unwrap();
    let mut w = csv::Writer::from_path(path).unwrap();
    w.write_record(&header).unwrap();
    for (r, c) in rows.iter().zip(CASES) {
        let mut r = r.clone();
        r[id] = c.to_string();
        w.write_record(&r).unwrap();
    }
    w.flush().unwrap();
}

#[test]
fn every_csv_is_safe_in_a_spreadsheet_and_reports_stay_escaped() {
    let tmp = tempfile::tempdir().unwrap();
    let net = tmp.path().join("net");
    ok(bin()
        .args(["synth", "--segments", "6", "--seed", "11", "--defects", "0"])
        .args(["--no-real-cases", "--out"])
        .arg(&net));
    make_hostile(&net);
    ok(bin().arg("run").arg(&net).args(["--jobs", "2"]));
    let db = net.join("pipewave.sqlite");

    let set = |v: &[&str]| {
        v.iter()
            .map(|s| s.to_string())
            .collect::<BTreeSet<String>>()
    };
    let ids = set(&IDS_SAFE);
    let soils = set(&SOILS_SAFE);
    let numeric: Vec<&str> = PROPERTIES
        .iter()
        .filter(|p| p.kind != Kind::Text)
        .map(|p| p.name)
        .collect();
    let export_text = [("segment_id", &ids), ("soil_type", &soils)];

    // `run`'s export, `export --format csv` and `fit --out`: the same columns.
    check_csv(&net.join("out/segments.csv"), &numeric, &export_text);
    let exported = tmp.path().join("export.csv");
    ok(bin()
        .args(["export", "--format", "csv", "--db"])
        .arg(&db)
        .arg("--out")
        .arg(&exported));
    check_csv(&exported, &numeric, &export_text);
    let fitted = tmp.path().join("fit.csv");
    ok(bin()
        .args(["fit", "--jobs", "2", "--segments"])
        .arg(net.join("segments.csv"))
        .arg("--measurements")
        .arg(net.join("measurements.csv"))
        .arg("--out")
        .arg(&fitted));
    check_csv(&fitted, &numeric, &export_text);

    // `diagnose`: every CSV it writes (diagnosis.csv, and groups.csv where written), and its report.
    let diag = tmp.path().join("diag");
    ok(bin()
        .args([
            "diagnose",
            "--no-apply",
            "--jobs",
            "2",
            "--candidates",
            "wall_thinning",
            "--db",
        ])
        .arg(&db)
        .arg("--out")
        .arg(&diag));
    let mut diag_csvs = Vec::new();
    for e in std::fs::read_dir(&diag).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "csv") {
            diag_csvs.push(p);
        }
    }
    diag_csvs.sort();
    assert!(
        diag_csvs.iter().any(|p| p.ends_with("diagnosis.csv")),
        "{diag_csvs:?}"
    );
    for p in &diag_csvs {
        if p.ends_with("diagnosis.csv") {
            check_csv(
                p,
                &[
                    "effect_value",
                    "effect_std",
                    "chi2_per_dof_before",
                    "chi2_per_dof_after",
                    "lr_statistic",
                    "p_value",
                ],
                &[("segment_id", &ids)],
            );
        } else if read(p).1.is_empty() {
            // No group large enough to test: the header alone, still safe.
            let (header, _) = read(p);
            assert!(header.iter().any(|h| h == "group"), "{}", p.display());
        } else {
            check_csv(p, &[], &[]);
        }
    }
    check_html(&diag.join("diagnosis.html"));
    check_html(&net.join("out/report.html"));

    // `forward --output`: the case id is text, the wavenumbers (negative k_im) numbers.
    let cases = tmp.path().join("cases.csv");
    forward_input(&cases);
    let results = tmp.path().join("results.csv");
    ok(bin()
        .arg("forward")
        .arg("--input")
        .arg(&cases)
        .arg("--output")
        .arg(&results));
    let case_ids = set(&CASES_SAFE);
    check_csv(
        &results,
        &[
            "k_re_rad_per_m",
            "k_im_np_per_m",
            "phase_speed_m_per_s",
            "attenuation_db_per_m",
        ],
        &[("case_id", &case_ids)],
    );
    let (_, rows) = read(&results);
    assert!(
        rows.iter().all(|r| r[5] == "ok"),
        "the reference cases solve: {rows:?}"
    );

    // `wavenumbers --out`: the sample network's recording under a hostile segment id and
    // campaign.
    let rec = tmp.path().join("rec");
    std::fs::create_dir_all(&rec).unwrap();
    std::fs::copy(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/sample_network/recordings/WM10003.wav"
        ),
        rec.join("WM10003.wav"),
    )
    .unwrap();
    std::fs::write(
        rec.join("layout.csv"),
        "segment_id,file,channel,position_m\n\
         \"=HYPERLINK(\"\"http://x\"\")\",WM10003.wav,0,0\n\
         \"=HYPERLINK(\"\"http://x\"\")\",WM10003.wav,1,-70.5\n\
         \"=HYPERLINK(\"\"http://x\"\")\",WM10003.wav,2,59.7\n",
    )
    .unwrap();
    let wn = tmp.path().join("wavenumbers.csv");
    ok(bin()
        .arg("wavenumbers")
        .arg("--layout")
        .arg(rec.join("layout.csv"))
        .args(["--campaign", "@SUM(A1)", "--out"])
        .arg(&wn));
    check_csv(
        &wn,
        &[
            "frequency_hz",
            "k_re_rad_per_m",
            "attenuation_np_per_m",
            "k_re_std",
            "attenuation_std",
        ],
        &[("segment_id", &set(&["'=HYPERLINK(\"http://x\")"]))],
    );
    let (header, rows) = read(&wn);
    let campaign = header.iter().position(|h| h == "campaign").unwrap();
    assert!(
        rows.iter().all(|r| r[campaign].starts_with("'@SUM(A1)")),
        "{rows:?}"
    );
}
