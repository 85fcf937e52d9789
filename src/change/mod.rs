//! Whether a pipe changed between two measurement campaigns, and why (model §7.14).
//!
//! The later campaign B is fitted as every segment is (the current state); the earlier
//! campaign A and both campaigns pooled are then fitted from B's optimum ([`refit_from`]), which
//! lies in their basin unless the pipe changed. The test compares one state for both campaigns
//! with separate states (P94), at a level calibrated by simulation ([`CHANGE_ALPHA`]); where
//! the pipe changed, the cause is the one quantity which, let change on its own, explains both
//! campaigns at the lowest information criterion (P95, the diagnosis's [`aicc`]). Where it did
//! not, the current fit pools both campaigns. No simulation runs per segment.

pub mod joint;

use crate::db::changes::{CampaignSpeedRow, ChangeRecord, ChangeRow};
use crate::diagnose::{aicc, TIE_LR};
use crate::invert::problem::{pool, SegmentData, Weighting};
use crate::invert::{fit_segment, refit_from, FitResult, FitSettings, Method, Param, WithError};
use crate::physics::effects::Effect;
use crate::physics::Material;
use crate::stats::chi2_upper_tail;
use crate::types::FitStatus;

use joint::Joint;

/// The level of the change test: a pipe is reported `changed` when its p-value (P94) is below
/// this. The p-value is that of χ² with as many degrees of freedom as the fit has parameters;
/// the false-alarm rate this gives on unchanged pipes is measured by simulation
/// (tests/change_test.rs; docs/campaigns.md).
pub const CHANGE_ALPHA: f64 = 0.005;

/// The causes of a change a second campaign can show (model §7.14).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Cause {
    /// The soil's E_m, ν_m and ξ (drying, wetting, freezing, disturbance).
    SoilChange,
    /// Free air in the water (E3).
    AirInWater,
    /// The wall's effective thickness (E4; not plastic walls).
    WallThinning,
    /// The wall's loss factor (E2).
    PipeLoss,
}

impl Cause {
    /// Every cause, in the order reported.
    pub const ALL: [Cause; 4] = [
        Cause::SoilChange,
        Cause::AirInWater,
        Cause::WallThinning,
        Cause::PipeLoss,
    ];

    /// The name in the database and the export (`change_effect`).
    pub fn as_str(self) -> &'static str {
        match self {
            Cause::SoilChange => "soil_change",
            Cause::AirInWater => "air_in_water",
            Cause::WallThinning => "wall_thinning",
            Cause::PipeLoss => "pipe_loss",
        }
    }

    /// The effect whose parameter this cause changes (`None`: the soil's own parameters).
    pub fn effect(self) -> Option<Effect> {
        match self {
            Cause::SoilChange => None,
            Cause::AirInWater => Some(Effect::AirInWater),
            Cause::WallThinning => Some(Effect::WallThinning),
            Cause::PipeLoss => Some(Effect::PipeLoss),
        }
    }

    /// The parameters the later campaign has of its own under this cause.
    pub fn parameters(self) -> Vec<Param> {
        match self.effect() {
            None => vec![Param::SoilModulus, Param::SoilPoisson, Param::Contact],
            Some(e) => vec![Param::Effect(e)],
        }
    }

    /// Whether a pipe of `material` can change this way (a plastic wall does not thin).
    pub fn applies_to(self, material: Option<Material>) -> bool {
        match (self.effect(), material) {
            (Some(e), Some(m)) => e.applies_to(m),
            _ => true,
        }
    }
}

/// The outcome of the change test of one segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// The later campaign differs from the earlier by more than their noise (P94).
    Changed,
    /// One state explains both campaigns: they are pooled.
    Unchanged,
    /// The segment has one campaign.
    OneCampaign,
    /// Two campaigns, but no test: a fit failed, or the measurements have no standard
    /// deviations (the test is in χ²), or the method is the paper's.
    Untested,
}

impl Status {
    /// The name in the database and the export (`change_status`).
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Changed => "changed",
            Status::Unchanged => "unchanged",
            Status::OneCampaign => "one_campaign",
            Status::Untested => "untested",
        }
    }
}

