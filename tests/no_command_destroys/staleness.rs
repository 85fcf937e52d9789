//! Defect 2: edits to the database by other tools are seen. Staleness is computed from the
//! stored rows themselves, so an edit by plain SQL to any input column makes the next
//! calibrate refit exactly the edited segment.

use std::collections::BTreeMap;

use rusqlite::Connection;

use crate::common::cli::{ok, pipewave};

/// Columns that are not inputs: bookkeeping, and the ids (a renamed segment is a new segment,
/// which has no fit and is fitted for that reason).
const NOT_EDITED: &[&str] = &["segment_id", "inputs_hash", "imported_at", "id"];

/// One plain-SQL edit per input column of `segments`, as `SET` expressions, each changing the
/// value to another one the model can use.
const SEGMENT_EDITS: &[(&str, &str)] = &[
    (
        "material",
        "CASE material WHEN 'DI' THEN 'CI' WHEN 'CI' THEN 'DI' WHEN 'ST' THEN 'DI' \
         WHEN 'PVC' THEN 'MDPE' WHEN 'MDPE' THEN 'HDPE' WHEN 'HDPE' THEN 'MDPE' ELSE 'DI' END",
    ),
    ("outer_diameter_mm", "outer_diameter_mm * 1.01"),
    ("wall_thickness_mm", "wall_thickness_mm * 0.5"),
    ("soil_density_kg_m3", "soil_density_kg_m3 * 1.01"),
    (
        "pipe_youngs_modulus_pa",
        "COALESCE(pipe_youngs_modulus_pa * 1.01, CASE WHEN material IN ('DI', 'CI', 'ST') \
         THEN 1.6e11 WHEN material = 'AC' THEN 2.3e10 ELSE 1.5e9 END)",
    ),
    ("pipe_poisson", "COALESCE(pipe_poisson * 1.01, 0.3)"),
    (
        "pipe_density_kg_m3",
        "COALESCE(pipe_density_kg_m3 * 1.01, CASE WHEN material IN ('DI', 'CI', 'ST') \
         THEN 7100 WHEN material = 'AC' THEN 2000 ELSE 1200 END)",
    ),
    (
        "pipe_loss_factor",
        "COALESCE(pipe_loss_factor * 1.01, 0.05)",
    ),
    (
        "fluid_density_kg_m3",
        "COALESCE(fluid_density_kg_m3 * 1.01, 999)",
    ),
    (
        "fluid_bulk_modulus_pa",
        "COALESCE(fluid_bulk_modulus_pa * 1.01, 2.2e9)",
    ),
    ("length_m", "COALESCE(length_m * 1.01, 100)"),
    ("soil_type", "COALESCE(soil_type || 'x', 'clay')"),
    ("install_year", "COALESCE(install_year + 1, 1970)"),
    (
        "geometry_wkt",
        "CASE WHEN geometry_wkt IS NULL THEN 'LINESTRING (0 0, 10 0)' ELSE NULL END",
    ),
    ("srid", "CASE WHEN srid IS NULL THEN 27700 ELSE NULL END"),
    ("soil_zone", "COALESCE(soil_zone || 'x', 'Z9')"),
    ("risk_weight", "COALESCE(risk_weight * 2, 2)"),
    (
        "soil_class_override",
        "COALESCE(soil_class_override || 'x', soil_type, 'clay')",
    ),
];

/// One edit per input column of `measurements`, applied to one row of the segment.
const MEASUREMENT_EDITS: &[(&str, &str)] = &[
    ("omega_rad_s", "omega_rad_s * 1.001"),
    ("frequency_hz", "frequency_hz * 1.001"),
    ("k_re_rad_per_m", "k_re_rad_per_m * 1.5"),
    ("attenuation_np_per_m", "attenuation_np_per_m * 1.01"),
    (
        "k_re_std",
        "COALESCE(k_re_std * 1.1, 0.01 * k_re_rad_per_m)",
    ),
    (
        "attenuation_std",
        "COALESCE(attenuation_std * 1.1, 0.1 * attenuation_np_per_m)",
    ),
    ("measured_on", "COALESCE(measured_on || 'x', '2027-05-01')"),
    ("campaign", "campaign || '-edited'"),
    ("note", "COALESCE(note || 'x', 'reflection_suspected')"),
];

