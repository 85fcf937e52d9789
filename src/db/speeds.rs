//! The speed curve of a segment for leak location (model §11): its latest usable fit's
//! `curves`, or, for a segment without one, its `prediction_curves` (model §7.12, P81).

use rusqlite::{params, Connection, OptionalExtension};

use super::results::CurvePoint;
use super::DbError;

/// Where a segment's curve comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CurveSource {
    /// Its own fit (the calibrate run's id).
    Fit(i64),
    /// The network soil field's prediction.
    Prediction,
}

impl CurveSource {
    /// `fit` or `prediction`, for output columns.
    pub fn as_str(self) -> &'static str {
        match self {
            CurveSource::Fit(_) => "fit",
            CurveSource::Prediction => "prediction",
        }
    }
}

/// The curve of a segment: the newest fit that is not `failed`, else its prediction; `None`
/// when it has neither.
pub fn speed_curve(
    conn: &Connection,
    segment_id: &str,
) -> Result<Option<(CurveSource, Vec<CurvePoint>)>, DbError> {
    let run: Option<i64> = conn
        .prepare_cached(
            "SELECT run_id FROM fits WHERE segment_id = ?1 AND status != 'failed' \
             ORDER BY id DESC LIMIT 1",
        )?
        .query_row([segment_id], |r| r.get(0))
        .optional()?;
    if let Some(run) = run {
        let pts = super::results::curves_for(conn, segment_id, run)?;
        if pts.iter().any(|p| p.phase_speed_m_per_s.is_some()) {
            return Ok(Some((CurveSource::Fit(run), pts)));
        }
    }
    let mut stmt = conn.prepare_cached(
        "SELECT frequency_hz, phase_speed_m_per_s, attenuation_db_per_m, \
         phase_speed_std_m_per_s, attenuation_std_db_per_m FROM prediction_curves \
         WHERE segment_id = ?1 ORDER BY frequency_hz",
    )?;
    let pts = stmt
        .query_map(params![segment_id], |r| {
            Ok(CurvePoint {
                frequency_hz: r.get(0)?,
                phase_speed_m_per_s: r.get(1)?,
                attenuation_db_per_m: r.get(2)?,
                phase_speed_std_m_per_s: r.get(3)?,
                attenuation_std_db_per_m: r.get(4)?,
                model_phase_speed_m_per_s: None,
                model_attenuation_db_per_m: None,
            })
        })?
        .collect::<Result<Vec<_>, _>>()?;
    Ok(pts
        .iter()
        .any(|p| p.phase_speed_m_per_s.is_some())
        .then_some((CurveSource::Prediction, pts)))
}