/// One cause's joint fit of both campaigns (P95).
#[derive(Debug, Clone, PartialEq)]
pub struct CauseFit {
    /// The cause.
    pub cause: Cause,
    /// Summed χ² of both campaigns.
    pub chi2: f64,
    /// Its AICc with the joint parameter count.
    pub aicc: f64,
    /// The later campaign's own values of the quantities that changed (physical units).
    pub after: Vec<(Param, f64)>,
    /// The later campaign's coordinates at the joint optimum (the fit's space with the
    /// cause's effect added where it lacks it): the start of the current state's fit.
    pub later_x: Vec<f64>,
}

/// The change test of one segment (model §7.14).
#[derive(Debug, Clone)]
pub struct ChangeTest {
    /// What the test found.
    pub status: Status,
    /// Λ = χ²_one − χ²_A − χ²_B (P94), before the misfit scale.
    pub lr: f64,
    /// The misfit scale s² ≥ 1 (P94) the statistic is divided by.
    pub scale: f64,
    /// Degrees of freedom of the reference χ² (the fit's parameters).
    pub dof: usize,
    /// P(χ²_dof > Λ / s²).
    pub p_value: f64,
    /// The summed χ² of both campaigns under one state.
    pub chi2_one: f64,
    /// The earlier campaign's own χ².
    pub chi2_earlier: f64,
    /// The later campaign's own χ².
    pub chi2_later: f64,
    /// The earlier campaign fitted on its own (its state and speed).
    pub earlier: Option<FitResult>,
    /// Both campaigns pooled (one state): the current fit when unchanged.
    pub pooled: Option<FitResult>,
    /// Where the pipe changed by a named effect the fit lacks (air, a thinner wall, more wall
    /// loss), the latest campaign fitted with that effect, from the joint optimum: the current
    /// state, described by the physics that changed.
    pub current: Option<FitResult>,
    /// The named cause when changed; `None` there means unexplained.
    pub cause: Option<Cause>,
    /// Causes whose AICc is within [`TIE_LR`] of the named one's: the data cannot tell them
    /// apart from it.
    pub ambiguous_with: Vec<Cause>,
    /// Every cause fitted, in [`Cause::ALL`]'s order.
    pub causes: Vec<CauseFit>,
    /// Why the test did not run, or what it leaves open.
    pub note: Option<String>,
}

impl ChangeTest {
    pub fn untested(note: impl Into<String>) -> ChangeTest {
        ChangeTest {
            status: Status::Untested,
            lr: f64::NAN,
            scale: f64::NAN,
            dof: 0,
            p_value: f64::NAN,
            chi2_one: f64::NAN,
            chi2_earlier: f64::NAN,
            chi2_later: f64::NAN,
            earlier: None,
            pooled: None,
            current: None,
            cause: None,
            ambiguous_with: Vec::new(),
            causes: Vec::new(),
            note: Some(note.into()),
        }
    }

    /// The change test's statistic Λ / s² (P94).
    pub fn statistic(&self) -> f64 {
        self.lr / self.scale
    }
}

/// Seed stream of the earlier campaign's own search, where a polish from the latest state does
/// not explain it.
pub const EARLIER_STREAM: u64 = 0x6561_726c;

/// Whether a fit leaves a misfit its noise does not explain (the `high_misfit` test, P88).
fn misfits(fit: &FitResult) -> bool {
    fit.status == FitStatus::Failed || fit.has_flag(crate::invert::FlagCode::HighMisfit)
}

/// The number of residuals of a segment's data (two per measurement).
fn residuals_of(data: &SegmentData) -> usize {
    2 * data.measurements.len()
}

