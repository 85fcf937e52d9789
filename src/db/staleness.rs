//! What a fit was made from, read from the stored rows themselves.
//!
//! A segment's `inputs_hash` is the FNV-1a hash ([`super::hash`]) of a canonical text of its
//! `segments` row and of every one of its `measurements` rows, column by column, as SQLite
//! holds them now. Every column counts except bookkeeping ([`SEGMENT_BOOKKEEPING`],
//! [`MEASUREMENT_BOOKKEEPING`]), so a change made with any tool (QGIS, DB Browser, plain SQL)
//! to any input, a campaign label or a date included, makes the segment's fit stale; a column a
//! later migration adds counts from then on without a change here. A fit stores the hash it
//! was made from, and `calibrate` recomputes every segment's hash before it selects what to fit
//! ([`refresh_all_inputs_hashes`]): one ordered pass over the two tables.

use rusqlite::types::ValueRef;
use rusqlite::{params, Connection, Statement};

use super::hash::Canonical;
use super::DbError;

/// Columns of `segments` that record how a row was stored, not what a fit uses.
pub const SEGMENT_BOOKKEEPING: &[&str] = &["inputs_hash", "imported_at"];
/// Columns of `measurements` that identify a row rather than describe the measurement (the
/// row id changes when a measurement is written again; the segment is the one hashed).
pub const MEASUREMENT_BOOKKEEPING: &[&str] = &["id", "segment_id"];

/// The version tag of the canonical text: a change of its form changes every hash, and with it
/// every fit's staleness.
const TAG: &str = "pipewave-inputs-v2";

/// Append one stored value to a canonical text, by its SQLite storage class: a REAL as its
/// shortest round-trip digits, an INTEGER exactly, a TEXT length-prefixed, a BLOB as hex, NULL
/// as `-` ([`Canonical`]). The class is part of the text, so `1` and `1.0` differ, as they do
/// in the table.
fn push_value(c: &mut Canonical, key: &str, v: ValueRef<'_>) {
    match v {
        ValueRef::Null => c.text(key, None),
        ValueRef::Integer(i) => c.int(key, Some(i)),
        ValueRef::Real(x) => c.num(key, Some(x)),
        ValueRef::Text(t) => c.text(key, Some(&String::from_utf8_lossy(t))),
        ValueRef::Blob(b) => {
            let hex: String = b.iter().map(|x| format!("{x:02x}")).collect();
            c.text(key, Some(&format!("blob:{hex}")))
        }
    };
}

/// The canonical text of the current row of `stmt`'s query, without the `skip` columns.
fn row_text(names: &[String], row: &rusqlite::Row<'_>, skip: &[&str]) -> rusqlite::Result<String> {
    let mut c = Canonical::default();
    for (i, name) in names.iter().enumerate() {
        if !skip.contains(&name.as_str()) {
            push_value(&mut c, name, row.get_ref(i)?);
        }
    }
    Ok(c.as_str().to_string())
}

/// The hash of a segment from its row's text and its measurements' texts, in any order (they
/// are sorted, so the hash does not depend on the order rows were stored in).
fn hash_of(segment: &str, mut measurements: Vec<String>) -> String {
    measurements.sort_unstable();
    let mut c = Canonical::new(TAG);
    c.text("segment", Some(segment)).int(
        "measurements",
        Some(i64::try_from(measurements.len()).unwrap_or(i64::MAX)),
    );
    for m in &measurements {
        c.text("measurement", Some(m));
    }
    c.hash_hex()
}

fn column_names(stmt: &Statement<'_>) -> Vec<String> {
    stmt.column_names().iter().map(|s| s.to_string()).collect()
}

/// The inputs hash of one segment as stored now (`None`: no such segment).
pub fn stored_inputs_hash(conn: &Connection, segment_id: &str) -> Result<Option<String>, DbError> {
    let mut seg = conn.prepare_cached("SELECT * FROM segments WHERE segment_id = ?1")?;
    let names = column_names(&seg);
    let mut rows = seg.query([segment_id])?;
    let Some(r) = rows.next()? else {
        return Ok(None);
    };
    let segment = row_text(&names, r, SEGMENT_BOOKKEEPING)?;
    let mut ms = conn.prepare_cached("SELECT * FROM measurements WHERE segment_id = ?1")?;
    let m_names = column_names(&ms);
    let texts = ms
        .query_map([segment_id], |r| {
            row_text(&m_names, r, MEASUREMENT_BOOKKEEPING)
        })?
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Some(hash_of(&segment, texts)))
}

