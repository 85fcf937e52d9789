//! The soil field's user features (model §7.12): `speed_source` with its reason for every
//! segment in every export, the class a user forces with `soil_class_override`, and `plan`'s
//! `risk_weight` and its statement of the hypothetical measurement (P83).

use std::collections::BTreeMap;
use std::path::Path;

use pipewave::field::plan::HYPOTHETICAL_MEASUREMENT;
mod common;
use common::cli::ok as run;

/// One exported row: speed_source, its reason, the speed and its error, and the class columns.
#[derive(Debug, Clone, PartialEq)]
struct Row {
    source: String,
    reason: String,
    speed: Option<f64>,
    std: Option<f64>,
    soil_class: Option<String>,
    class_overridden: Option<i64>,
    label_rejected: Option<i64>,
}

/// The rows of an export CSV, by segment id.
fn csv_rows(path: &Path) -> BTreeMap<String, Row> {
    let mut rdr = csv::Reader::from_path(path).unwrap();
    let h = rdr.headers().unwrap().clone();
    let col = |n: &str| {
        h.iter()
            .position(|c| c == n)
            .unwrap_or_else(|| panic!("no {n}"))
    };
    let c = [
        col("segment_id"),
        col("speed_source"),
        col("speed_source_reason"),
        col("leak_band_speed_m_per_s"),
        col("leak_band_speed_std_m_per_s"),
        col("soil_class"),
        col("class_overridden"),
        col("label_rejected"),
    ];
    rdr.records()
        .map(|r| {
            let r = r.unwrap();
            let text = |i: usize| Some(r[c[i]].to_string()).filter(|s| !s.is_empty());
            (
                r[c[0]].to_string(),
                Row {
                    source: r[c[1]].to_string(),
                    reason: r[c[2]].to_string(),
                    speed: text(3).map(|v| v.parse().unwrap()),
                    std: text(4).map(|v| v.parse().unwrap()),
                    soil_class: text(5),
                    class_overridden: text(6).map(|v| v.parse().unwrap()),
                    label_rejected: text(7).map(|v| v.parse().unwrap()),
                },
            )
        })
        .collect()
}

/// The rows of an export GeoJSON, by segment id.
fn geojson_rows(path: &Path) -> BTreeMap<String, Row> {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    v["features"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let p = &f["properties"];
            let s = |n: &str| p[n].as_str().map(str::to_string);
            (
                s("segment_id").unwrap(),
                Row {
                    source: s("speed_source").unwrap_or_default(),
                    reason: s("speed_source_reason").unwrap_or_default(),
                    speed: p["leak_band_speed_m_per_s"].as_f64(),
                    std: p["leak_band_speed_std_m_per_s"].as_f64(),
                    soil_class: s("soil_class"),
                    class_overridden: p["class_overridden"].as_i64(),
                    label_rejected: p["label_rejected"].as_i64(),
                },
            )
        })
        .collect()
}

/// The rows of an export GeoPackage's segment layer, by segment id.
fn gpkg_rows(path: &Path) -> BTreeMap<String, Row> {
    let conn = rusqlite::Connection::open(path).unwrap();
    let mut stmt = conn
        .prepare(
            "SELECT segment_id, speed_source, speed_source_reason, leak_band_speed_m_per_s, \
             leak_band_speed_std_m_per_s, soil_class, class_overridden, label_rejected \
             FROM pipe_segments",
        )
        .unwrap();
    let rows = stmt
        .query_map([], |r| {
            Ok((
                r.get::<_, String>(0)?,
                Row {
                    source: r.get::<_, Option<String>>(1)?.unwrap_or_default(),
                    reason: r.get::<_, Option<String>>(2)?.unwrap_or_default(),
                    speed: r.get(3)?,
                    std: r.get(4)?,
                    soil_class: r.get(5)?,
                    class_overridden: r.get(6)?,
                    label_rejected: r.get(7)?,
                },
            ))
        })
        .unwrap();
    rows.map(Result::unwrap).collect()
}

/// The sample network's first `n` segments (the inventory as csv records).
fn sample_segments(n: usize) -> (csv::StringRecord, Vec<csv::StringRecord>) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_network/segments.csv");
    let mut rdr = csv::Reader::from_path(src).unwrap();
    let h = rdr.headers().unwrap().clone();
    let rows: Vec<csv::StringRecord> = rdr.records().take(n).map(Result::unwrap).collect();
    (h, rows)
}

fn write_csv(path: &Path, header: &[&str], rows: &[Vec<String>]) {
    let mut w = csv::Writer::from_path(path).unwrap();
    w.write_record(header).unwrap();
    for r in rows {
        w.write_record(r).unwrap();
    }
    w.flush().unwrap();
}