/// Test whether the pipe of `later` (fitted as `fit_later` with `settings`) is the pipe of
/// `earlier`, and name the cause where it is not (model §7.14, P94–P96). Deterministic.
pub fn test_change(
    earlier: &SegmentData,
    later: &SegmentData,
    settings: &FitSettings,
    fit_later: &FitResult,
    seed: u64,
) -> ChangeTest {
    if settings.method != Method::Default {
        return ChangeTest::untested("the change test needs the default method's χ²");
    }
    if settings.effects.iter().any(|e| e.is_discrete()) {
        return ChangeTest::untested("not tested with a choice among inventory records");
    }
    if fit_later.status == FitStatus::Failed || fit_later.weighting != Weighting::ChiSquare {
        return ChangeTest::untested(if fit_later.status == FitStatus::Failed {
            "the latest campaign's fit failed"
        } else {
            "the measurements have no standard deviations (the test is in χ²)"
        });
    }
    let Some(pooled) = pool(earlier, later) else {
        return ChangeTest::untested(
            "the earlier campaign's measurements have no standard deviations",
        );
    };
    let x_later = fit_later.coordinates();
    let pooled_fit = refit_from(&pooled.data, settings, std::slice::from_ref(&x_later));
    let mut starts = vec![x_later.clone()];
    if pooled_fit.status != FitStatus::Failed {
        starts.push(pooled_fit.coordinates());
    }
    let mut earlier_fit = refit_from(earlier, settings, &starts);
    if misfits(&earlier_fit) {
        // The latest state's basin is not the earlier campaign's (the pipe changed enough to
        // move the soil that best explains it): the earlier campaign is searched on its own.
        let searched = fit_segment(earlier, settings, crate::seed::derive(seed, EARLIER_STREAM));
        if searched.status != FitStatus::Failed
            && (earlier_fit.status == FitStatus::Failed || searched.misfit < earlier_fit.misfit)
        {
            earlier_fit = searched;
        }
    }
    if earlier_fit.status == FitStatus::Failed || pooled_fit.status == FitStatus::Failed {
        return ChangeTest {
            earlier: (earlier_fit.status != FitStatus::Failed).then_some(earlier_fit),
            ..ChangeTest::untested(
                "the earlier campaign could not be fitted from the latest's state",
            )
        };
    }
    let p = x_later.len();
    let n = residuals_of(earlier) + residuals_of(later);
    let chi2_a = earlier_fit.misfit;
    let chi2_b = fit_later.misfit;
    let mut pooled_fit = pooled_fit;
    let mut chi2_one = pooled_fit.misfit + pooled.consistency_chi2;
    let planned = alternatives_planned(settings, earlier.material);
    let screen = Screen {
        lr_separate: (chi2_one - chi2_a - chi2_b).max(0.0),
        alternatives: planned,
        earlier_misfit_p: chi2_upper_tail(chi2_a, residuals_of(earlier).saturating_sub(p) as f64),
        later_misfit_p: chi2_upper_tail(chi2_b, residuals_of(later).saturating_sub(p) as f64),
    };
    let causes = if screen.passes() {
        fit_causes(
            earlier,
            later,
            settings,
            &earlier_fit,
            fit_later,
            &pooled_fit,
        )
    } else {
        Vec::new()
    };
    let mut alts = alternatives(chi2_one, chi2_a + chi2_b, p, &causes, settings);
    let mut verdict = judge(n, p, &alts, planned).0;
    if verdict.p_value < CHANGE_ALPHA {
        // Before a change is reported, one state is given every chance: the pooled fit is
        // polished from the earlier campaign's optimum too (a poorly determined soil has
        // several basins), and a cause's effect is allowed in both campaigns alike, so that
        // Λ_c measures the effect's change, not its presence (a defect both campaigns share,
        // such as attenuations in dB/m, is absorbed by an effect in either).
        let again = refit_from(&pooled.data, settings, &[earlier_fit.coordinates()]);
        if again.status != FitStatus::Failed && again.misfit < pooled_fit.misfit {
            pooled_fit = again;
            chi2_one = pooled_fit.misfit + pooled.consistency_chi2;
            alts = alternatives(chi2_one, chi2_a + chi2_b, p, &causes, settings);
        }
        // A shared effect only lowers its own alternative's Λ, so the smallest p-value is
        // final once it belongs to an alternative whose null is complete: the shared fits are
        // made in the order of the p-values, and only while they can change the verdict.
        let mut shared_done = vec![false; alts.len()];
        loop {
            let (v, i) = judge(n, p, &alts, planned);
            verdict = v;
            if verdict.p_value >= CHANGE_ALPHA || shared_done[i] {
                break;
            }
            shared_done[i] = true;
            let Some(e) = alts[i]
                .cause
                .and_then(Cause::effect)
                .filter(|e| !settings.effects.contains(e))
            else {
                break;
            };
            if let Some(chi2) = shared_effect_chi2(earlier, later, settings, e, &pooled_fit) {
                alts[i].null = alts[i].null.min(chi2 + pooled.consistency_chi2);
            }
        }
    }
    let Verdict {
        p_value,
        lr,
        dof,
        scale,
    } = verdict;
    let changed = p_value < CHANGE_ALPHA;
    let mut t = ChangeTest {
        status: if changed {
            Status::Changed
        } else {
            Status::Unchanged
        },
        lr,
        scale,
        dof,
        p_value,
        chi2_one,
        chi2_earlier: chi2_a,
        chi2_later: chi2_b,
        earlier: None,
        pooled: None,
        current: None,
        cause: None,
        ambiguous_with: Vec::new(),
        causes,
        note: None,
    };
    if changed {
        name_cause(&mut t, n, p, residuals_of(earlier));
        t.current = current_with_cause(&t, later, settings, fit_later);
    } else {
        t.pooled = Some(widened_by_consistency(
            pooled_fit,
            pooled.consistency_chi2,
            n,
        ));
    }
    t.earlier = Some(earlier_fit);
    t
}

