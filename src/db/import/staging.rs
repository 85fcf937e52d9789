//! The rows of an import, staged in temporary tables while they are checked and before they are
//! written. SQLite keeps its temporary database in a file behind a small page cache, so an
//! import holds one row at a time in memory whatever the size of its files; duplicates, the
//! segments measurements refer to, and each segment's measurement set are then found by
//! ordered queries.

use rusqlite::types::Value;
use rusqlite::{params, params_from_iter, Connection};

use crate::db::inventory::{
    inventory_values, measurement_from_row, segment_from_row, MeasurementRecord, SegmentRecord,
    MEASUREMENT_COLUMNS, MEASUREMENT_WIDTH, SEGMENT_COLUMNS, UNNAMED_CAMPAIGN,
};
use crate::db::DbError;

/// The staging tables of one import, dropped when this is dropped.
pub(super) struct Staging<'c> {
    conn: &'c Connection,
    /// The temporary database's cache size before, restored after.
    cache_size: i64,
}

/// Page cache of the temporary database while an import stages its rows, KiB (SQLite's
/// default is 2000): what the staging may hold in memory, whatever the size of the files.
const TEMP_CACHE_KIB: u32 = 8192;

const DROP: &str = "DROP TABLE IF EXISTS temp.import_segments; \
    DROP TABLE IF EXISTS temp.import_measurements;";

impl<'c> Staging<'c> {
    /// Create the (empty) staging tables.
    pub fn create(conn: &'c Connection) -> Result<Self, DbError> {
        let cache_size = conn.query_row("PRAGMA temp.cache_size", [], |r| r.get(0))?;
        conn.execute_batch(&format!(
            "{DROP}
            PRAGMA temp.cache_size = -{TEMP_CACHE_KIB};
            -- Every row of the segments file whose id could be read; `valid`: the whole row is.
            CREATE TEMP TABLE import_segments (
                line INTEGER NOT NULL, valid INTEGER NOT NULL, segment_id TEXT NOT NULL,
                material TEXT NOT NULL, outer_diameter_mm REAL, wall_thickness_mm REAL,
                soil_density_kg_m3 REAL, pipe_youngs_modulus_pa REAL, pipe_poisson REAL,
                pipe_density_kg_m3 REAL, pipe_loss_factor REAL, fluid_density_kg_m3 REAL,
                fluid_bulk_modulus_pa REAL, length_m REAL, soil_type TEXT, install_year INTEGER,
                geometry_wkt TEXT, srid INTEGER, inputs_hash TEXT NOT NULL DEFAULT '',
                imported_at TEXT NOT NULL DEFAULT '', soil_zone TEXT, risk_weight REAL,
                soil_class_override TEXT);
            -- Every valid row of the measurements file; `valid` is cleared for a duplicate or a
            -- row of an unknown segment. `omega_given`: the frequency was given as ω.
            CREATE TEMP TABLE import_measurements (
                line INTEGER NOT NULL, valid INTEGER NOT NULL, segment_id TEXT NOT NULL,
                omega_given INTEGER NOT NULL, omega_rad_s REAL NOT NULL,
                frequency_hz REAL NOT NULL, k_re_rad_per_m REAL NOT NULL,
                attenuation_np_per_m REAL NOT NULL, k_re_std REAL, attenuation_std REAL,
                measured_on TEXT, campaign TEXT NOT NULL, note TEXT);"
        ))?;
        Ok(Staging { conn, cache_size })
    }

    /// Stage a segment row: its checked record, or only its id when the row is invalid.
    pub fn segment(
        &self,
        line: u64,
        id: &str,
        record: Option<&SegmentRecord>,
    ) -> Result<(), DbError> {
        let mut stmt = self.conn.prepare_cached(
            "INSERT INTO temp.import_segments (line, valid, segment_id, material, \
             outer_diameter_mm, wall_thickness_mm, soil_density_kg_m3, pipe_youngs_modulus_pa, \
             pipe_poisson, pipe_density_kg_m3, pipe_loss_factor, fluid_density_kg_m3, \
             fluid_bulk_modulus_pa, length_m, soil_type, install_year, geometry_wkt, srid, \
             soil_zone, risk_weight, soil_class_override) \
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, \
             ?17, ?18, ?19, ?20, ?21)",
        )?;
        let line = line_sql(line);
        match record {
            None => stmt.execute(params![
                line,
                false,
                id,
                "",
                None::<f64>,
                None::<f64>,
                None::<f64>,
                None::<f64>,
                None::<f64>,
                None::<f64>,
                None::<f64>,
                None::<f64>,
                None::<f64>,
                None::<f64>,
                None::<String>,
                None::<i64>,
                None::<String>,
                None::<i64>,
                None::<String>,
                None::<f64>,
                None::<String>,
            ])?,
            Some(s) => {
                let head = [Value::from(line), Value::from(true)];
                stmt.execute(params_from_iter(
                    head.into_iter().chain(inventory_values(s)),
                ))?
            }
        };
        Ok(())
    }

