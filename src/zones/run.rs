//! The zones of a database: every zone with at least [`MIN_MEMBERS`] fitted segments is
//! estimated (model §7.11) when the soil field is rebuilt after a `calibrate` run, as the class
//! mean of its zone class (model §7.12), and stored in `zone_fits` / `zone_members` where its
//! member fits changed since its last stored estimate.

use std::collections::BTreeMap;
use std::time::Instant;

use rusqlite::Connection;

use crate::db::zones::{insert_zone_fit, latest_zone_fit, ZoneFitRow, ZoneMemberRow};
use crate::db::{latest_fits, load_zoned_segments, DbError, FitRow, FitStatus, SegmentRecord};
use crate::invert::problem::{parameter_space, Param};
use crate::invert::Method;
use crate::physics::effects::parse_effects;
use crate::rows::segment_data;

use super::flags::{OutlierEvidence, ZoneFlag, POOR_FIT_CHI2_PER_DOF};
use super::model::{estimate_zone, ZoneEstimate, MIN_MEMBERS};
use super::{members_by_zone, FitSetup, FittedSegment};

/// What the zones' part of a field update did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ZoneUpdate {
    /// Zones estimated (stored).
    pub estimated: usize,
    /// Zones whose estimate was current.
    pub up_to_date: usize,
    /// Zones with fewer than [`MIN_MEMBERS`] fitted segments (not estimated).
    pub too_few: usize,
    /// Segments reported as zone outliers in the stored estimates.
    pub outliers: usize,
    /// Wall-clock time, s.
    pub elapsed_s: f64,
}

impl ZoneUpdate {
    /// The summary line, e.g. `zones: 16 estimated, 0 up to date, 1 with too few fits, 2
    /// outliers, in 0.4 s`.
    pub fn line(&self) -> String {
        format!(
            "zones: {} estimated, {} up to date, {} with fewer than {} fitted segments, {} \
             zone outliers, in {:.2} s",
            self.estimated,
            self.up_to_date,
            self.too_few,
            MIN_MEMBERS,
            self.outliers,
            self.elapsed_s
        )
    }
}

/// The single fit's optimum in the default coordinates, from its stored values.
fn coordinates(fit: &FitRow, setup: &FitSetup) -> Option<Vec<f64>> {
    parameter_space(Method::Default, &setup.effects)
        .iter()
        .map(|s| {
            let v = match s.param {
                Param::SoilModulus => fit.soil_youngs_modulus_pa,
                Param::SoilPoisson => fit.soil_poisson,
                Param::Contact => fit.contact,
                Param::Effect(e) => match e.parameter().map(|p| p.name) {
                    Some("soil_loss_factor") => fit.soil_loss_factor,
                    Some("air_fraction") => fit.air_fraction,
                    Some("wall_thickness_ratio") => fit.wall_thickness_ratio,
                    Some("pipe_loss_factor") => fit.pipe_loss_factor,
                    _ => None,
                },
            }?;
            let c = s.coordinate(v);
            c.is_finite().then_some(c.clamp(s.lower, s.upper))
        })
        .collect()
}

/// σ / |value|, where both are stored and finite.
fn relative(std: Option<f64>, value: Option<f64>) -> Option<f64> {
    let r = std? / value?.abs();
    r.is_finite().then_some(r)
}

/// The hash of a zone's member fits: `segment_id:fit_id` lines, sorted.
fn members_hash(fits: &[&FitRow]) -> String {
    let mut lines: Vec<String> = fits
        .iter()
        .map(|f| format!("{}:{}", f.segment_id, f.id.unwrap_or(-1)))
        .collect();
    lines.sort();
    crate::db::hash::fnv1a64_hex(&lines.join("\n"))
}

/// One zone estimated from the stored fits, with what its stored rows need.
#[derive(Debug, Clone)]
pub struct StoredZone {
    /// The zone's name (its `soil_zone`).
    pub zone: String,
    /// The hierarchical estimate (model §7.11).
    pub estimate: ZoneEstimate,
    /// The hash of its member fits.
    pub members_hash: String,
    /// Its members are all metal or all plastic.
    pub single_pipe_kind: bool,
    /// Each member's fit id.
    pub fit_ids: BTreeMap<String, i64>,
    /// Time the estimate took, ms.
    pub elapsed_ms: f64,
}

/// Every zone of a database estimated from its latest fits.
#[derive(Debug, Clone, Default)]
pub struct ZoneEstimates {
    /// The zones with at least [`MIN_MEMBERS`] usable fits, by name.
    pub zones: Vec<StoredZone>,
    /// Zones with fewer (not estimated).
    pub too_few: usize,
}