/// The measurements of the sample network for the segments `ids`.
fn sample_measurements(path: &Path, ids: &[String]) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_network/measurements.csv");
    let text = std::fs::read_to_string(src).unwrap();
    let mut lines = text.lines();
    let mut out = vec![lines.next().unwrap().to_string()];
    out.extend(
        lines
            .filter(|l| {
                ids.iter()
                    .any(|id| l.split(',').next() == Some(id.as_str()))
            })
            .map(str::to_string),
    );
    std::fs::write(path, out.join("\n") + "\n").unwrap();
}

/// Every export (CSV, GeoJSON, GeoPackage) gives every segment a `speed_source` and a reason:
/// `fitted` for a segment with its own fit; `predicted` (with a speed, an error and what it
/// rests on) for a segment without measurements, one whose measurements were never fitted,
/// one whose fit failed, and one without geometry (its class mean); `none` only where the
/// field has nothing to offer: a segment imported after the last update, and a network with
/// no fitted segment at all. A `soil_class_override` sets the class the field uses, reported
/// in the exports; `plan` states its hypothetical measurement once and weights by
/// `risk_weight` where given.
#[test]
fn every_export_gives_every_segment_a_speed_source_and_its_reason() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (h, rows) = sample_segments(45);
    let ci = |n: &str| h.iter().position(|c| c == n).unwrap();
    let (id_c, geom_c, srid_c, soil_c) = (
        ci("segment_id"),
        ci("geometry_wkt"),
        ci("srid"),
        ci("soil_type"),
    );
    let ids: Vec<String> = rows.iter().map(|r| r[id_c].to_string()).collect();
    // Every third of the segments the sample measured (a fifth of its pipes have no data).
    let sample_measured: std::collections::BTreeSet<String> = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_network/measurements.csv"),
    )
    .unwrap()
    .lines()
    .skip(1)
    .filter_map(|l| l.split(',').next().map(str::to_string))
    .collect();
    let measured: Vec<String> = ids
        .iter()
        .filter(|id| sample_measured.contains(*id))
        .step_by(3)
        .cloned()
        .collect();
    // A: measured but never fitted; B: its fit failed; G: unmeasured, no geometry;
    // X: unmeasured, its class forced to one no neighbour carries.
    let (a, b) = (measured[1].clone(), measured[2].clone());
    let (g, x) = (ids[1].clone(), ids[4].clone());
    assert!(!measured.contains(&g) && !measured.contains(&x));
    let mut header: Vec<&str> = h.iter().collect();
    header.push("soil_class_override");
    let inventory: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            let mut v: Vec<String> = r.iter().map(str::to_string).collect();
            if v[id_c] == g {
                v[geom_c].clear();
                v[srid_c].clear();
            }
            v.push(if v[id_c] == x {
                "peat".into()
            } else {
                String::new()
            });
            v
        })
        .collect();
    assert!(inventory.iter().all(|r| r[soil_c] != "peat"));
    write_csv(&d.join("segments.csv"), &header, &inventory);
    sample_measurements(&d.join("measurements.csv"), &measured);
    let db = d.join("net.sqlite");
    let dbs = db.to_str().unwrap();
    let seg_csv = d.join("segments.csv");
    let meas_csv = d.join("measurements.csv");
    run(&[
        "import",
        "--db",
        dbs,
        "--segments",
        seg_csv.to_str().unwrap(),
        "--measurements",
        meas_csv.to_str().unwrap(),
    ]);
    // Fit every measured segment but A.
    let mut args = vec!["calibrate", "--db", dbs, "--jobs", "2"];
    for id in measured.iter().filter(|id| **id != a) {
        args.extend(["--segment", id.as_str()]);
    }
    run(&args);
    // B's fit stored as a failed fit is (status failed, its reason, no speeds); the field is
    // then rebuilt by a run that fits nothing.
    let conn = rusqlite::Connection::open(&db).unwrap();
    conn.execute(
        "UPDATE fits SET status = 'failed', message = 'no root on the search path', \
         leak_band_speed_m_per_s = NULL, leak_band_speed_std_m_per_s = NULL, \
         soil_p_wave_speed_m_per_s = NULL, soil_s_wave_speed_m_per_s = NULL, \
         soil_information_pp = NULL, soil_information_ps = NULL, soil_information_ss = NULL \
         WHERE segment_id = ?1",
        [&b],
    )
    .unwrap();
    conn.execute("UPDATE field_runs SET fingerprint = 'stale'", [])
        .unwrap();
    drop(conn);
    let out = run(&[
        "calibrate",
        "--db",
        dbs,
        "--jobs",
        "2",
        "--segment",
        &measured[0],
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(!stdout.contains("field: up to date"), "{stdout}");
    // N: imported after the last field update.
    let mut extra = inventory[0].clone();
    extra[id_c] = "NEW-1".into();
    write_csv(&d.join("new.csv"), &header, &[extra]);
    run(&[
        "import",
        "--db",
        dbs,
        "--segments",
        d.join("new.csv").to_str().unwrap(),
    ]);

    let csv_out = d.join("out.csv");
    let json_out = d.join("out.geojson");
    let gpkg_out = d.join("out.gpkg");
    for (format, out) in [
        ("csv", &csv_out),
        ("geojson", &json_out),
        ("gpkg", &gpkg_out),
    ] {
        run(&[
            "export",
            "--db",
            dbs,
            "--format",
            format,
            "--out",
            out.to_str().unwrap(),
        ]);
    }
    let exports = [
        ("csv", csv_rows(&csv_out)),
        ("geojson", geojson_rows(&json_out)),
        ("gpkg", gpkg_rows(&gpkg_out)),
    ];
    let fitted: Vec<&String> = measured
        .iter()
        .filter(|id| **id != a && **id != b)
        .collect();
    for (format, rows) in &exports {
        assert_eq!(rows.len(), ids.len() + 1, "{format}");
        for (id, r) in rows {
            assert!(!r.reason.is_empty(), "{format} {id}: {r:?}");
            let with_speed =
                r.speed.is_some_and(|v| v > 50.0 && v < 1600.0) && r.std.is_some_and(|v| v > 0.0);
            match r.source.as_str() {
                "fitted" => {
                    assert!(fitted.contains(&id), "{format} {id}: {r:?}");
                    assert!(with_speed, "{format} {id}: {r:?}");
                    assert!(r.reason.starts_with("fitted to "), "{format} {id}: {r:?}");
                }
                "predicted" => {
                    assert!(!fitted.contains(&id) && id != "NEW-1", "{format} {id}");
                    assert!(with_speed, "{format} {id}: {r:?}");
                    assert!(r.reason.contains("soil class"), "{format} {id}: {r:?}");
                }
                "none" => {
                    assert_eq!(id, "NEW-1", "{format}: {r:?}");
                    assert!(r.speed.is_none() && r.std.is_none(), "{format}: {r:?}");
                    assert!(r.reason.contains("run calibrate"), "{format}: {r:?}");
                }
                other => panic!("{format} {id}: speed_source {other}"),
            }
        }
        let count = |s: &str| rows.values().filter(|r| r.source == s).count();
        assert_eq!(count("fitted"), fitted.len(), "{format}");
        assert_eq!(count("predicted"), ids.len() - fitted.len(), "{format}");
        // Never fitted and failed: predicted from the measured neighbours.
        for id in [&a, &b] {
            assert_eq!(rows[id].source, "predicted", "{format} {id}");
            assert!(
                rows[id].reason.contains("measured segment"),
                "{format} {id}: {:?}",
                rows[id]
            );
        }
        assert!(
            rows[&g]
                .reason
                .starts_with("no geometry: the mean of soil class"),
            "{format}: {:?}",
            rows[&g]
        );
        // The override: class peat, reported, never rejected; nobody else is overridden.
        assert_eq!(rows[&x].soil_class.as_deref(), Some("peat"), "{format}");
        assert_eq!(rows[&x].class_overridden, Some(1), "{format}");
        assert_eq!(rows[&x].label_rejected, Some(0), "{format}");
        assert!(
            rows[&x].reason.contains("soil_class_override"),
            "{format}: {:?}",
            rows[&x]
        );
        let overridden = rows
            .values()
            .filter(|r| r.class_overridden == Some(1))
            .count();
        assert_eq!(overridden, 1, "{format}");
    }
    // The three formats agree on every segment's source and reason.
    for (format, rows) in &exports[1..] {
        for (id, r) in rows {
            let c = &exports[0].1[id];
            assert_eq!(
                (&r.source, &r.reason),
                (&c.source, &c.reason),
                "{format} {id}"
            );
        }
    }
    let conn = rusqlite::Connection::open(&db).unwrap();
    let stored: i64 = conn
        .query_row(
            "SELECT class_overridden FROM field_segments WHERE segment_id = ?1",
            [&x],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(stored, 1);
    drop(conn);
    // The audit report says which class came from an override.
    let report = d.join("audit.html");
    run(&["audit", "--db", dbs, "--out", report.to_str().unwrap()]);
    let html = std::fs::read_to_string(&report).unwrap();
    assert!(
        html.contains("1 segment takes its class from the inventory's soil_class_override"),
        "no override line in the audit report"
    );

    // plan: the statement of the hypothetical measurement, once; the weight is the length.
    let next = d.join("next.csv");
    let plan = |count: &str| {
        let out = run(&[
            "plan",
            "--db",
            dbs,
            "--count",
            count,
            "--out",
            next.to_str().unwrap(),
        ]);
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let stdout = plan("3");
    assert_eq!(
        stdout.matches(HYPOTHETICAL_MEASUREMENT).count(),
        1,
        "{stdout}"
    );
    // No jargon; the gain is told in the user's units (issue 64).
    assert!(!stdout.contains("entrywise"), "{stdout}");
    assert!(
        stdout.contains("their frequencies and their noise"),
        "{stdout}"
    );
    let gain_line = stdout
        .lines()
        .find(|l| l.starts_with("plan: expected_gain is"))
        .unwrap_or_else(|| panic!("no gain line: {stdout}"));
    assert!(gain_line.contains("metres of pipe"), "{gain_line}");
    assert!(gain_line.contains("m of pipe"), "{gain_line}");
    assert!(stdout.contains("weight: length in m"), "{stdout}");
    let picks = |path: &Path| -> Vec<(String, f64)> {
        let mut rdr = csv::Reader::from_path(path).unwrap();
        let h = rdr.headers().unwrap().clone();
        let w = h.iter().position(|c| c == "weight").unwrap();
        rdr.records()
            .map(|r| {
                let r = r.unwrap();
                (r[0].to_string(), r[w].parse().unwrap())
            })
            .collect()
    };
    let by_length = picks(&next);
    assert_eq!(by_length.len(), 3);
    // A risk weight on one unmeasured plastic pipe (its speed error is per cent, not per mille
    // as a metal pipe's) that length alone does not pick first: a weight a thousand times the
    // network's length makes its own error dominate the sum (P83), so it is measured first,
    // and the weight column shows it.
    let mat_c = ci("material");
    let plastic = |id: &String| {
        rows.iter().any(|r| {
            &r[id_c] == id.as_str()
                && matches!(r[mat_c].to_uppercase().as_str(), "PVC" | "MDPE" | "HDPE")
        })
    };
    let r_id = ids
        .iter()
        .find(|id| {
            !measured.contains(id)
                && **id != g
                && **id != x
                && **id != by_length[0].0
                && plastic(id)
        })
        .unwrap()
        .clone();
    let mut row = inventory.iter().find(|r| r[id_c] == r_id).unwrap().clone();
    row.pop();
    let mut risk_header: Vec<&str> = h.iter().collect();
    risk_header.push("risk_weight");
    row.push("1e6".into());
    write_csv(&d.join("risk.csv"), &risk_header, &[row]);
    run(&[
        "import",
        "--db",
        dbs,
        "--segments",
        d.join("risk.csv").to_str().unwrap(),
    ]);
    let stdout = plan("3");
    assert!(
        stdout.contains("weight: risk_weight (1 segment), length in m elsewhere"),
        "{stdout}"
    );
    let by_risk = picks(&next);
    assert_eq!(by_risk[0], (r_id.clone(), 1e6), "{by_risk:?}");
    assert!(by_risk[1..].iter().all(|p| p.1 < 1e3), "{by_risk:?}");
}

/// A network without a fitted segment: the field has nothing to learn the soil from, so every
/// segment's speed is `none`, and the reason says so.
#[test]
fn without_a_fitted_segment_every_speed_is_none_with_its_reason() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (h, rows) = sample_segments(4);
    let header: Vec<&str> = h.iter().collect();
    let rows: Vec<Vec<String>> = rows
        .iter()
        .map(|r| r.iter().map(str::to_string).collect())
        .collect();
    write_csv(&d.join("segments.csv"), &header, &rows);
    let db = d.join("net.sqlite");
    let dbs = db.to_str().unwrap();
    run(&[
        "import",
        "--db",
        dbs,
        "--segments",
        d.join("segments.csv").to_str().unwrap(),
    ]);
    run(&["calibrate", "--db", dbs, "--jobs", "1"]);
    let out = d.join("out.csv");
    run(&[
        "export",
        "--db",
        dbs,
        "--format",
        "csv",
        "--out",
        out.to_str().unwrap(),
    ]);
    let rows = csv_rows(&out);
    assert_eq!(rows.len(), 4);
    for (id, r) in &rows {
        assert_eq!(r.source, "none", "{id}: {r:?}");
        assert_eq!(
            r.reason, "no fitted segment in the network to learn the soil from",
            "{id}"
        );
        assert!(r.speed.is_none() && r.std.is_none(), "{id}: {r:?}");
    }
}
