//! Zone estimation on a zoned synthetic network with known truth (the acceptance trial): fit
//! every segment, estimate every zone, and compare with the zones' true soils. Used by the
//! `zones` test and the `zones_acceptance` example (which prints the figures and the timing).

use std::time::Instant;

use rayon::prelude::*;

use crate::invert::{fit_segment, FitResult, FitSettings, Param};
use crate::synth::{generate, Defect, SynthOptions, SynthSegment};
use crate::types::FitStatus;

use crate::zones::bound::{member_fisher, zone_bound, ZoneBound};
use crate::zones::{estimate_member_zones, members_by_zone, FitSetup, FittedSegment, ZoneEstimate};

/// One zone's estimate against its truth.
#[derive(Debug, Clone)]
pub struct ZoneCheck {
    /// Zone.
    pub zone: String,
    /// True E_z, Pa, and ν_z.
    pub truth: (f64, f64),
    /// The estimate.
    pub estimate: ZoneEstimate,
    /// The median of the members' single fits: E (Pa), ν.
    pub single_median: (f64, f64),
    /// Members that are metal / plastic pipes.
    pub metal: usize,
    /// Plastic members.
    pub plastic: usize,
}

impl ZoneCheck {
    /// |E_est / E_true − 1|.
    pub fn modulus_error(&self) -> f64 {
        (self.estimate.modulus() / self.truth.0 - 1.0).abs()
    }
    /// |ν_est − ν_true|.
    pub fn poisson_error(&self) -> f64 {
        (self.estimate.poisson - self.truth.1).abs()
    }
}

/// A zoned network's fits and zone estimates.
#[derive(Debug, Clone)]
pub struct ZonedRun {
    /// The network.
    pub network: Vec<SynthSegment>,
    /// Every segment's fit.
    pub fits: Vec<FitResult>,
    /// Every zone.
    pub zones: Vec<ZoneCheck>,
    /// Wall-clock time of the segment fits, s.
    pub fit_seconds: f64,
    /// Wall-clock time of the zone estimation (members' models and zones), s.
    pub zone_seconds: f64,
    /// Of which the members' misfit models ([`crate::zones::member_from_fit`]), s.
    pub member_seconds: f64,
}

/// The zones of a fitted network and the time taken.
#[derive(Debug, Clone)]
pub struct Estimated {
    /// Every zone with an estimate.
    pub zones: Vec<ZoneCheck>,
    /// Wall-clock time of the zone estimation (members' models and zones), s.
    pub seconds: f64,
    /// Of which the members' misfit models, s.
    pub member_seconds: f64,
}

/// The default coordinates (log10 E_m, ν_m, ξ, effects…) of a fit's optimum.
pub fn optimum(r: &FitResult) -> Vec<f64> {
    r.estimates.iter().map(|e| e.coordinate).collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    crate::synth::network::recovery::quantile(&v, 0.5)
}

/// The zoned network of `zones × per_zone` segments that [`run`] and [`network_bounds`] use:
/// `synth --zones` with `seed`, no defects, the default mix, noise and scatter.
fn zoned_network(seed: u64, zones: usize, per_zone: usize) -> Vec<SynthSegment> {
    generate(&SynthOptions {
        segments: zones * per_zone,
        seed,
        defect_fraction: 0.0,
        zones,
        ..SynthOptions::default()
    })
}

/// Generate `zones × per_zone` segments with `seed` (no defects, the default mix, noise and
/// scatter), fit them with the default settings and estimate the zones.
pub fn run(seed: u64, zones: usize, per_zone: usize) -> ZonedRun {
    let network = zoned_network(seed, zones, per_zone);
    let settings = FitSettings::default();
    let t0 = Instant::now();
    let fits: Vec<FitResult> = network
        .par_iter()
        .map(|s| fit_segment(&s.segment_data(), &settings, crate::seed::derive(seed, 1)))
        .collect();
    let fit_seconds = t0.elapsed().as_secs_f64();
    let est = estimate(&network, &fits, |_| true);
    ZonedRun {
        network,
        fits,
        zones: est.zones,
        fit_seconds,
        zone_seconds: est.seconds,
        member_seconds: est.member_seconds,
    }
}