/// The latest campaign fitted with the named cause's effect, where the fit lacks it, polished
/// from the joint optimum; kept when it fits the latest campaign better than the fit without.
fn current_with_cause(
    t: &ChangeTest,
    later: &SegmentData,
    settings: &FitSettings,
    fit_later: &FitResult,
) -> Option<FitResult> {
    let cause = t.cause?;
    let e = cause.effect()?;
    if settings.effects.contains(&e) {
        return None;
    }
    let cf = t.causes.iter().find(|c| c.cause == cause)?;
    let mut with = settings.clone();
    with.effects.push(e);
    let fit = refit_from(later, &with, std::slice::from_ref(&cf.later_x));
    (fit.status != FitStatus::Failed && fit.misfit < fit_later.misfit).then_some(fit)
}

/// The pooled fit with its errors widened by the campaigns' disagreement as well (P96): its χ²
/// over both campaigns is its own plus the consistency term C, over n − p degrees of freedom,
/// and the Birge ratio (P88) of that, not of the pooled χ² alone, widens its errors. A change
/// too small to report still widens the errors of the speed that pools across it.
fn widened_by_consistency(mut fit: FitResult, consistency: f64, n: usize) -> FitResult {
    let p = fit.estimates.len();
    let m = 2 * fit.n_measurements;
    let own = crate::stats::birge_ratio(fit.misfit, m, p);
    let both = crate::stats::birge_ratio(fit.misfit + consistency, n, p);
    let f = both / own;
    if !(f.is_finite() && f > 1.0) {
        return fit;
    }
    for e in &mut fit.estimates {
        e.std = e.std.map(|s| s * f);
        e.coordinate_std *= f;
    }
    if let Some(v) = fit.leak_band_speed.as_mut() {
        v.std *= f;
    }
    for c in &mut fit.curve {
        c.phase_speed_std = c.phase_speed_std.map(|s| s * f);
        c.attenuation_db_std = c.attenuation_db_std.map(|s| s * f);
    }
    fit
}

/// The change test's verdict before the cause is named.
struct Verdict {
    /// Bonferroni-corrected p-value over the alternatives.
    p_value: f64,
    /// Λ of the alternative that gave it.
    lr: f64,
    /// Its degrees of freedom.
    dof: usize,
    /// The misfit scale s².
    scale: f64,
}

/// One alternative to one state in P94.
#[derive(Debug, Clone, Copy)]
struct Alternative {
    /// The cause it lets change (`None`: separate states).
    cause: Option<Cause>,
    /// Its χ² over both campaigns.
    chi2: f64,
    /// The parameters it adds to one state, k_a.
    k: usize,
    /// χ²_null,a: one state's χ², or that of one state with the cause's effect shared by
    /// both campaigns where that is lower.
    null: f64,
}

