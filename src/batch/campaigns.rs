//! The campaigns of a re-measured segment in a calibrate run: which two are tested, and the
//! change test of the latest against the one before it (model §7.14, P94–P96).

use super::{BatchError, Job};
use crate::change::{self, CampaignName};
use crate::db::changes::ChangeRecord;
use crate::db::inventory::MeasurementRecord;
use crate::db::{self, Connection};
use crate::invert::FitSettings;
use crate::rows::segment_data;

/// A segment's latest campaign, and the one before it with its measurements.
#[allow(clippy::type_complexity)]
pub(super) fn campaigns_to_test(
    conn: &Connection,
    segment_id: &str,
) -> Result<
    (
        Option<CampaignName>,
        Option<(CampaignName, Vec<MeasurementRecord>)>,
    ),
    BatchError,
> {
    let mut cs = db::inventory::campaigns_of(conn, segment_id)?;
    let name = |c: &db::inventory::CampaignOfSegment| CampaignName {
        name: c.name.clone(),
        measured_on: c.newest_measured_on.clone(),
    };
    let Some(latest) = cs.pop() else {
        return Ok((None, None));
    };
    let earlier = match cs.pop() {
        Some(e) => {
            let rows = db::inventory::load_campaign(conn, segment_id, &e.name)?;
            Some((name(&e), rows))
        }
        None => None,
    };
    Ok((Some(name(&latest)), earlier))
}

/// The change test of a segment measured in two or more campaigns (model §7.14): its latest
/// campaign's fit `result` against the campaign before it. Where the pipe did not change,
/// `result` becomes the fit of both campaigns pooled. `None` for a segment without
/// measurements.
pub(super) fn test_campaigns(
    job: &Job,
    run_id: i64,
    latest_data: &crate::invert::SegmentData,
    settings: &FitSettings,
    result: &mut crate::invert::FitResult,
) -> Option<ChangeRecord> {
    let latest = job.latest.as_ref()?;
    let id = job.record.segment_id.as_str();
    let Some((earlier_name, rows)) = &job.earlier else {
        return Some(change::change_record(id, run_id, latest, None, result));
    };
    let mut earlier_rec = job.record.clone();
    earlier_rec.measurements = rows.clone();
    let test = match segment_data(&earlier_rec) {
        Ok(earlier) => change::test_change(&earlier, latest_data, settings, result, job.seed),
        Err(e) => change::ChangeTest::untested(format!(
            "the earlier campaign {}'s inputs are invalid: {e}",
            earlier_name.name
        )),
    };
    let record = change::change_record(id, run_id, latest, Some((earlier_name, &test)), result);
    if let Some(current) = test.pooled.or(test.current) {
        *result = current;
    }
    Some(record)
}