/// Estimate the zones of a fitted network from the segments `members` accepts (e.g. metal
/// pipes only), each in the zone its `soil_zone` names.
pub fn estimate(
    network: &[SynthSegment],
    fits: &[FitResult],
    members: impl Fn(&SynthSegment) -> bool,
) -> Estimated {
    let data: Vec<_> = network.iter().map(SynthSegment::segment_data).collect();
    let t1 = Instant::now();
    let fitted: Vec<FittedSegment<'_>> = network
        .iter()
        .zip(fits)
        .zip(&data)
        .filter(|((s, r), _)| {
            r.status != FitStatus::Failed && s.defect == Defect::None && members(s)
        })
        .filter_map(|((s, r), d)| {
            Some(FittedSegment {
                segment_id: s.id.clone(),
                soil_zone: s.soil_zone.clone()?,
                data: d,
                setup: FitSetup {
                    model: r.model,
                    contact_mode: r.contact_mode,
                    effects: r.effects.clone(),
                },
                x: optimum(r),
                speed_rstd: [
                    r.p_wave_speed.map(|w| w.relative()),
                    r.s_wave_speed.map(|w| w.relative()),
                ],
            })
        })
        .collect();
    let by_zone = members_by_zone(&fitted);
    let member_seconds = t1.elapsed().as_secs_f64();
    let estimates = estimate_member_zones(by_zone);
    let seconds = t1.elapsed().as_secs_f64();
    let zones = estimates
        .into_iter()
        .map(|(zone, estimate)| {
            let in_zone: Vec<(&SynthSegment, &FitResult)> = network
                .iter()
                .zip(fits)
                .filter(|(s, _)| estimate.members.iter().any(|m| m.segment_id == s.id))
                .collect();
            // The zone's truth: the soil most of its members were made in (a member moved in
            // from another zone keeps its own).
            let soils: Vec<(f64, f64)> = in_zone.iter().filter_map(|(s, _)| s.zone_soil).collect();
            let truth = *soils
                .iter()
                .max_by_key(|t| soils.iter().filter(|u| u == t).count())
                .expect("zoned network");
            let single = |p: Param| {
                median(
                    in_zone
                        .iter()
                        .filter_map(|(_, r)| r.get(p).map(|e| e.value))
                        .collect(),
                )
            };
            ZoneCheck {
                zone,
                truth,
                single_median: (single(Param::SoilModulus), single(Param::SoilPoisson)),
                metal: in_zone
                    .iter()
                    .filter(|(s, _)| !s.material.is_plastic())
                    .count(),
                plastic: in_zone
                    .iter()
                    .filter(|(s, _)| s.material.is_plastic())
                    .count(),
                estimate,
            }
        })
        .collect();
    Estimated {
        zones,
        seconds,
        member_seconds,
    }
}

/// The Cramér–Rao bound of a zone ([`crate::zones::bound`]) for its members' pipes, frequency plans and
/// noise, at their true soils and ξ, with the zone's scatter `tau` (τ_E decades, τ_ν) of P67.
/// Members whose information cannot be evaluated at their truth (or that carry a hidden effect
/// the fit does not model) are left out and counted in the second value.
pub fn bound_at_truth(
    members: &[&SynthSegment],
    setup: &FitSetup,
    tau: (f64, f64),
) -> (ZoneBound, usize) {
    let infos: Vec<Option<[f64; 4]>> = members
        .par_iter()
        .map(|s| {
            if !setup.effects.is_empty() || s.hidden.is_some() {
                return None;
            }
            let x = [s.soil_modulus.log10(), s.soil_poisson, s.contact];
            member_fisher(&s.segment_data(), setup, &x)
        })
        .collect();
    let ok: Vec<[f64; 4]> = infos.iter().flatten().copied().collect();
    (zone_bound(&ok, tau), infos.len() - ok.len())
}

/// [`bound_at_truth`] for the members of an estimated zone, fitted with `fits`' settings.
pub fn zone_bound_at_truth(
    network: &[SynthSegment],
    fits: &[FitResult],
    zone: &ZoneCheck,
    tau: (f64, f64),
) -> (ZoneBound, usize) {
    let mut members = Vec::new();
    let mut setup = None;
    for m in &zone.estimate.members {
        if let Some(i) = network.iter().position(|s| s.id == m.segment_id) {
            members.push(&network[i]);
            setup.get_or_insert_with(|| FitSetup {
                model: fits[i].model,
                contact_mode: fits[i].contact_mode,
                effects: fits[i].effects.clone(),
            });
        }
    }
    let setup = setup.unwrap_or_else(|| default_setup(&FitSettings::default()));
    bound_at_truth(&members, &setup, tau)
}

/// The setup of a fit made with `settings`.
pub fn default_setup(settings: &FitSettings) -> FitSetup {
    FitSetup {
        model: settings.model,
        contact_mode: settings.contact_mode,
        effects: settings.effects.clone(),
    }
}

/// The zones of a zoned network (generated as [`run`] does, without fitting it) and the
/// Cramér–Rao bound of each for the default fit settings: (zone, bound, truth E_z Pa, ν_z).
pub fn network_bounds(
    seed: u64,
    zones: usize,
    per_zone: usize,
    tau: (f64, f64),
) -> Vec<(String, ZoneBound, (f64, f64))> {
    let network = zoned_network(seed, zones, per_zone);
    let setup = default_setup(&FitSettings::default());
    let mut by_zone: std::collections::BTreeMap<String, Vec<&SynthSegment>> = Default::default();
    for s in &network {
        if let Some(z) = &s.soil_zone {
            by_zone.entry(z.clone()).or_default().push(s);
        }
    }
    by_zone
        .into_iter()
        .filter_map(|(z, ms)| {
            let truth = ms[0].zone_soil?;
            Some((z, bound_at_truth(&ms, &setup, tau).0, truth))
        })
        .collect()
}