/// Whether a cause is an alternative of P94 for a pipe of `material` with `settings`: soil
/// change is one only where the fit has effects besides the soil, since otherwise it is the
/// separate states.
fn is_alternative(cause: Cause, settings: &FitSettings, material: Option<Material>) -> bool {
    cause.applies_to(material) && (cause != Cause::SoilChange || !settings.effects.is_empty())
}

/// K of P94: separate states and every cause that is an alternative for this pipe, whether
/// or not its fit runs (the screen, [`Screen`], or a failed fit leaves it out, never the
/// count).
fn alternatives_planned(settings: &FitSettings, material: Option<Material>) -> usize {
    1 + Cause::ALL
        .iter()
        .filter(|c| is_alternative(**c, settings, material))
        .count()
}

/// The alternatives that were fitted: separate states (every parameter the campaign's own,
/// k = p) and each cause (its quantity the later campaign's own, k = its parameters), each
/// with one state's χ² as its null.
fn alternatives(
    chi2_one: f64,
    chi2_separate: f64,
    p: usize,
    causes: &[CauseFit],
    settings: &FitSettings,
) -> Vec<Alternative> {
    let mut out = vec![Alternative {
        cause: None,
        chi2: chi2_separate,
        k: p,
        null: chi2_one,
    }];
    out.extend(
        causes
            .iter()
            // Only causes that apply to the pipe's material were fitted (`fit_causes`).
            .filter(|c| is_alternative(c.cause, settings, None))
            .map(|c| Alternative {
                cause: Some(c.cause),
                chi2: c.chi2,
                k: c.cause.parameters().len(),
                null: chi2_one,
            }),
    );
    out
}

/// P94 over the alternatives: each gives Λ_a = χ²_null,a − χ²_a on k_a degrees of freedom.
/// The misfit beyond the noise of the alternative that fits best per degree of freedom widens
/// them all, as the Birge ratio widens a fit's errors (P88). The smallest p-value,
/// Bonferroni-corrected for the `planned` alternatives, is the test's; with it, the index of
/// the alternative that gave it.
fn judge(n: usize, p: usize, alts: &[Alternative], planned: usize) -> (Verdict, usize) {
    let scale = alts
        .iter()
        .filter_map(|a| {
            let dof = n.checked_sub(p + a.k).filter(|d| *d > 0)?;
            Some(a.chi2 / dof as f64)
        })
        .fold(f64::INFINITY, f64::min)
        .max(1.0);
    let scale = if scale.is_finite() { scale } else { 1.0 };
    let (mut p_value, mut lr, mut dof, mut at) = (1.0f64, 0.0f64, p, 0);
    for (i, a) in alts.iter().enumerate() {
        let l = (a.null - a.chi2).max(0.0);
        let pv = chi2_upper_tail(l / scale, a.k as f64);
        if pv < p_value || (pv == p_value && l > lr) {
            (p_value, lr, dof, at) = (pv, l, a.k, i);
        }
    }
    let k = planned.max(alts.len()) as f64;
    (
        Verdict {
            p_value: (p_value * k).min(1.0),
            lr,
            dof,
            scale,
        },
        at,
    )
}

/// The loose screen before the causes are fitted: their joint fits (P95) run only where a
/// change could be reported. Λ of a cause nested in the separate states is at most Λ_sep, so
/// where even one degree of freedom and no misfit scale (s² = 1) would leave Λ_sep's
/// Bonferroni p-value above [`SCREEN_LEVEL`], a nested cause cannot reach the level; a cause
/// whose effect the fit lacks can exceed Λ_sep only by what the effect explains of a campaign
/// the fit leaves unexplained, so the causes are fitted too wherever either campaign's own
/// χ² has a p-value below [`SCREEN_MISFIT`]. What the screen lets through is measured against
/// fitting every cause (docs/campaigns.md).
struct Screen {
    /// Λ_sep = χ²_one − χ²_A − χ²_B.
    lr_separate: f64,
    /// K of P94.
    alternatives: usize,
    /// P(χ²_{n_A − p} > χ²_A).
    earlier_misfit_p: f64,
    /// P(χ²_{n_B − p} > χ²_B).
    later_misfit_p: f64,
}