/// Recompute and store a segment's `inputs_hash` from what is in the database now. Returns true
/// when the stored hash changed.
pub fn refresh_inputs_hash(conn: &Connection, segment_id: &str) -> Result<bool, DbError> {
    let Some(hash) = stored_inputs_hash(conn, segment_id)? else {
        return Ok(false);
    };
    let n = conn
        .prepare_cached(
            "UPDATE segments SET inputs_hash = ?2 WHERE segment_id = ?1 AND inputs_hash IS NOT ?2",
        )?
        .execute(params![segment_id, hash])?;
    Ok(n > 0)
}

/// What [`refresh_all_inputs_hashes`] found.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct InputsSweep {
    /// Segments hashed.
    pub segments: usize,
    /// Measurement rows read.
    pub measurements: usize,
    /// The segments whose stored inputs changed since their hash was last stored (edited by
    /// another tool), by id.
    pub changed: Vec<String>,
    /// The segments hashed for the first time (an empty stored hash: a segment stored before
    /// hashes took this form, or inserted by another tool).
    pub first_hashed: usize,
}

/// Recompute every segment's inputs hash from its stored row and measurements, and store the
/// ones that changed (one transaction). One pass over each table in `segment_id` order, merged
/// as they stream: what it holds is one segment's rows.
pub fn refresh_all_inputs_hashes(conn: &mut Connection) -> Result<InputsSweep, DbError> {
    let mut sweep = InputsSweep::default();
    let mut updates: Vec<(String, String)> = Vec::new();
    {
        let mut seg = conn.prepare("SELECT * FROM segments ORDER BY segment_id")?;
        let names = column_names(&seg);
        let id_at = names.iter().position(|n| n == "segment_id");
        let hash_at = names.iter().position(|n| n == "inputs_hash");
        let (Some(id_at), Some(hash_at)) = (id_at, hash_at) else {
            return Ok(sweep);
        };
        let mut ms = conn.prepare("SELECT * FROM measurements ORDER BY segment_id")?;
        let m_names = column_names(&ms);
        let Some(m_id_at) = m_names.iter().position(|n| n == "segment_id") else {
            return Ok(sweep);
        };
        let mut m_rows = ms.query([])?;
        // The next measurement row not yet given to a segment: (its segment, its text).
        let mut pending: Option<(String, String)> = None;
        let mut next_measurement =
            |pending: &mut Option<(String, String)>| -> rusqlite::Result<()> {
                *pending = match m_rows.next()? {
                    Some(r) => Some((
                        r.get::<_, String>(m_id_at)?,
                        row_text(&m_names, r, MEASUREMENT_BOOKKEEPING)?,
                    )),
                    None => None,
                };
                Ok(())
            };
        next_measurement(&mut pending)?;
        let mut rows = seg.query([])?;
        while let Some(r) = rows.next()? {
            let id: String = r.get(id_at)?;
            let stored: String = r.get(hash_at)?;
            let text = row_text(&names, r, SEGMENT_BOOKKEEPING)?;
            // Measurements of segments that sort before this one have no segment (a foreign
            // key prevents them; a database edited with the keys off may have some): skipped.
            let mut texts = Vec::new();
            while let Some((mid, _)) = &pending {
                match mid.as_str().cmp(id.as_str()) {
                    std::cmp::Ordering::Less => next_measurement(&mut pending)?,
                    std::cmp::Ordering::Equal => {
                        if let Some((_, t)) = pending.take() {
                            texts.push(t);
                        }
                        next_measurement(&mut pending)?;
                    }
                    std::cmp::Ordering::Greater => break,
                }
            }
            sweep.segments += 1;
            sweep.measurements += texts.len();
            let fresh = hash_of(&text, texts);
            if fresh != stored {
                if stored.is_empty() {
                    sweep.first_hashed += 1;
                } else {
                    sweep.changed.push(id.clone());
                }
                updates.push((id, fresh));
            }
        }
    }
    if !updates.is_empty() {
        let tx = conn.transaction()?;
        {
            let mut up =
                tx.prepare("UPDATE segments SET inputs_hash = ?2 WHERE segment_id = ?1")?;
            for (id, h) in &updates {
                up.execute(params![id, h])?;
            }
        }
        tx.commit()?;
    }
    Ok(sweep)
}

