//! What a zone estimate tells a user to act on (model §7.11): the zone's own flags
//! (`zone_fits.flags`) and its verdict on a member segment, `zone_outlier`, with the evidence.
//!
//! A segment's fit flags (`fits.flags`, src/invert) describe its own data. The zone verdict is a
//! second fact about the segment, stored once, in `zone_members.zone_outlier` with its
//! statistic; [`segment_flag`] turns it into a flag code and a reason line, and the exports and
//! the audit report (src/export/record.rs) append that to the fit's own `flags` and
//! `flag_reasons`, so that it shows wherever a segment's flags are shown.

use crate::db::zones::{ZoneFitRow, ZoneMemberRow};
use crate::db::FitRow;
use crate::physics::soil::soil_speeds;

use super::model::OUTLIER_CHI2;

/// The flags of a zone estimate and of a segment in it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ZoneFlag {
    /// On a segment: it disagrees with its zone (its misfit at the zone, the scatter allowed
    /// for, exceeds [`OUTLIER_CHI2`]) and was left out of the zone's estimate. On a zone: it has
    /// such members (named in `zone_fits.outliers`).
    Outlier,
    /// On a zone: it holds only metal or only plastic pipes, so its data fix c_P or c_S but not
    /// both (model §7.10): E_m and ν_m are known only along a valley.
    SinglePipeKind,
    /// On a zone: its χ²/dof exceeds [`POOR_FIT_CHI2_PER_DOF`]: the scatter between its
    /// segments is larger than assumed, or it is more than one soil.
    PoorFit,
}

/// χ²/dof above which a zone is flagged [`ZoneFlag::PoorFit`].
pub const POOR_FIT_CHI2_PER_DOF: f64 = 3.0;

impl ZoneFlag {
    /// Every flag.
    pub const ALL: [ZoneFlag; 3] = [
        ZoneFlag::Outlier,
        ZoneFlag::SinglePipeKind,
        ZoneFlag::PoorFit,
    ];

    /// The code stored in `zone_fits.flags` and shown in a segment's `flags`.
    pub fn as_str(self) -> &'static str {
        match self {
            ZoneFlag::Outlier => "zone_outlier",
            ZoneFlag::SinglePipeKind => "single_pipe_kind",
            ZoneFlag::PoorFit => "zone_poor_fit",
        }
    }

    /// The flag of a code, if it is one.
    pub fn from_code(code: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.as_str() == code)
    }

    /// What it means and what to do (README, audit report).
    pub fn advice(self) -> &'static str {
        match self {
            ZoneFlag::Outlier => "the segment's soil disagrees with the other segments of its soil zone (p < 0.001) and was left out of the zone's estimate: check its soil_zone, whether the soil changed along it, and its inventory record (material, diameter, wall)",
            ZoneFlag::SinglePipeKind => "the zone holds only metal or only plastic pipes, so it fixes c_P or c_S but not E_m and nu_m separately; its E_m and nu_m intervals are wide: measure a pipe of the other kind in the zone to narrow them",
            ZoneFlag::PoorFit => "the zone's segments scatter more than one soil unit does: split the zone or check its members",
        }
    }
}

impl std::fmt::Display for ZoneFlag {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The evidence that a segment disagrees with its zone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutlierEvidence {
    /// The segment's misfit at the zone with the scatter allowed for (χ²₂ under the model).
    pub statistic: f64,
    /// The zone's (E_m Pa, ν_m).
    pub zone: (f64, f64),
    /// The segment's single fit's (E_m Pa, ν_m).
    pub segment: (f64, f64),
    /// The zone's (c_P, c_S) at the segment's soil density, m/s (P63–P64).
    pub zone_speeds: (f64, f64),
    /// The segment's single fit's (c_P, c_S), m/s.
    pub segment_speeds: (f64, f64),
}

impl OutlierEvidence {
    /// The evidence of a segment of soil density `rho` (kg/m³) whose single fit is `segment`
    /// against a zone at `zone`.
    pub fn new(statistic: f64, zone: (f64, f64), segment: (f64, f64), rho: f64) -> Self {
        OutlierEvidence {
            statistic,
            zone,
            segment,
            zone_speeds: soil_speeds(zone.0, zone.1, rho),
            segment_speeds: soil_speeds(segment.0, segment.1, rho),
        }
    }