impl ZoneEstimates {
    /// The zone named `zone`, if estimated.
    pub fn get(&self, zone: &str) -> Option<&StoredZone> {
        self.zones.iter().find(|z| z.zone == zone)
    }
}

/// Estimate every declared zone with at least [`MIN_MEMBERS`] usable latest fits (model §7.11,
/// P67–P68). The field update calls it when it rebuilds the field: the estimates are the class
/// means of the zone classes (model §7.12) and what [`store_zones`] writes.
pub fn estimate_stored_zones(conn: &Connection) -> Result<ZoneEstimates, DbError> {
    let mut out = ZoneEstimates::default();
    let records: Vec<SegmentRecord> = load_zoned_segments(conn)?
        .into_iter()
        .filter(|r| r.soil_zone.as_deref().is_some_and(|z| !z.trim().is_empty()))
        .collect();
    if records.is_empty() {
        return Ok(out);
    }
    let fits: BTreeMap<String, FitRow> = latest_fits(conn, None)?
        .into_iter()
        .map(|f| (f.segment_id.clone(), f))
        .collect();
    // Members by zone: segments with a usable latest fit.
    let mut zones: BTreeMap<String, Vec<(&SegmentRecord, &FitRow)>> = BTreeMap::new();
    let mut all_zones = std::collections::BTreeSet::new();
    for r in &records {
        let zone = r
            .soil_zone
            .as_deref()
            .unwrap_or_default()
            .trim()
            .to_string();
        all_zones.insert(zone.clone());
        if let Some(f) = fits.get(&r.segment_id) {
            if f.status != FitStatus::Failed
                && f.soil_youngs_modulus_pa.is_some()
                && f.soil_poisson.is_some()
            {
                zones.entry(zone).or_default().push((r, f));
            }
        }
    }
    out.too_few = all_zones
        .iter()
        .filter(|z| zones.get(*z).map_or(0, Vec::len) < MIN_MEMBERS)
        .count();
    for (zone, members) in zones.iter().filter(|(_, m)| m.len() >= MIN_MEMBERS) {
        let t0 = Instant::now();
        let fit_refs: Vec<&FitRow> = members.iter().map(|(_, f)| *f).collect();
        let hash = members_hash(&fit_refs);
        let data: Vec<Option<crate::invert::SegmentData>> =
            members.iter().map(|(r, _)| segment_data(r).ok()).collect();
        let mut fitted = Vec::new();
        let mut plastic = 0usize;
        let mut metal = 0usize;
        for ((r, f), d) in members.iter().zip(&data) {
            let Some(d) = d else { continue };
            let Ok(effects) = parse_effects(&f.effects) else {
                continue;
            };
            let setup = FitSetup {
                model: f.model,
                contact_mode: f.contact_mode,
                effects,
            };
            let Some(x) = coordinates(f, &setup) else {
                continue;
            };
            if r.material.is_plastic() {
                plastic += 1;
            } else {
                metal += 1;
            }
            fitted.push(FittedSegment {
                segment_id: r.segment_id.clone(),
                soil_zone: zone.clone(),
                data: d,
                setup,
                x,
                speed_rstd: [
                    relative(f.soil_p_wave_speed_std_m_per_s, f.soil_p_wave_speed_m_per_s),
                    relative(f.soil_s_wave_speed_std_m_per_s, f.soil_s_wave_speed_m_per_s),
                ],
            });
        }
        let by_zone = members_by_zone(&fitted);
        let Some(est) = by_zone.get(zone).and_then(|ms| estimate_zone(ms)) else {
            out.too_few += 1;
            continue;
        };
        out.zones.push(StoredZone {
            zone: zone.clone(),
            estimate: est,
            members_hash: hash,
            single_pipe_kind: plastic == 0 || metal == 0,
            fit_ids: fit_refs
                .iter()
                .map(|f| (f.segment_id.clone(), f.id.unwrap_or(-1)))
                .collect(),
            elapsed_ms: t0.elapsed().as_secs_f64() * 1e3,
        });
    }
    Ok(out)
}

/// The zones' part of a field update that found the field current: its inputs, the zones'
/// member fits among them, are those of the last rebuild, so every declared zone with a stored
/// estimate is up to date and the others had too few fitted segments.
pub fn zones_up_to_date(conn: &Connection) -> Result<Option<ZoneUpdate>, DbError> {
    let declared = crate::db::zones::declared_zones(conn)?;
    if declared.is_empty() {
        return Ok(None);
    }
    let stored = declared.iter().filter(|z| z.1).count();
    Ok(Some(ZoneUpdate {
        up_to_date: stored,
        too_few: declared.len() - stored,
        ..ZoneUpdate::default()
    }))
}