/// The screen's level on the bound of P94 (20 × [`CHANGE_ALPHA`]).
pub const SCREEN_LEVEL: f64 = 0.1;

/// The screen's level on a campaign's own misfit (ten times the `high_misfit` level, P88).
pub const SCREEN_MISFIT: f64 = 0.01;

impl Screen {
    /// Whether the causes are fitted.
    fn passes(&self) -> bool {
        let bound = chi2_upper_tail(self.lr_separate, 1.0) * self.alternatives as f64;
        !(bound >= SCREEN_LEVEL
            && self.earlier_misfit_p >= SCREEN_MISFIT
            && self.later_misfit_p >= SCREEN_MISFIT)
    }
}

/// The χ² of the pooled campaigns under one state with effect `e` (one value for both), from
/// the pooled optimum with `e` at its neutral value and across its range.
fn shared_effect_chi2(
    earlier: &SegmentData,
    later: &SegmentData,
    settings: &FitSettings,
    e: Effect,
    pooled_fit: &FitResult,
) -> Option<f64> {
    let sys = pooled_fit.system?;
    let mut with = settings.clone();
    with.effects.push(e);
    let pooled = pool(earlier, later)?;
    let x = pooled_fit.coordinates();
    let spec = crate::invert::problem::parameter_space(with.method, &with.effects)
        .last()
        .copied()?;
    let neutral = spec
        .coordinate(e.neutral_value(&sys)?)
        .clamp(spec.lower, spec.upper);
    let starts: Vec<Vec<f64>> = std::iter::once(neutral)
        .chain(
            joint::OWN_START_FRACTIONS
                .iter()
                .map(|f| spec.lower + f * (spec.upper - spec.lower)),
        )
        .map(|v| x.iter().copied().chain([v]).collect())
        .collect();
    let fit = refit_from(&pooled.data, &with, &starts);
    (fit.status != FitStatus::Failed).then_some(fit.misfit)
}

/// Every applicable cause fitted jointly to both campaigns (P95), in [`Cause::ALL`]'s order.
fn fit_causes(
    earlier: &SegmentData,
    later: &SegmentData,
    settings: &FitSettings,
    earlier_fit: &FitResult,
    later_fit: &FitResult,
    pooled_fit: &FitResult,
) -> Vec<CauseFit> {
    let Some(sys_a) = earlier_fit.system else {
        return Vec::new();
    };
    let n = residuals_of(earlier) + residuals_of(later);
    let (xa, xb, xp) = (
        earlier_fit.coordinates(),
        later_fit.coordinates(),
        pooled_fit.coordinates(),
    );
    let mut out = Vec::new();
    for cause in Cause::ALL {
        if !cause.applies_to(earlier.material) {
            continue;
        }
        let Some(j) = Joint::new(earlier, later, settings, &cause.parameters(), &sys_a) else {
            continue;
        };
        let mut starts = j.spread_starts(&j.start(&xa, &xb));
        starts.extend(j.spread_starts(&j.start(&xp, &xb)));
        let Some(opt) = j.fit(&starts) else { continue };
        out.push(CauseFit {
            cause,
            chi2: opt.chi2,
            aicc: aicc(opt.chi2, n, j.dim()),
            after: opt.own_values,
            later_x: opt.later_x,
        });
    }
    out
}

