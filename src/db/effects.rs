//! Effects switched on for single segments (table `segment_effects`, migration 0003), and the
//! state of each segment's latest fit, from which `calibrate` decides what to refit.

use std::collections::BTreeMap;

use rusqlite::{params, Connection, OptionalExtension};

use super::DbError;

/// The effects set for each segment that has any: segment id → comma-separated names.
pub fn segment_effects(conn: &Connection) -> Result<BTreeMap<String, String>, DbError> {
    let mut stmt = conn.prepare("SELECT segment_id, effects FROM segment_effects")?;
    let rows = stmt
        .query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?)))?
        .collect::<Result<BTreeMap<_, _>, _>>()?;
    Ok(rows)
}

/// The effects set for one segment (empty when none).
pub fn effects_of(conn: &Connection, segment_id: &str) -> Result<String, DbError> {
    Ok(conn
        .query_row(
            "SELECT effects FROM segment_effects WHERE segment_id = ?1",
            [segment_id],
            |r| r.get(0),
        )
        .optional()?
        .unwrap_or_default())
}

/// Set (or replace) the effects of a segment; an empty list removes the row.
pub fn set_segment_effects(
    conn: &Connection,
    segment_id: &str,
    effects: &str,
    source: &str,
    evidence: &str,
) -> Result<(), DbError> {
    if effects.trim().is_empty() {
        conn.execute(
            "DELETE FROM segment_effects WHERE segment_id = ?1",
            [segment_id],
        )?;
    } else {
        conn.execute(
            "INSERT INTO segment_effects (segment_id, effects, source, evidence) \
             VALUES (?1, ?2, ?3, ?4) \
             ON CONFLICT(segment_id) DO UPDATE SET effects = excluded.effects, \
             source = excluded.source, evidence = excluded.evidence, \
             created_at = strftime('%Y-%m-%dT%H:%M:%fZ', 'now')",
            params![segment_id, effects, source, evidence],
        )?;
    }
    Ok(())
}

/// What `calibrate` needs to know about a segment to decide whether to refit it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FitState {
    /// The segment.
    pub segment_id: String,
    /// Its current inputs hash.
    pub inputs_hash: String,
    /// The inputs hash its latest fit was made from (None: never fitted).
    pub fit_inputs_hash: Option<String>,
    /// The settings hash of its latest fit.
    pub fit_settings_hash: Option<String>,
    /// The fitting algorithm's version of its latest fit (None: never fitted, or fitted before
    /// the version was recorded).
    pub fit_algorithm_version: Option<i64>,
    /// It has at least one measurement.
    pub has_measurements: bool,
    /// A `calibrate --force` run was asked to refit it and stopped before it did (table
    /// `forced_refits`).
    pub forced: bool,
}

impl FitState {
    /// Whether the segment needs a (re)fit under settings whose hash is `settings_hash`: it has
    /// measurements and no fit yet, or its latest fit was made from other inputs or settings,
    /// or by another version of the fitting algorithm, or a forced run that stopped did not
    /// reach it.
    pub fn is_stale(&self, settings_hash: &str) -> bool {
        self.has_measurements
            && (self.forced
                || self.fit_inputs_hash.as_deref() != Some(self.inputs_hash.as_str())
                || self.fit_settings_hash.as_deref() != Some(settings_hash)
                || self.made_by_other_algorithm())
    }

    /// Its latest fit exists and was made by another version of the fitting algorithm
    /// ([`crate::types::FIT_ALGORITHM_VERSION`]).
    pub fn made_by_other_algorithm(&self) -> bool {
        self.fit_inputs_hash.is_some()
            && self.fit_algorithm_version != Some(crate::types::FIT_ALGORITHM_VERSION)
    }
}

/// The columns of a [`FitState`] (read by [`FitState::from_row`]), over [`FIT_STATE_FROM`].
pub(crate) const FIT_STATE_COLUMNS: &str = "s.segment_id, s.inputs_hash, f.inputs_hash, \
    f.settings_hash, f.algorithm_version, \
    EXISTS (SELECT 1 FROM measurements m WHERE m.segment_id = s.segment_id), \
    EXISTS (SELECT 1 FROM forced_refits p WHERE p.segment_id = s.segment_id)";
/// The tables [`FIT_STATE_COLUMNS`] come from: every segment with its latest fit, if any.
pub(crate) const FIT_STATE_FROM: &str =
    "segments s LEFT JOIN latest_fits f ON f.segment_id = s.segment_id";

impl FitState {
    /// A fit state from the first seven columns of `r`, selected as [`FIT_STATE_COLUMNS`].
    pub(crate) fn from_row(r: &rusqlite::Row<'_>) -> rusqlite::Result<Self> {
        Ok(FitState {
            segment_id: r.get(0)?,
            inputs_hash: r.get(1)?,
            fit_inputs_hash: r.get(2)?,
            fit_settings_hash: r.get(3)?,
            fit_algorithm_version: r.get(4)?,
            has_measurements: r.get(5)?,
            forced: r.get(6)?,
        })
    }
}

/// The number of columns [`FitState::from_row`] reads.
pub(crate) const FIT_STATE_WIDTH: usize = 7;

/// Record that a forced run `run_id` is to refit `segment_ids` (table `forced_refits`): until a
/// new fit of one is stored, the segment stays stale for every later run.
pub fn mark_forced_refits<'a>(
    conn: &mut Connection,
    run_id: i64,
    segment_ids: impl IntoIterator<Item = &'a str>,
) -> Result<(), DbError> {
    let tx = conn.transaction()?;
    {
        let mut ins = tx.prepare_cached(
            "INSERT INTO forced_refits (segment_id, run_id) VALUES (?1, ?2) \
             ON CONFLICT(segment_id) DO UPDATE SET run_id = excluded.run_id",
        )?;
        for id in segment_ids {
            ins.execute(params![id, run_id])?;
        }
    }
    tx.commit()?;
    Ok(())
}

/// The fit state of every segment, by id.
pub fn fit_states(conn: &Connection) -> Result<Vec<FitState>, DbError> {
    let mut stmt = conn.prepare(&format!(
        "SELECT {FIT_STATE_COLUMNS} FROM {FIT_STATE_FROM} ORDER BY s.segment_id"
    ))?;
    let rows = stmt
        .query_map([], FitState::from_row)?
        .collect::<Result<Vec<_>, _>>()?;
    Ok(rows)
}