/// Store the estimates of [`estimate_stored_zones`] under `run_id` in `zone_fits` /
/// `zone_members`: a zone whose latest stored estimate has the same member fits is counted up
/// to date and not stored again (the estimate is a function of those fits).
pub fn store_zones(
    conn: &mut Connection,
    run_id: Option<i64>,
    zones: &ZoneEstimates,
    elapsed_s: f64,
) -> Result<ZoneUpdate, DbError> {
    let mut update = ZoneUpdate {
        too_few: zones.too_few,
        elapsed_s,
        ..ZoneUpdate::default()
    };
    for z in &zones.zones {
        if latest_zone_fit(conn, &z.zone)?.is_some_and(|s| s.members_hash == z.members_hash) {
            update.up_to_date += 1;
            continue;
        }
        let est = &z.estimate;
        let mut row = zone_row(&z.zone, run_id, est, &z.members_hash, z.single_pipe_kind);
        row.elapsed_ms = Some(z.elapsed_ms);
        let member_rows: Vec<ZoneMemberRow> = est
            .members
            .iter()
            .map(|m| ZoneMemberRow {
                segment_id: m.segment_id.clone(),
                fit_id: z.fit_ids.get(&m.segment_id).copied().unwrap_or(-1),
                shrunk_soil_youngs_modulus_pa: Some(m.shrunk_modulus),
                shrunk_soil_poisson: Some(m.shrunk_poisson),
                statistic: Some(m.statistic),
                zone_outlier: m.outlier,
            })
            .collect();
        update.outliers += est.members.iter().filter(|m| m.outlier).count();
        insert_zone_fit(conn, &row, &member_rows)?;
        update.estimated += 1;
    }
    Ok(update)
}

/// The `zone_fits` row of an estimate.
pub fn zone_row(
    zone: &str,
    run_id: Option<i64>,
    est: &ZoneEstimate,
    members_hash: &str,
    single_pipe_kind: bool,
) -> ZoneFitRow {
    let (cp, cs) = est.speeds();
    let outliers: Vec<&super::MemberResult> = est.members.iter().filter(|m| m.outlier).collect();
    let mut flags = Vec::new();
    if single_pipe_kind {
        flags.push(ZoneFlag::SinglePipeKind.as_str());
    }
    if !outliers.is_empty() {
        flags.push(ZoneFlag::Outlier.as_str());
    }
    if est.chi2_per_dof > POOR_FIT_CHI2_PER_DOF {
        flags.push(ZoneFlag::PoorFit.as_str());
    }
    let reasons: Vec<String> = outliers
        .iter()
        .map(|m| {
            let ev = OutlierEvidence::new(
                m.statistic,
                (est.modulus(), est.poisson),
                (10f64.powf(m.single.0), m.single.1),
                m.soil_density,
            );
            format!("{}: {}", m.segment_id, ev.reason(zone))
        })
        .collect();
    ZoneFitRow {
        id: None,
        soil_zone: zone.to_string(),
        run_id,
        n_segments: est.members.len() as i64,
        n_outliers: outliers.len() as i64,
        soil_youngs_modulus_pa: Some(est.modulus()),
        soil_youngs_modulus_lo_pa: Some(est.modulus_interval.lo),
        soil_youngs_modulus_hi_pa: Some(est.modulus_interval.hi),
        soil_poisson: Some(est.poisson),
        soil_poisson_lo: Some(est.poisson_interval.lo),
        soil_poisson_hi: Some(est.poisson_interval.hi),
        soil_density_kg_m3: Some(est.soil_density),
        soil_p_wave_speed_m_per_s: Some(cp),
        soil_p_wave_speed_lo_m_per_s: Some(est.p_wave_speed_interval.0),
        soil_p_wave_speed_hi_m_per_s: Some(est.p_wave_speed_interval.1),
        soil_s_wave_speed_m_per_s: Some(cs),
        soil_s_wave_speed_lo_m_per_s: Some(est.s_wave_speed_interval.0),
        soil_s_wave_speed_hi_m_per_s: Some(est.s_wave_speed_interval.1),
        scatter_youngs_modulus_decades: est.scatter.0,
        scatter_poisson: est.scatter.1,
        scatter_source: est.scatter_source.as_str().to_string(),
        chi2_per_dof: Some(est.chi2_per_dof),
        flags: flags.join(","),
        outliers: outliers
            .iter()
            .map(|m| m.segment_id.as_str())
            .collect::<Vec<_>>()
            .join(","),
        outlier_reasons: reasons.join("\n"),
        members_hash: members_hash.to_string(),
        elapsed_ms: None,
        created_at: None,
    }
}