/// P95: the cause of lowest AICc is named; those within [`TIE_LR`] of it are ambiguous with
/// it; none is named when even the best leaves both campaigns unexplained (χ² beyond the fit's
/// misfit level) while the earlier campaign alone fits. `n` residuals in all, `p` parameters of
/// one state, `n_earlier` residuals of the earlier campaign.
fn name_cause(t: &mut ChangeTest, n: usize, p: usize, n_earlier: usize) {
    let Some(best) = t
        .causes
        .iter()
        .min_by(|a, b| a.aicc.total_cmp(&b.aicc))
        .cloned()
    else {
        t.note = Some("no cause could be fitted to both campaigns".into());
        return;
    };
    let k = p + best.cause.parameters().len();
    let level = crate::invert::flags::MISFIT_P_VALUE;
    let explained = chi2_upper_tail(best.chi2, n.saturating_sub(k) as f64) >= level;
    let earlier_fits = chi2_upper_tail(t.chi2_earlier, n_earlier.saturating_sub(p) as f64) >= level;
    if !explained && earlier_fits {
        t.note = Some(format!(
            "no one quantity explains both campaigns (best: {}, χ² {:.1} on {} residuals)",
            best.cause.as_str(),
            best.chi2,
            n
        ));
        return;
    }
    t.cause = Some(best.cause);
    t.ambiguous_with = t
        .causes
        .iter()
        .filter(|c| c.cause != best.cause && c.aicc <= best.aicc + TIE_LR)
        .map(|c| c.cause)
        .collect();
}

/// A campaign of a segment, as the stored rows name it.
#[derive(Debug, Clone, PartialEq)]
pub struct CampaignName {
    /// Its name.
    pub name: String,
    /// Its newest `measured_on` on the segment.
    pub measured_on: Option<String>,
}

/// The speed row of a campaign fitted on its own.
fn speed_row(c: &CampaignName, fit: &FitResult) -> CampaignSpeedRow {
    CampaignSpeedRow {
        campaign: c.name.clone(),
        measured_on: c.measured_on.clone(),
        leak_band_speed_m_per_s: fit.leak_band_speed.map(|v| v.value),
        leak_band_speed_std_m_per_s: fit.leak_band_speed.map(|v| v.std),
        chi2: (fit.status != FitStatus::Failed).then_some(fit.misfit),
        n_measurements: i64::try_from(fit.n_measurements).unwrap_or(i64::MAX),
        soil_youngs_modulus_pa: fit.soil_modulus(),
        soil_poisson: fit.soil_poisson(),
        contact: fit.contact(),
    }
}

/// The relative change of the leak-band speed from `before` to `after`, %, with its error
/// (the two campaigns' fits are independent: their relative errors add in quadrature).
pub fn speed_change_pct(before: WithError, after: WithError) -> Option<(f64, f64)> {
    if !(before.value > 0.0 && after.value.is_finite()) {
        return None;
    }
    let ratio = after.value / before.value;
    let rel = ((before.std / before.value).powi(2) + (after.std / after.value).powi(2)).sqrt();
    Some((100.0 * (ratio - 1.0), 100.0 * ratio * rel))
}