fn columns(conn: &Connection, table: &str) -> Vec<String> {
    let mut st = conn
        .prepare(&format!("SELECT name FROM pragma_table_info('{table}')"))
        .unwrap();
    st.query_map([], |r| r.get(0))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap()
}

/// Each segment's newest fit id.
fn latest_fits(conn: &Connection) -> BTreeMap<String, i64> {
    let mut st = conn
        .prepare("SELECT segment_id, MAX(id) FROM fits GROUP BY segment_id")
        .unwrap();
    st.query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap()
}

fn calibrate(db: &str) {
    let o = pipewave()
        .args(["calibrate", "--db", db, "--jobs", "2"])
        .output()
        .unwrap();
    assert!(
        matches!(o.status.code(), Some(0 | 1)),
        "calibrate: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Every input column of both tables, edited by plain SQL one at a time on a different segment
/// each: the next calibrate refits exactly that segment, and a calibrate after it refits nothing.
/// Deleting and adding a measurement row do the same.
#[test]
fn defect_02_edits_by_other_tools_make_exactly_the_edited_segments_stale() {
    let dir = tempfile::tempdir().unwrap();
    let net = dir.path().join("net");
    ok(&[
        "synth",
        "--out",
        net.to_str().unwrap(),
        "--segments",
        "10",
        "--seed",
        "7",
        "--no-real-cases",
        "--defects",
        "0",
    ]);
    let db = dir.path().join("edit.sqlite");
    let db_s = db.to_str().unwrap().to_string();
    ok(&["run", net.to_str().unwrap(), "--db", &db_s]);
    let conn = Connection::open(&db).unwrap();
    // The edits cover every column the tables have now, so a column a later migration adds
    // fails this test until it is covered.
    for (table, edits) in [
        ("segments", SEGMENT_EDITS),
        ("measurements", MEASUREMENT_EDITS),
    ] {
        for c in columns(&conn, table) {
            assert!(
                NOT_EDITED.contains(&c.as_str()) || edits.iter().any(|(n, _)| *n == c),
                "{table}.{c} has no edit in this test"
            );
        }
    }
    let ids: Vec<String> = latest_fits(&conn).into_keys().collect();
    assert_eq!(ids.len(), 10);
    let mut edits: Vec<(String, String)> = Vec::new();
    for (i, (col, expr)) in SEGMENT_EDITS.iter().enumerate() {
        let id = &ids[i % ids.len()];
        edits.push((
            format!("segments.{col}"),
            format!("UPDATE segments SET {col} = {expr} WHERE segment_id = '{id}'"),
        ));
    }
    for (i, (col, expr)) in MEASUREMENT_EDITS.iter().enumerate() {
        let id = &ids[(i + 3) % ids.len()];
        edits.push((
            format!("measurements.{col}"),
            format!(
                "UPDATE measurements SET {col} = {expr} WHERE id = \
                 (SELECT MIN(id) FROM measurements WHERE segment_id = '{id}')"
            ),
        ));
    }
    edits.push((
        "a deleted measurement".into(),
        format!(
            "DELETE FROM measurements WHERE id = (SELECT MAX(id) FROM measurements WHERE \
             segment_id = '{}')",
            ids[5]
        ),
    ));
    edits.push((
        "an added measurement".into(),
        format!(
            "INSERT INTO measurements (segment_id, omega_rad_s, frequency_hz, k_re_rad_per_m, \
             attenuation_np_per_m) SELECT segment_id, omega_rad_s * 1.1, frequency_hz * 1.1, \
             k_re_rad_per_m * 1.1, attenuation_np_per_m FROM measurements WHERE id = \
             (SELECT MAX(id) FROM measurements WHERE segment_id = '{}')",
            ids[6]
        ),
    ));
    for (what, sql) in &edits {
        let id = ids
            .iter()
            .find(|id| sql.contains(&format!("'{id}'")))
            .unwrap();
        let before = latest_fits(&conn);
        assert_eq!(conn.execute(sql, []).unwrap(), 1, "{what}: {sql}");
        calibrate(&db_s);
        let after = latest_fits(&conn);
        let refitted: Vec<&String> = after
            .iter()
            .filter(|(k, v)| before.get(*k) != Some(v))
            .map(|(k, _)| k)
            .collect();
        assert_eq!(refitted, [id], "{what}: refitted {refitted:?}, edited {id}");
        calibrate(&db_s);
        assert_eq!(
            latest_fits(&conn),
            after,
            "{what}: a second calibrate refitted"
        );
    }
}
