//! Soil zones (model §7.10–7.11): segments in one soil unit share E_m and ν_m up to
//! a small scatter. Metal pipes fix the soil's c_P, plastic pipes its c_S, so a zone that holds
//! both determines E_m and ν_m, which no single segment does.
//!
//! * [`model`]: the hierarchical model P67–P68 on per-segment quadratic misfit models in
//!   (ln c_P, ln c_S); the zone's estimate, 95 % profile intervals, members shrunk toward it,
//!   and outliers (reported, left out).
//! * [`bound`]: the Cramér–Rao bound of a zone's soil from its members' true parameters.
//! * [`flags`]: the zone's flags and its verdict on a member (`zone_outlier`, with evidence).
//! * [`member`]: a member's quadratic model from its data and single fit (real misfit).
//! * [`run`]: the zones of a database: estimated when the soil field is rebuilt (they are its
//!   zone classes' means), stored in `zone_fits` / `zone_members`.
pub mod bound;
pub mod flags;
pub mod member;
pub mod model;
pub mod run;

pub use flags::{segment_flag, OutlierEvidence, ZoneFlag};
pub use member::{member_from_fit, FitSetup};
pub use model::{
    estimate_zone, Member, MemberResult, ScatterSource, ZoneEstimate, ZoneInterval, MIN_MEMBERS,
    OUTLIER_CHI2, TAU_E_DECADES, TAU_NU,
};
pub use run::{
    estimate_stored_zones, store_zones, zones_up_to_date, StoredZone, ZoneEstimates, ZoneUpdate,
};

use rayon::prelude::*;

/// One fitted segment as the zone estimation takes it.
#[derive(Debug, Clone)]
pub struct FittedSegment<'a> {
    /// Segment.
    pub segment_id: String,
    /// Its zone.
    pub soil_zone: String,
    /// Its data.
    pub data: &'a crate::invert::SegmentData,
    /// How it was fitted.
    pub setup: FitSetup,
    /// The single fit's optimum in the default coordinates (log10 E_m, ν_m, ξ, effects…).
    pub x: Vec<f64>,
    /// The single fit's relative one-sigma errors of c_P and c_S (P65), where known.
    pub speed_rstd: [Option<f64>; 2],
}

/// The members of every zone (in the order given), built in parallel (each is independent, so
/// the result does not depend on the thread count). Segments whose model cannot be evaluated
/// at their optimum are left out.
pub fn members_by_zone(
    segments: &[FittedSegment<'_>],
) -> std::collections::BTreeMap<String, Vec<Member>> {
    let built: Vec<Option<Member>> = segments
        .par_iter()
        .map(|s| member_from_fit(&s.segment_id, s.data, &s.setup, &s.x, s.speed_rstd))
        .collect();
    let mut out: std::collections::BTreeMap<String, Vec<Member>> = Default::default();
    for (s, m) in segments.iter().zip(built) {
        if let Some(m) = m {
            out.entry(s.soil_zone.clone()).or_default().push(m);
        }
    }
    out
}

/// Estimate every zone with at least [`MIN_MEMBERS`] members (in parallel over zones).
pub fn estimate_zones(
    segments: &[FittedSegment<'_>],
) -> std::collections::BTreeMap<String, ZoneEstimate> {
    estimate_member_zones(members_by_zone(segments))
}

/// Estimate every zone of [`members_by_zone`]'s result with at least [`MIN_MEMBERS`] members
/// (in parallel over zones).
pub fn estimate_member_zones(
    by_zone: std::collections::BTreeMap<String, Vec<Member>>,
) -> std::collections::BTreeMap<String, ZoneEstimate> {
    let by_zone: Vec<(String, Vec<Member>)> = by_zone.into_iter().collect();
    by_zone
        .par_iter()
        .filter_map(|(z, ms)| estimate_zone(ms).map(|e| (z.clone(), e)))
        .collect::<Vec<_>>()
        .into_iter()
        .collect()
}