    /// Stage a valid measurement row of segment `id`.
    pub fn measurement(
        &self,
        line: u64,
        id: &str,
        omega_given: bool,
        m: &MeasurementRecord,
    ) -> Result<(), DbError> {
        self.conn
            .prepare_cached(
                "INSERT INTO temp.import_measurements (line, valid, segment_id, omega_given, \
                 omega_rad_s, frequency_hz, k_re_rad_per_m, attenuation_np_per_m, k_re_std, \
                 attenuation_std, measured_on, campaign, note) \
                 VALUES (?1, 1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)",
            )?
            .execute(params![
                line_sql(line),
                id,
                omega_given,
                m.omega_rad_s,
                m.frequency_hz,
                m.k_re_rad_per_m,
                m.attenuation_np_per_m,
                m.k_re_std,
                m.attenuation_std,
                m.measured_on,
                m.campaign.as_deref().unwrap_or(UNNAMED_CAMPAIGN),
                m.note,
            ])?;
        Ok(())
    }

    /// Index the staged segment rows for the queries that follow (faster than indexing row by
    /// row).
    pub fn index_segments(&self) -> Result<(), DbError> {
        self.conn.execute_batch(
            "CREATE INDEX temp.import_segments_id ON import_segments (segment_id, line);",
        )?;
        Ok(())
    }

    /// Index the staged measurement rows for the queries that follow.
    pub fn index_measurements(&self) -> Result<(), DbError> {
        self.conn.execute_batch(
            "CREATE INDEX temp.import_measurements_id \
             ON import_measurements (segment_id, campaign, omega_rad_s, line, omega_given);",
        )?;
        Ok(())
    }

    /// Every staged segment row whose id is on more than one row, as `(id, line)` by id, then
    /// line.
    pub fn repeated_segment_ids(&self, mut each: impl FnMut(&str, u64)) -> Result<(), DbError> {
        let mut stmt = self.conn.prepare(
            "SELECT segment_id, line FROM temp.import_segments WHERE segment_id IN \
             (SELECT segment_id FROM temp.import_segments GROUP BY segment_id \
              HAVING count(*) > 1) ORDER BY segment_id, line",
        )?;
        let mut rows = stmt.query([])?;
        while let Some(r) = rows.next()? {
            each(&r.get::<_, String>(0)?, line_rust(r.get(1)?));
        }
        Ok(())
    }

    /// Mark every row of a segment id invalid.
    pub fn invalidate_segment(&self, id: &str) -> Result<(), DbError> {
        self.conn
            .prepare_cached("UPDATE temp.import_segments SET valid = 0 WHERE segment_id = ?1")?
            .execute([id])?;
        Ok(())
    }

    /// The valid measurement rows as `(rowid, segment id, ω, line, ω given)`, by segment, ω and
    /// line.
    pub fn measurements_by_frequency(
        &self,
        mut each: impl FnMut(StagedMeasurement) -> Result<(), DbError>,
    ) -> Result<(), DbError> {
        let mut stmt = self.conn.prepare(
            "SELECT rowid, segment_id, omega_rad_s, line, omega_given, campaign \
             FROM temp.import_measurements WHERE valid \
             ORDER BY segment_id, campaign, omega_rad_s, line",
        )?;
        let mut rows = stmt.query([])?;
        while let Some(r) = rows.next()? {
            each(StagedMeasurement {
                rowid: r.get(0)?,
                segment_id: r.get(1)?,
                omega_rad_s: r.get(2)?,
                line: line_rust(r.get(3)?),
                omega_given: r.get(4)?,
                campaign: r.get(5)?,
            })?;
        }
        Ok(())
    }

    /// Mark one measurement row invalid.
    pub fn invalidate_measurement(&self, rowid: i64) -> Result<(), DbError> {
        self.conn
            .prepare_cached("UPDATE temp.import_measurements SET valid = 0 WHERE rowid = ?1")?
            .execute([rowid])?;
        Ok(())
    }

