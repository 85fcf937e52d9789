//! The GeoPackage's soil-field layers (model §7.12): `soil_field`, one line per segment with
//! the soil and speed the network's field gives it (its own fit's where measured, the field's
//! prediction elsewhere) and its leave-one-out check; `next_measurements`, the stored plan
//! (P83), best first. Written only when the database holds a field or a plan.

use std::collections::BTreeMap;

use rusqlite::{params, Transaction};

use crate::db::field::PlanPick;
use crate::db::wkt::LineString;

use super::gpkg::{envelope, linestring_blob, register_feature_table};
use super::record::SegmentExport;

/// Name of the soil-field layer.
pub const FIELD_TABLE: &str = "soil_field";
/// Name of the plan layer.
pub const PLAN_TABLE: &str = "next_measurements";

/// A plan pick with its line (GeoPackage binary) and envelope, if it has a geometry.
type PlanRow = (Option<Vec<u8>>, PlanPick, Option<[f64; 4]>);

/// The two layers, filled while the records stream past.
pub(crate) struct FieldLayers {
    created: bool,
    rows: usize,
    bbox: Option<[f64; 4]>,
    plan: BTreeMap<String, PlanPick>,
    plan_rows: Vec<PlanRow>,
}

fn grow(b: Option<[f64; 4]>, e: [f64; 4]) -> Option<[f64; 4]> {
    Some(b.map_or(e, |b| {
        [
            b[0].min(e[0]),
            b[1].max(e[1]),
            b[2].min(e[2]),
            b[3].max(e[3]),
        ]
    }))
}

impl FieldLayers {
    /// Layers for the stored plan `plan`.
    pub fn new(plan: Vec<PlanPick>) -> Self {
        FieldLayers {
            created: false,
            rows: 0,
            bbox: None,
            plan: plan
                .into_iter()
                .map(|p| (p.segment_id.clone(), p))
                .collect(),
            plan_rows: Vec::new(),
        }
    }

    /// Add one record with its line in the table's system (`srs_id` as in the blobs).
    pub fn add(
        &mut self,
        tx: &Transaction<'_>,
        rec: &SegmentExport,
        line: Option<&LineString>,
        srs_id: i32,
    ) -> rusqlite::Result<()> {
        let blob = line.map(|l| linestring_blob(srs_id, l));
        if let Some(p) = self.plan.remove(rec.id()) {
            self.plan_rows.push((blob.clone(), p, line.map(envelope)));
        }
        if rec.field.is_none() && rec.prediction.is_none() {
            return Ok(());
        }
        if !self.created {
            tx.execute_batch(&format!(
                "CREATE TABLE {FIELD_TABLE} (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, \
                 geom LINESTRING, segment_id TEXT NOT NULL UNIQUE, speed_source TEXT, \
                 soil_class TEXT, label_rejected INTEGER, soil_p_wave_speed_m_per_s DOUBLE, \
                 soil_p_wave_speed_std_m_per_s DOUBLE, soil_s_wave_speed_m_per_s DOUBLE, \
                 soil_s_wave_speed_std_m_per_s DOUBLE, leak_band_speed_m_per_s DOUBLE, \
                 leak_band_speed_std_m_per_s DOUBLE, field_z DOUBLE, field_outlier INTEGER, \
                 note TEXT);"
            ))?;
            self.created = true;
        }
        let (cp, cs) = match (&rec.prediction, &rec.fit) {
            (Some(p), _) => (p.soil_p_wave_speed, p.soil_s_wave_speed),
            (None, Some(f)) => (
                f.soil_p_wave_speed_m_per_s
                    .zip(f.soil_p_wave_speed_std_m_per_s),
                f.soil_s_wave_speed_m_per_s
                    .zip(f.soil_s_wave_speed_std_m_per_s),
            ),
            _ => (None, None),
        };
        let f = rec.field.as_ref();
        tx.prepare_cached(&format!(
            "INSERT INTO {FIELD_TABLE} (geom, segment_id, speed_source, soil_class, \
             label_rejected, soil_p_wave_speed_m_per_s, soil_p_wave_speed_std_m_per_s, \
             soil_s_wave_speed_m_per_s, soil_s_wave_speed_std_m_per_s, leak_band_speed_m_per_s, \
             leak_band_speed_std_m_per_s, field_z, field_outlier, note) \
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14)"
        ))?
        .execute(params![
            blob,
            rec.id(),
            rec.speed_source,
            f.and_then(|f| f.soil_class.clone()),
            f.map(|f| f.label_rejected),
            cp.map(|v| v.0),
            cp.map(|v| v.1),
            cs.map(|v| v.0),
            cs.map(|v| v.1),
            rec.leak_band_speed.filter(|v| v.is_finite()),
            rec.leak_band_speed_std().filter(|v| v.is_finite()),
            f.and_then(|f| f.loo_z),
            f.map(|f| f.field_outlier),
            rec.speed_source_reason,
        ])?;
        self.rows += 1;
        if let Some(l) = line {
            self.bbox = grow(self.bbox, envelope(l));
        }
        Ok(())
    }

    /// Register the soil-field layer and write the plan layer (in the plan's order).
    pub fn finish(self, tx: &Transaction<'_>, table_srs: i64) -> rusqlite::Result<()> {
        if self.created {
            register_feature_table(
                tx,
                FIELD_TABLE,
                "the soil field of the network: every segment's soil and speed, fitted or \
                 predicted (pipewave, physics 7.12)",
                self.bbox,
                "geom",
                "LINESTRING",
                table_srs,
            )?;
        }
        if self.plan_rows.is_empty() {
            return Ok(());
        }
        tx.execute_batch(&format!(
            "CREATE TABLE {PLAN_TABLE} (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, \
             geom LINESTRING, rank INTEGER NOT NULL, segment_id TEXT NOT NULL, \
             expected_gain DOUBLE, leak_band_speed_std_m_per_s DOUBLE, weight DOUBLE);"
        ))?;
        let mut rows = self.plan_rows;
        rows.sort_by_key(|r| r.1.rank);
        let mut bbox = None;
        for (blob, p, e) in rows {
            if let Some(e) = e {
                bbox = grow(bbox, e);
            }
            tx.execute(
                &format!(
                    "INSERT INTO {PLAN_TABLE} (geom, rank, segment_id, expected_gain, \
                     leak_band_speed_std_m_per_s, weight) VALUES (?1, ?2, ?3, ?4, ?5, ?6)"
                ),
                params![
                    blob,
                    p.rank,
                    p.segment_id,
                    p.expected_gain,
                    p.leak_band_speed_std_m_per_s,
                    p.weight
                ],
            )?;
        }
        register_feature_table(
            tx,
            PLAN_TABLE,
            "the next measurement campaign, best first (pipewave plan, physics P83)",
            bbox,
            "geom",
            "LINESTRING",
            table_srs,
        )
    }
}