    /// The reason line (without the code), e.g. `statistic 41.2 (above 13.82: p < 0.001)
    /// against zone Z07, left out of its estimate: c_P 412 m/s (zone 356), c_S 229 m/s (zone
    /// 214); E_m 2.9e8 Pa (zone 2.46e8), nu_m 0.27 (zone 0.26)`.
    pub fn reason(&self, zone: &str) -> String {
        format!(
            "statistic {} (above {}: p < 0.001) against zone {zone}, left out of its estimate: \
             c_P {} m/s (zone {}), c_S {} m/s (zone {}); E_m {} Pa (zone {}), nu_m {} (zone {})",
            short(self.statistic),
            short(OUTLIER_CHI2),
            short(self.segment_speeds.0),
            short(self.zone_speeds.0),
            short(self.segment_speeds.1),
            short(self.zone_speeds.1),
            short(self.segment.0),
            short(self.zone.0),
            short(self.segment.1),
            short(self.zone.1),
        )
    }
}

/// The zone's verdict on a segment's latest fit `fit`: [`ZoneFlag::Outlier`] and its reason
/// line (`zone_outlier: …`) when the zone's newest estimate left this very fit out; `None`
/// otherwise (consistent, or the estimate was made from an older fit). `rho` is the segment's
/// soil density, kg/m³.
pub fn segment_flag(
    zone: &ZoneFitRow,
    member: &ZoneMemberRow,
    fit: &FitRow,
    rho: f64,
) -> Option<(ZoneFlag, String)> {
    if !member.zone_outlier || fit.id != Some(member.fit_id) {
        return None;
    }
    let ev = OutlierEvidence::new(
        member.statistic.unwrap_or(f64::NAN),
        (zone.soil_youngs_modulus_pa?, zone.soil_poisson?),
        (fit.soil_youngs_modulus_pa?, fit.soil_poisson?),
        rho,
    );
    Some((
        ZoneFlag::Outlier,
        format!("{}: {}", ZoneFlag::Outlier, ev.reason(&zone.soil_zone)),
    ))
}

/// A number in short form for messages (4 significant digits; scientific beyond 1e5).
pub(crate) fn short(v: f64) -> String {
    if !v.is_finite() {
        return "–".to_string();
    }
    if v != 0.0 && (v.abs() >= 1e5 || v.abs() < 1e-3) {
        let s = format!("{v:.3e}");
        // 2.460e8 → 2.46e8
        match s.split_once('e') {
            Some((m, e)) if m.contains('.') => {
                format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
            }
            _ => s,
        }
    } else {
        let s = format!("{:.4}", v);
        let s = if v.abs() >= 100.0 {
            format!("{v:.0}")
        } else if v.abs() >= 10.0 {
            format!("{v:.2}")
        } else {
            s
        };
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_numbers_are_short() {
        for f in ZoneFlag::ALL {
            assert_eq!(ZoneFlag::from_code(f.as_str()), Some(f));
        }
        assert_eq!(ZoneFlag::from_code("high_misfit"), None);
        assert_eq!(short(2.46e8), "2.46e8");
        assert_eq!(short(412.4), "412");
        assert_eq!(short(13.815_510_557_964_274), "13.82");
        assert_eq!(short(0.2612), "0.2612");
    }

    #[test]
    fn the_verdict_applies_to_the_fit_it_was_made_from() {
        let zone = ZoneFitRow {
            soil_zone: "Z07".into(),
            soil_youngs_modulus_pa: Some(2.46e8),
            soil_poisson: Some(0.26),
            ..Default::default()
        };
        let member = ZoneMemberRow {
            segment_id: "S1".into(),
            fit_id: 5,
            statistic: Some(41.2),
            zone_outlier: true,
            ..Default::default()
        };
        let mut fit = FitRow::new(
            "S1",
            1,
            crate::db::FitStatus::Ok,
            crate::physics::Model::Seed,
            crate::physics::ContactMode::Reciprocal,
        );
        fit.id = Some(5);
        fit.soil_youngs_modulus_pa = Some(2.9e8);
        fit.soil_poisson = Some(0.33);
        let (flag, reason) = segment_flag(&zone, &member, &fit, 2000.0).unwrap();
        assert_eq!(flag, ZoneFlag::Outlier);
        assert!(reason.starts_with("zone_outlier: statistic 41.2 (above 13.82"));
        assert!(reason.contains("E_m 2.9e8 Pa (zone 2.46e8), nu_m 0.33 (zone 0.26)"));
        // The zone's c_P at this density.
        let (cp, _) = soil_speeds(2.46e8, 0.26, 2000.0);
        assert!(
            reason.contains(&format!("(zone {})", short(cp))),
            "{reason}"
        );
        // A newer fit than the one the zone was made from: no verdict on it.
        fit.id = Some(6);
        assert!(segment_flag(&zone, &member, &fit, 2000.0).is_none());
        // Consistent members carry no flag.
        fit.id = Some(5);
        let ok = ZoneMemberRow {
            zone_outlier: false,
            ..member
        };
        assert!(segment_flag(&zone, &ok, &fit, 2000.0).is_none());
    }
}