/// Fill an empty database with `segments` plastic segments of `per_segment` measurements each
/// (every one in campaign `bench`), for timing [`refresh_all_inputs_hashes`] at a network's
/// size (`pipewave bench --staleness N`). One transaction; the values are plausible, not fitted.
pub fn fill_for_bench(
    conn: &mut Connection,
    segments: usize,
    per_segment: usize,
) -> Result<(), DbError> {
    let tx = conn.transaction()?;
    let n = i64::try_from(segments).unwrap_or(i64::MAX);
    let k = i64::try_from(per_segment).unwrap_or(i64::MAX);
    tx.execute(
        "WITH RECURSIVE i(x) AS (SELECT 1 UNION ALL SELECT x + 1 FROM i WHERE x < ?1) \
         INSERT INTO segments (segment_id, material, outer_diameter_mm, wall_thickness_mm, \
         soil_density_kg_m3, length_m, soil_type) \
         SELECT printf('B%07d', x), 'MDPE', 180, 16.4, 1800 + (x % 400), 50 + (x % 97), 'clay' \
         FROM i",
        [n],
    )?;
    tx.execute(
        "WITH RECURSIVE j(y) AS (SELECT 1 UNION ALL SELECT y + 1 FROM j WHERE y < ?1) \
         INSERT INTO measurements (segment_id, campaign, omega_rad_s, frequency_hz, \
         k_re_rad_per_m, attenuation_np_per_m, k_re_std, attenuation_std, measured_on) \
         SELECT s.segment_id, 'bench', 6.283185307179586 * 50 * j.y, 50 * j.y, \
         6.283185307179586 * 50 * j.y / 400.0, 0.02 * j.y, 0.002 * j.y, 0.002, '2026-05-01' \
         FROM segments s, j",
        [k],
    )?;
    tx.commit()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::migrate;

    fn db() -> Connection {
        let mut conn = Connection::open_in_memory().unwrap();
        conn.pragma_update(None, "foreign_keys", true).unwrap();
        migrate::migrate(&mut conn, std::path::Path::new(":memory:")).unwrap();
        conn.execute_batch(
            "INSERT INTO segments (segment_id, material, outer_diameter_mm, wall_thickness_mm, \
             soil_density_kg_m3) VALUES ('A', 'DI', 170, 6, 1900), ('B', 'PVC', 110, 5.3, 1800);
             INSERT INTO measurements (segment_id, omega_rad_s, frequency_hz, k_re_rad_per_m, \
             attenuation_np_per_m) VALUES ('A', 628.3, 100, 0.5, 0.01), ('A', 1256.6, 200, 1.0, 0.02), \
             ('B', 628.3, 100, 1.3, 0.05);",
        )
        .unwrap();
        conn
    }

    /// The sweep and the one-segment hash agree, a second sweep finds nothing, and an edit to
    /// one column of one row makes exactly that segment changed.
    #[test]
    fn an_edit_to_any_column_changes_exactly_its_segment() {
        let mut conn = db();
        let first = refresh_all_inputs_hashes(&mut conn).unwrap();
        assert_eq!((first.segments, first.measurements), (2, 3));
        assert!(first.changed.is_empty());
        assert_eq!(first.first_hashed, 2);
        for id in ["A", "B"] {
            let stored: String = conn
                .query_row(
                    "SELECT inputs_hash FROM segments WHERE segment_id = ?1",
                    [id],
                    |r| r.get(0),
                )
                .unwrap();
            assert_eq!(Some(stored), stored_inputs_hash(&conn, id).unwrap());
        }
        assert!(refresh_all_inputs_hashes(&mut conn)
            .unwrap()
            .changed
            .is_empty());
        for edit in [
            "UPDATE measurements SET campaign = 'FD-2027' WHERE segment_id = 'A' AND frequency_hz = 200",
            "UPDATE measurements SET measured_on = '2027-05-01' WHERE segment_id = 'A' AND frequency_hz = 200",
            "UPDATE measurements SET k_re_rad_per_m = 1.5 WHERE segment_id = 'A' AND frequency_hz = 200",
            "UPDATE segments SET wall_thickness_mm = 3 WHERE segment_id = 'A'",
            "UPDATE segments SET risk_weight = 2 WHERE segment_id = 'A'",
            "DELETE FROM measurements WHERE segment_id = 'A' AND frequency_hz = 100",
        ] {
            conn.execute_batch(edit).unwrap();
            assert_eq!(refresh_all_inputs_hashes(&mut conn).unwrap().changed, ["A"], "{edit}");
        }
        // Bookkeeping is not an input.
        conn.execute_batch("UPDATE segments SET imported_at = 'x'")
            .unwrap();
        assert!(refresh_all_inputs_hashes(&mut conn)
            .unwrap()
            .changed
            .is_empty());
    }

    /// The hash of a stored row must not change between program versions, or every fit would be
    /// stale after an upgrade. Value computed once and checked independently by a 20-line
    /// Python FNV-1a over the canonical text written out by hand; change it only with a new
    /// [`TAG`].
    #[test]
    fn the_inputs_hash_is_pinned() {
        let conn = db();
        assert_eq!(stored_inputs_hash(&conn, "B").unwrap().unwrap(), PINNED_B);
        assert_eq!(stored_inputs_hash(&conn, "none").unwrap(), None);
    }

    const PINNED_B: &str = "503be6a89363097d";
}