/// What a calibrate fit of a segment stores of its campaigns: the test of `latest` against
/// `earlier` (`None`: one campaign) and each one's speed fitted on its own. `latest_alone` is
/// the latest campaign's own fit.
pub fn change_record(
    segment_id: &str,
    run_id: i64,
    latest: &CampaignName,
    earlier: Option<(&CampaignName, &ChangeTest)>,
    latest_alone: &FitResult,
) -> ChangeRecord {
    let mut change = ChangeRow {
        segment_id: segment_id.to_string(),
        run_id,
        campaign: latest.name.clone(),
        status: Status::OneCampaign.as_str().to_string(),
        ..ChangeRow::default()
    };
    let mut speeds = Vec::new();
    let Some((ec, t)) = earlier else {
        speeds.push(speed_row(latest, latest_alone));
        return ChangeRecord { change, speeds };
    };
    let finite = |v: f64| v.is_finite().then_some(v);
    change.since_campaign = Some(ec.name.clone());
    change.status = t.status.as_str().to_string();
    change.statistic = finite(t.statistic());
    change.dof = (t.dof > 0).then(|| i64::try_from(t.dof).unwrap_or(i64::MAX));
    change.p_value = finite(t.p_value);
    change.alpha = (t.status != Status::Untested).then_some(CHANGE_ALPHA);
    change.chi2_one_state = finite(t.chi2_one);
    change.chi2_earlier = finite(t.chi2_earlier);
    change.chi2_latest = finite(t.chi2_later);
    change.pooled = t.pooled.is_some();
    change.note = t.note.clone();
    if t.status == Status::Changed {
        change.effect = Some(t.cause.map_or("unexplained", Cause::as_str).to_string());
    }
    change.ambiguous_with = t
        .ambiguous_with
        .iter()
        .map(|c| c.as_str())
        .collect::<Vec<_>>()
        .join(",");
    change.causes = t
        .causes
        .iter()
        .map(|c| format!("{} chi2 {:.2} AICc {:.2}", c.cause.as_str(), c.chi2, c.aicc))
        .collect::<Vec<_>>()
        .join("; ");
    if let Some(e) = &t.earlier {
        change.earlier_soil_youngs_modulus_pa = e.soil_modulus();
        change.earlier_soil_poisson = e.soil_poisson();
        change.earlier_contact = e.contact();
        if let (Some(a), Some(b)) = (e.leak_band_speed, latest_alone.leak_band_speed) {
            if let Some((pct, std)) = speed_change_pct(a, b) {
                change.leak_band_speed_pct = Some(pct);
                change.leak_band_speed_pct_std = Some(std);
            }
        }
        if let Some(cf) = t.cause.and_then(|c| t.causes.iter().find(|f| f.cause == c)) {
            // The quantity that changed: E_m for the soil, the effect's parameter otherwise;
            // before is the earlier state's (an effect the fit lacks is at its neutral value).
            let (param, after) = cf.after[0];
            change.effect_value_after = Some(after);
            change.effect_value_before = match param {
                Param::Effect(eff) => e
                    .get(param)
                    .map(|v| v.value)
                    .or_else(|| e.system.and_then(|s| eff.neutral_value(&s))),
                _ => e.get(param).map(|v| v.value),
            };
        }
        speeds.push(speed_row(ec, e));
    }
    speeds.push(speed_row(latest, latest_alone));
    ChangeRecord { change, speeds }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn screen(lr: f64, pa: f64, pb: f64) -> Screen {
        Screen {
            lr_separate: lr,
            alternatives: 4,
            earlier_misfit_p: pa,
            later_misfit_p: pb,
        }
    }

    #[test]
    fn the_screen_fits_causes_where_a_change_could_be_reported() {
        // K · P(χ²_1 > Λ) with K = 4: Λ = 4 gives 0.182 ≥ 0.1 (screened out), Λ = 6 gives
        // 0.057 (fitted).
        assert!(!screen(4.0, 0.5, 0.5).passes());
        assert!(screen(6.0, 0.5, 0.5).passes());
        // Either campaign unexplained by the fit's physics: fitted whatever Λ_sep.
        assert!(screen(0.0, 0.005, 0.5).passes());
        assert!(screen(0.0, 0.5, 0.005).passes());
        // A statistic that is not a number is never screened out.
        assert!(screen(f64::NAN, 0.5, 0.5).passes());
    }

    #[test]
    fn the_bonferroni_count_is_that_of_the_planned_alternatives() {
        let alt = |cause, chi2, k, null| Alternative {
            cause,
            chi2,
            k,
            null,
        };
        // n = 24 residuals, p = 3; separate states leave χ² 18 on 18 dof (s² = 1).
        let alts = [
            alt(None, 18.0, 3, 30.0),
            alt(Some(Cause::AirInWater), 19.0, 1, 30.0),
        ];
        let (v, at) = judge(24, 3, &alts, 4);
        let expected = 4.0 * chi2_upper_tail(11.0, 1.0);
        assert_eq!(at, 1);
        assert!((v.p_value - expected).abs() < 1e-12, "{}", v.p_value);
        assert_eq!(v.dof, 1);
        // The cause screened out or failed: still four alternatives in the count.
        let (v, at) = judge(24, 3, &alts[..1], 4);
        assert_eq!(at, 0);
        let expected = 4.0 * chi2_upper_tail(12.0, 3.0);
        assert!((v.p_value - expected).abs() < 1e-12, "{}", v.p_value);
    }
}
