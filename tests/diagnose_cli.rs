//! The discrepancy workflow end to end, as a user runs it: a synthetic network in which some
//! segments hide a thinned wall is imported and calibrated with the base model, then
//! `diagnose` names the effect, stores the extended fits and switches the effect on for those
//! segments, and the next `calibrate` uses it.

mod report_check;

use std::collections::BTreeMap;
use std::path::Path;
mod common;
use common::cli::{ok, pipewave as bin};

fn rows(path: &Path) -> Vec<BTreeMap<String, String>> {
    let mut r = csv::Reader::from_path(path).unwrap();
    let h = r.headers().unwrap().clone();
    r.records()
        .map(|x| {
            let x = x.unwrap();
            h.iter()
                .zip(x.iter())
                .map(|(a, b)| (a.to_string(), b.to_string()))
                .collect()
        })
        .collect()
}

#[test]
fn diagnose_names_adds_and_the_next_calibrate_uses_the_effect() {
    let tmp = tempfile::tempdir().unwrap();
    let net = tmp.path().join("net");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    ok(&[
        "synth",
        "--out",
        &s(&net),
        "--segments",
        "8",
        "--seed",
        "5",
        "--defects",
        "0",
        "--no-real-cases",
        "--hidden-effect",
        "wall_thinning",
        "--hidden-range",
        "0.5,0.7",
        "--hidden-fraction",
        "0.5",
    ]);
    ok(&["run", &s(&net), "--jobs", "2"]);
    let db = net.join("pipewave.sqlite");
    // The stored fits' chi2/dof, before the diagnosis adds any row.
    let stored: BTreeMap<String, f64> = {
        let conn = rusqlite::Connection::open(&db).unwrap();
        let mut st = conn
            .prepare("SELECT segment_id, chi2_per_dof FROM latest_fits")
            .unwrap();
        let v = st
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
            .unwrap()
            .map(Result::unwrap)
            .collect();
        v
    };
    let out = tmp.path().join("diag");
    let d = ok(&[
        "diagnose",
        "--db",
        &s(&db),
        "--out",
        &s(&out),
        "--jobs",
        "2",
    ]);
    let stdout = String::from_utf8_lossy(&d.stdout);
    assert!(stdout.contains("diagnose: 8 segments"), "{stdout}");

    let truth: BTreeMap<String, String> = rows(&net.join("truth.csv"))
        .into_iter()
        .map(|r| (r["segment_id"].clone(), r["hidden_effect"].clone()))
        .collect();
    let diag = rows(&out.join("diagnosis.csv"));
    assert_eq!(diag.len(), 8);
    // Readable by `head` and a spreadsheet (issue 64): one line per row, p-values in
    // scientific notation (never a 189-character 0.000… string), other numbers to 6 significant
    // digits, and no "inf" or "NaN" in the evidence.
    let text = std::fs::read_to_string(out.join("diagnosis.csv")).unwrap();
    assert_eq!(text.lines().count(), 9);
    for r in &diag {
        let p = &r["p_value"];
        if !p.is_empty() {
            assert!(p.len() <= 10 && p.contains('e'), "p_value {p}");
            assert!(
                p.parse::<f64>().is_ok_and(|v| (0.0..=1.0).contains(&v)),
                "{p}"
            );
        }
        for c in ["lr_statistic", "holdout_chi2_before", "holdout_chi2_after"] {
            assert!(r[c].len() <= 13, "{c} {}", r[c]);
        }
        let ev = r["evidence"].to_lowercase();
        assert!(
            !ev.contains("inf") && !ev.contains("nan"),
            "{}",
            r["evidence"]
        );
    }
    let mut named = Vec::new();
    for r in &diag {
        let hidden = &truth[&r["segment_id"]];
        let before: f64 = r["chi2_per_dof_before"].parse().unwrap();
        // The diagnosis starts from the stored fit, reproduced bit for bit (same settings and
        // seed), written by the export's rule (6 significant digits).
        assert_eq!(
            r["chi2_per_dof_before"],
            pipewave::export::numbers::significant(stored[&r["segment_id"]], 6),
            "{}",
            r["segment_id"]
        );
        if hidden.is_empty() {
            assert_eq!(
                r["named_effect"], "none",
                "control {} was given an effect",
                r["segment_id"]
            );
        } else if r["structured"] == "1" {
            assert_eq!(r["named_effect"], "wall_thinning", "{:?}", r);
            let after: f64 = r["chi2_per_dof_after"].parse().unwrap();
            assert!(after < before && after <= 2.0, "{before} -> {after}");
            let v: f64 = r["effect_value"].parse().unwrap();
            assert!((0.4..=0.8).contains(&v), "fitted r_h {v}");
            named.push(r["segment_id"].clone());
        }
    }
    assert!(
        !named.is_empty(),
        "no thinned segment had a misfit to explain"
    );
    let html = std::fs::read_to_string(out.join("diagnosis.html")).unwrap();
    let svgs = report_check::svgs(&html);
    assert_eq!(
        svgs.len(),
        8,
        "one residual plot per segment of a small network"
    );
    for svg in svgs {
        report_check::parse_xml(svg);
    }
    // Pooling (default groups: material x age class): every group of 3 or more segments is
    // tested; a group holding a named segment detects thinning, or the compliance pair it is
    // reported in.
    let groups = rows(&out.join("groups.csv"));
    let group_of: BTreeMap<String, String> = diag
        .iter()
        .map(|r| (r["segment_id"].clone(), r["group"].clone()))
        .collect();
    for g in &groups {
        let n: usize = g["n_segments"].parse().unwrap();
        assert!(n >= 3, "{g:?}");
        let p: f64 = g["p_value"].parse().unwrap();
        assert!((0.0..=1.0).contains(&p), "{g:?}");
    }
    for id in &named {
        if let Some(g) = groups
            .iter()
            .find(|g| g["group"] == group_of[id] && !group_of[id].is_empty())
        {
            assert!(
                g["named_effect"] == "wall_thinning"
                    || g["ambiguous_with"].contains("wall_thinning"),
                "{g:?}"
            );
        }
    }
    assert!(html.contains("Pooled over groups") || groups.is_empty());

    // Step 3: the extended fits are stored and the effect is switched on for those segments.
    let conn = rusqlite::Connection::open(&db).unwrap();
    for id in &named {
        let (effects, ratio): (String, Option<f64>) = conn
            .query_row(
                "SELECT effects, wall_thickness_ratio FROM latest_fits WHERE segment_id = ?1",
                [id],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .unwrap();
        assert_eq!(effects, "wall_thinning");
        assert!(ratio.is_some());
        let set: String = conn
            .query_row(
                "SELECT effects FROM segment_effects WHERE segment_id = ?1",
                [id],
                |r| r.get(0),
            )
            .unwrap();
        assert_eq!(set, "wall_thinning");
    }
    let n_set: i64 = conn
        .query_row("SELECT count(*) FROM segment_effects", [], |r| r.get(0))
        .unwrap();
    assert_eq!(n_set as usize, named.len());
    drop(conn);

    // The next calibrate sees those fits as up to date; a forced one refits with the effect.
    let again = ok(&["calibrate", "--db", &s(&db), "--jobs", "2"]);
    assert!(String::from_utf8_lossy(&again.stdout).contains("calibrate: 0 fitted"));
    ok(&["calibrate", "--db", &s(&db), "--jobs", "2", "--force"]);
    let conn = rusqlite::Connection::open(&db).unwrap();
    for id in &named {
        let effects: String = conn
            .query_row(
                "SELECT effects FROM latest_fits WHERE segment_id = ?1",
                [id],
                |r| r.get(0),
            )
            .unwrap();
        assert_eq!(effects, "wall_thinning", "{id}");
    }
    let plain: i64 = conn
        .query_row(
            "SELECT count(*) FROM latest_fits WHERE effects = ''",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(plain as usize, 8 - named.len());
    // The export carries the effect.
    let gj = tmp.path().join("n.csv");
    ok(&[
        "export",
        "--db",
        &s(&db),
        "--format",
        "csv",
        "--out",
        &s(&gj),
    ]);
    let exported = rows(&gj);
    let with = exported
        .iter()
        .filter(|r| {
            r.get("effects")
                .map(|e| e == "wall_thinning")
                .unwrap_or(false)
        })
        .count();
    assert_eq!(with, named.len());
}

#[test]
fn diagnose_needs_a_database_and_names_missing_segments() {
    let tmp = tempfile::tempdir().unwrap();
    let out = bin()
        .args(["diagnose", "--db"])
        .arg(tmp.path().join("none.sqlite"))
        .arg("--out")
        .arg(tmp.path().join("d"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no pipewave database at"));
}