    /// The valid measurement rows whose segment is neither in the database nor a valid row of
    /// the segments file, as `(rowid, segment id, line)` in line order.
    pub fn measurements_of_unknown_segments(
        &self,
        mut each: impl FnMut(i64, String, u64) -> Result<(), DbError>,
    ) -> Result<(), DbError> {
        let mut stmt = self.conn.prepare(
            "SELECT m.rowid, m.segment_id, m.line FROM temp.import_measurements m \
             WHERE m.valid \
             AND NOT EXISTS (SELECT 1 FROM main.segments s WHERE s.segment_id = m.segment_id) \
             AND NOT EXISTS (SELECT 1 FROM temp.import_segments i \
                             WHERE i.segment_id = m.segment_id AND i.valid) \
             ORDER BY m.line",
        )?;
        let mut rows = stmt.query([])?;
        while let Some(r) = rows.next()? {
            each(r.get(0)?, r.get(1)?, line_rust(r.get(2)?))?;
        }
        Ok(())
    }

    /// The first line of the segments file where `id` is on an invalid row, if any.
    pub fn invalid_segment_line(&self, id: &str) -> Result<Option<u64>, DbError> {
        let line: Option<i64> = self
            .conn
            .prepare_cached(
                "SELECT min(line) FROM temp.import_segments WHERE segment_id = ?1 AND NOT valid",
            )?
            .query_row([id], |r| r.get(0))?;
        Ok(line.map(line_rust))
    }

    /// The valid segment rows in file order, as records (without measurements).
    pub fn valid_segments(
        &self,
        mut each: impl FnMut(SegmentRecord) -> Result<(), DbError>,
    ) -> Result<(), DbError> {
        let mut stmt = self.conn.prepare(&format!(
            "SELECT {SEGMENT_COLUMNS} FROM temp.import_segments WHERE valid ORDER BY line"
        ))?;
        let mut rows = stmt.query([])?;
        while let Some(r) = rows.next()? {
            let (mut rec, material) = segment_from_row(r)?;
            rec.material = material.parse().map_err(|e| DbError::BadStoredValue {
                what: format!("staged segment {}: {e}", rec.segment_id),
            })?;
            each(rec)?;
        }
        Ok(())
    }

    /// The valid measurement rows by segment and campaign, each group by ω:
    /// `each(segment, campaign, rows)`, in segment then campaign order.
    pub fn measurement_sets(
        &self,
        mut each: impl FnMut(&str, &str, Vec<MeasurementRecord>) -> Result<(), DbError>,
    ) -> Result<(), DbError> {
        let mut stmt = self.conn.prepare(&format!(
            "SELECT {MEASUREMENT_COLUMNS}, segment_id FROM temp.import_measurements \
             WHERE valid ORDER BY segment_id, campaign, omega_rad_s, line"
        ))?;
        let mut rows = stmt.query([])?;
        let mut current: Option<(String, String, Vec<MeasurementRecord>)> = None;
        while let Some(r) = rows.next()? {
            let m = measurement_from_row(r)?;
            let id: String = r.get(MEASUREMENT_WIDTH)?;
            let campaign = m.campaign.clone().unwrap_or_default();
            match &mut current {
                Some((cur, cc, set)) if *cur == id && *cc == campaign => set.push(m),
                _ => {
                    if let Some((cur, cc, set)) = current.replace((id, campaign, vec![m])) {
                        each(&cur, &cc, set)?;
                    }
                }
            }
        }
        if let Some((cur, cc, set)) = current {
            each(&cur, &cc, set)?;
        }
        Ok(())
    }

    /// Every segment id on a valid row of either file, in id order.
    pub fn touched_segments(
        &self,
        mut each: impl FnMut(&str) -> Result<(), DbError>,
    ) -> Result<(), DbError> {
        let mut stmt = self.conn.prepare(
            "SELECT segment_id FROM temp.import_segments WHERE valid \
             UNION SELECT segment_id FROM temp.import_measurements WHERE valid \
             ORDER BY 1",
        )?;
        let mut rows = stmt.query([])?;
        while let Some(r) = rows.next()? {
            each(&r.get::<_, String>(0)?)?;
        }
        Ok(())
    }
}

impl Drop for Staging<'_> {
    fn drop(&mut self) {
        // Nothing to report: the tables are temporary and vanish with the connection anyway.
        let _ = self.conn.execute_batch(&format!(
            "{DROP} PRAGMA temp.cache_size = {}; PRAGMA shrink_memory;",
            self.cache_size
        ));
    }
}

/// A staged measurement row, for the duplicate check.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct StagedMeasurement {
    pub rowid: i64,
    pub segment_id: String,
    pub omega_rad_s: f64,
    pub line: u64,
    pub omega_given: bool,
    pub campaign: String,
}

/// Lines are `u64` in Rust and INTEGER in SQLite (no file has 2⁶³ lines).
fn line_sql(line: u64) -> i64 {
    i64::try_from(line).unwrap_or(i64::MAX)
}

fn line_rust(line: i64) -> u64 {
    u64::try_from(line).unwrap_or(0)
}
