//! Group detection: an effect present in many members of a group (air in a pressure
//! zone, thinning of old cast iron) can be below the per-segment threshold in each one. The
//! pooled test adds the members' likelihood-ratio gains for each candidate effect: the χ² the
//! member's refit with the effect removes (χ²(base) − χ²(extended), clamped at 0), or its score
//! statistic where the effect was not refitted (the data pulled its parameter out of its allowed
//! range: the gain is then 0 to first order). Each gain tests one parameter on the bound of its
//! range, so under "no effect in any member" it is χ̄² = ½χ²₀ + ½χ²₁ (Self & Liang 1987), and
//! the sum over n independent members has the binomial mixture Σ_k C(n,k)2⁻ⁿχ²_k
//! ([`super::stats::sum_chibar_sf`]; model P90).
//!
//! Why gains, not scores: the score is the first-order view at the base fit. In the local model
//! (Z_i the standardised efficient score of member i) score and gain coincide, and the sum of
//! χ̄² statistics is as powerful as a mixture likelihood ratio for an effect carried by a
//! fraction of the members, and much more powerful than a pooled one-direction score near the
//! one-segment floor (`examples/group_power.rs`, docs/group-test.md). On real fits the base has
//! already bent its soil parameters towards the effect, and the score captures only part of
//! what the refit removes; summing scores then loses most of the power.
//!
//! Four refinements make the sum name the right effect on refitted members
//! ([`member_gains`], [`less_shared`], [`vuong_z`], [`rank_twins`]):
//!
//! * **What every candidate removes is no evidence for any one of them.** A base fit that missed
//!   the soil optimum (or a noise draw the base fits badly) gives every candidate the same part
//!   of its gain. Each member's gains lose their smallest value over the candidate effects
//!   before they are summed. This only lowers each term, so the mixture's tail stays an upper
//!   bound of the statistic's null tail: the p-values are conservative.
//! * **Twins are refitted together.** Air in the water and a thinner wall both add compliance
//!   to the pipe–fluid system (air lowers the fluid's bulk modulus, P60; thinning the wall's
//!   hoop stiffness, P62 in P10): both slow the wave. A member's diagnosis that refitted one of
//!   them from a positive score may have left the other at its score, 0 to first order, even
//!   though its refit removes as much. Comparing a refit with a score would rank the refitted
//!   twin first; the missing twin is refitted ([`TWINS`]).
//! * **Which detected effects cannot be told apart** is decided by Vuong's (1989) test of two
//!   non-nested extensions of the base: the members' gain differences g_A − g_B are twice their
//!   log-likelihood ratios, independent over members; B is reported with A unless A is better at
//!   one-sided 5 % ([`VUONG_Z`]).
//! * **Detected twins are ranked by one common size** ([`rank_twins`], P91): the members carrying
//!   either twin are refitted with each held at one size common to them all; the twin with the
//!   larger likelihood ratio of "a fraction of them carry it at that size" ([`mixture_lr`]) goes
//!   first, unless its size is the end of its range.
//!
//! Correction: every candidate effect of every tested group is one test, at level
//! [`GROUP_ALPHA`] / (effects × groups) (Bonferroni), so the chance of any false detection in a
//! run is at most [`GROUP_ALPHA`].
//!
//! Members whose base could not be fitted, whose own diagnosis found a wrong inventory record, or
//! whose misfit is far above the noise with no physical effect explaining it
//! ([`super::Diagnosis::unexplained`]: a wrong record, a unit or transcription error in the data)
//! do not contribute ([`member_scores`]). One such member has statistics in the hundreds
//! for every compliance or loss effect and would alone make the group "detected": the pooled
//! test is for an effect the members share, not for one broken member.

use std::collections::BTreeMap;

use super::stats::sum_chibar_sf;
use crate::invert::FitResult;
use crate::physics::effects::Effect;

/// Family-wise false-alarm rate of the pooled test over one run: over all candidate effects and
/// all tested groups (Bonferroni, see the module description). Strict because the gains of
/// pipe_loss on real cast-iron fits are somewhat over-dispersed against χ̄² (a clean group of 40
/// reached p = 1e-3).
pub const GROUP_ALPHA: f64 = 0.001;
/// What the pooled statistic sums (the `statistic_kind` column of `groups.csv`).
pub const STATISTIC_KIND: &str = "lr_gain_sum";
/// A member carries the group's effect when its gain for it is its largest among the effects
/// and above the χ̄² upper 5 % point (χ²₁ upper 10 % point, 2.7055).
pub const CARRY_GAIN: f64 = 2.705_543_454_095_404;
/// Smallest group the pooled test is run on (a group of one is the segment's own test).
pub const MIN_GROUP_SIZE: usize = 3;
/// Another detected effect is reported as indistinguishable from the best at group level unless
/// Vuong's statistic of the best over it exceeds this: the standard normal's upper 5 % point
/// (a one-sided test at 5 %).
pub const VUONG_Z: f64 = 1.644_853_626_951_472_2;
/// Pairs of effects that change the same quantity to first order (both add compliance to the
/// pipe–fluid system): where a member's diagnosis refitted one and not the other, the other is
/// refitted for the pooled test.
pub const TWINS: [(Effect, Effect); 1] = [(Effect::AirInWater, Effect::WallThinning)];
/// Pairs of effects whose members' gains can rank the wrong one first when both are detected:
/// the compliance twins (air P60, thinning P62 in P10: both slow the wave) and the loss twins
/// (soil damping, complex Lamé moduli of the soil, and the pipe wall's loss factor: both add
/// attenuation rising with frequency). They are ranked by a refit of the group with one common
/// magnitude ([`rank_twins`]).
pub const GROUP_TWINS: [(Effect, Effect); 2] = [
    (Effect::AirInWater, Effect::WallThinning),
    (Effect::SoilDamping, Effect::PipeLoss),
];
/// Multiples of the compared members' median own deviation at which the common deviation of a
/// twin is tried (steps of 2^¼ from ½ to 2 times it).
pub const COMMON_GRID: [f64; 9] = [
    0.5,
    0.594_603_557_501_360_5,
    std::f64::consts::FRAC_1_SQRT_2,
    0.840_896_415_253_714_5,
    1.0,
    1.189_207_115_002_721,
    std::f64::consts::SQRT_2,
    1.681_792_830_507_429,
    2.0,
];

/// How segments are grouped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GroupBy {
    /// Material × age class (30-year classes, `CI 1925-1954`): the default.
    #[default]
    MaterialAge,
    /// The inventory's `soil_zone`.
    SoilZone,
    /// The material.
    Material,
    /// The inventory's `soil_type`.
    SoilType,
    /// The decade of `install_year` (`1960s`).
    InstallDecade,
}

impl std::str::FromStr for GroupBy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "material_age" | "default" => Ok(GroupBy::MaterialAge),
            "soil_zone" => Ok(GroupBy::SoilZone),
            "material" => Ok(GroupBy::Material),
            "soil_type" => Ok(GroupBy::SoilType),
            "install_year" => Ok(GroupBy::InstallDecade),
            _ => Err(format!(
                "unknown group column '{s}' (expected soil_zone, material, soil_type or install_year)"
            )),
        }
    }
}

/// First year of the first age class, and the classes' width in years.
pub const AGE_CLASS_START: i64 = 1865;
/// Width of an age class, years.
pub const AGE_CLASS_YEARS: i64 = 30;

/// The age class of an install year: `1925-1954`.
pub fn age_class(year: i64) -> String {
    let k = (year - AGE_CLASS_START).div_euclid(AGE_CLASS_YEARS);
    let lo = AGE_CLASS_START + k * AGE_CLASS_YEARS;
    format!("{lo}-{}", lo + AGE_CLASS_YEARS - 1)
}

/// The group key of a segment for `by`, from its material code, install year, soil type and
/// soil zone; `None` when the column is empty for it.
pub fn group_key(
    by: GroupBy,
    material: &str,
    install_year: Option<i64>,
    soil_type: Option<&str>,
    soil_zone: Option<&str>,
) -> Option<String> {
    let text = |v: Option<&str>| v.map(str::trim).filter(|s| !s.is_empty()).map(String::from);
    match by {
        GroupBy::MaterialAge => Some(match install_year {
            Some(y) => format!("{material} {}", age_class(y)),
            None => format!("{material} age unknown"),
        }),
        GroupBy::Material => Some(material.to_string()),
        GroupBy::SoilType => text(soil_type),
        GroupBy::SoilZone => text(soil_zone),
        GroupBy::InstallDecade => install_year.map(|y| format!("{}s", y.div_euclid(10) * 10)),
    }
}

/// The pooled statistic of one effect over a group.
#[derive(Debug, Clone, PartialEq)]
pub struct PooledStatistic {
    /// The effect.
    pub effect: Effect,
    /// Σ of the members' likelihood-ratio gains, each less the member's shared part
    /// ([`less_shared`]).
    pub statistic: f64,
    /// Members that contributed.
    pub n: usize,
    /// Upper-tail probability under "no effect".
    pub p_value: f64,
}

/// The outcome of the pooled test over one group.
#[derive(Debug, Clone, PartialEq)]
pub struct GroupTest {
    /// The group's key.
    pub group: String,
    /// Indices of its members.
    pub members: Vec<usize>,
    /// Every effect's pooled statistic, most significant first.
    pub pooled: Vec<PooledStatistic>,
    /// The detected effect (None: no effect passed).
    pub effect: Option<Effect>,
    /// Other detected effects the group's data cannot tell apart from it (Vuong's statistic of
    /// the detected effect over them at most [`VUONG_Z`]).
    pub ambiguous_with: Vec<Effect>,
    /// Members refitted with the detected effect.
    pub n_refitted: usize,
    /// Members that carry the detected effect best: its gain is the member's largest and above
    /// [`CARRY_GAIN`] (empty when nothing was detected).
    pub carrying: Vec<usize>,
    /// Per-test level: [`GROUP_ALPHA`] / (effects × groups).
    pub level: f64,
    /// The group-level comparison of the detected effect with its twin, when both were
    /// detected ([`rank_twins`]).
    pub twins: Option<TwinComparison>,
}

/// The group-level comparison of two detected twins ([`GROUP_TWINS`]): each refitted on the
/// members that carry either, with one magnitude common to the fraction of them that carry it.
#[derive(Debug, Clone, PartialEq)]
pub struct TwinComparison {
    /// The twin ranked first (the larger group evidence).
    pub first: Effect,
    /// The other twin.
    pub second: Effect,
    /// The group-level evidence for `first`: the likelihood ratio of "a fraction of the
    /// compared members carry it at one common deviation" ([`common_mixture`]).
    pub first_gain: f64,
    /// The same for `second`.
    pub second_gain: f64,
    /// The fraction of the compared members carrying `first` at that likelihood ratio's
    /// maximum.
    pub first_fraction: f64,
    /// The same for `second`.
    pub second_fraction: f64,
    /// The common deviation of `first` from its neutral value at that maximum.
    pub first_deviation: f64,
    /// Members compared.
    pub members: usize,
}

impl GroupTest {
    /// The statistic of the detected effect (or the most significant one).
    pub fn statistic(&self) -> f64 {
        self.pooled.first().map(|p| p.statistic).unwrap_or(f64::NAN)
    }
    /// Its p-value (before the correction over effects).
    pub fn p_value(&self) -> f64 {
        self.pooled.first().map(|p| p.p_value).unwrap_or(f64::NAN)
    }
}

/// A member's contribution to the pooled test: its likelihood-ratio gain per effect (the refit's
/// χ² drop, clamped at 0; its score statistic where the effect was not refitted), or nothing
/// when its own diagnosis named a wrong inventory record or left a gross misfit unexplained
/// ([`super::Diagnosis::unexplained`], which includes a base that could not be fitted). Only
/// effects with a score (one nested parameter on its bound) enter: their gain is χ̄² under the
/// null.
pub fn member_scores(d: &super::Diagnosis) -> Vec<(Effect, f64)> {
    if d.unexplained() || d.named == Some(Effect::InventoryError) {
        return Vec::new();
    }
    d.candidates
        .iter()
        .filter(|c| c.score.is_finite())
        .map(|c| {
            let gain = c
                .refit
                .as_ref()
                .map(|r| r.lr)
                .filter(|g| g.is_finite())
                .unwrap_or(c.score);
            (c.effect, gain.max(0.0))
        })
        .collect()
}

/// A member's contribution to the pooled test as the adopted design makes it: its gains
/// ([`member_scores`]), with each effect of a [`TWINS`] pair that the member's diagnosis did not
/// refit, while it refitted the other, refitted here (the nested fit with the effect added to the
/// base model, started from the base optimum, [`super::extended_fit`]); its gain is
/// χ²(base) − χ²(extended), clamped at 0. A refit that fails keeps the score.
pub fn member_gains(
    d: &super::Diagnosis,
    settings: &super::DiagnoseSettings,
) -> Vec<(Effect, f64)> {
    member_gains_and_refits(d, settings).0
}

/// The twin refits [`member_gains_and_refits`] made for one member: (effect, fit).
pub type TwinRefits = Vec<(Effect, FitResult)>;

/// [`member_gains`] and the twin refits it made (effect, fit): the optimum from which
/// [`rank_twins`] profiles that twin for this member ([`DiagnosedMembers`]).
pub fn member_gains_and_refits(
    d: &super::Diagnosis,
    settings: &super::DiagnoseSettings,
) -> (Vec<(Effect, f64)>, TwinRefits) {
    let mut gains = member_scores(d);
    let mut fits = Vec::new();
    if gains.is_empty() || d.base_failed() {
        return (gains, fits);
    }
    let refitted = |e: Effect| d.refit_of(e).is_some_and(|r| r.lr.is_finite());
    let chi2_base = d.before.chi2();
    for (e, g) in gains.iter_mut() {
        let twin_refitted = TWINS
            .iter()
            .any(|&(a, b)| (a == *e && refitted(b)) || (b == *e && refitted(a)));
        if refitted(*e) || !twin_refitted {
            continue;
        }
        let mut effects = settings.base_effects.clone();
        effects.push(*e);
        effects.sort();
        effects.dedup();
        let fit = super::extended_fit(&d.data, settings, effects, &d.base);
        if fit.status == crate::types::FitStatus::Failed {
            continue;
        }
        let lr = chi2_base - super::Residuals::of(&d.data, &fit.predicted).chi2();
        if lr.is_finite() {
            *g = lr.max(0.0);
            fits.push((*e, fit));
        }
    }
    (gains, fits)
}

/// A member's gains less their smallest value over the candidate effects: the part every
/// candidate removes (a base that missed the soil optimum, a noise draw the base fits badly) is
/// evidence for none of them. A member with fewer than two finite gains keeps them as they are
/// (there is nothing to compare). Non-finite gains are kept and ignored by the sum.
pub fn less_shared(gains: &[(Effect, f64)]) -> Vec<(Effect, f64)> {
    let finite: Vec<f64> = gains
        .iter()
        .map(|p| p.1)
        .filter(|g| g.is_finite())
        .collect();
    let shared = if finite.len() >= 2 {
        finite
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
            .max(0.0)
    } else {
        0.0
    };
    gains
        .iter()
        .map(|&(e, g)| {
            (
                e,
                if g.is_finite() {
                    (g.max(0.0) - shared).max(0.0)
                } else {
                    g
                },
            )
        })
        .collect()
}

/// Member `i`'s likelihood-ratio gain for effect `e` in `scores`, when it has a finite one.
fn member_gain(scores: &[Vec<(Effect, f64)>], i: usize, e: Effect) -> Option<f64> {
    scores[i]
        .iter()
        .find(|p| p.0 == e)
        .map(|p| p.1)
        .filter(|g| g.is_finite())
}

/// Vuong's (1989) statistic of extension `a` over extension `b` of the members' base fits:
/// with d_i = g_a,i − g_b,i over the members that have both gains (twice the log-likelihood
/// ratio of the two non-nested fits of member i), z = Σ d_i / (√n ω̂), ω̂² = (1/n) Σ (d_i − d̄)².
/// Under "equally close to the truth" z is N(0, 1); a large positive z says `a` is closer.
/// +∞ when every member favours `a` by the same amount, 0 when there is no member to compare
/// or no difference at all.
pub fn vuong_z(a: Effect, b: Effect, members: &[usize], scores: &[Vec<(Effect, f64)>]) -> f64 {
    let gain = |i: usize, e: Effect| member_gain(scores, i, e);
    let d: Vec<f64> = members
        .iter()
        .filter_map(|&i| Some(gain(i, a)? - gain(i, b)?))
        .collect();
    if d.is_empty() {
        return 0.0;
    }
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let omega = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    if omega <= 1e-12 * mean.abs().max(1.0) {
        return if mean > 0.0 {
            f64::INFINITY
        } else if mean < 0.0 {
            f64::NEG_INFINITY
        } else {
            0.0
        };
    }
    n * mean / (n.sqrt() * omega)
}

/// The pooled test of one group tested alone (level [`GROUP_ALPHA`] over its effects).
/// `scores[i]` holds segment i's gains per candidate effect (NaN or absent: not available).
pub fn pooled_score_test(
    group: &str,
    members: &[usize],
    scores: &[Vec<(Effect, f64)>],
) -> GroupTest {
    pooled_test(group, members, scores, 1)
}

/// The pooled test of one group among `n_groups` tested: each effect's statistic is the sum of
/// the members' gains less their shared part ([`less_shared`]), tested at level
/// [`GROUP_ALPHA`] / (effects × `n_groups`); the detected effect is the most significant one, and
/// another detected effect is reported with it unless Vuong's test separates them ([`vuong_z`]).
/// `scores[i]` holds segment i's gains per candidate effect (as [`member_gains`] gives them).
pub fn pooled_test(
    group: &str,
    members: &[usize],
    scores: &[Vec<(Effect, f64)>],
    n_groups: usize,
) -> GroupTest {
    let mut sums: BTreeMap<Effect, (f64, usize)> = BTreeMap::new();
    for &i in members {
        for (e, s) in less_shared(&scores[i]) {
            if s.is_finite() {
                let v = sums.entry(e).or_default();
                v.0 += s.max(0.0);
                v.1 += 1;
            }
        }
    }
    let mut pooled: Vec<PooledStatistic> = sums
        .into_iter()
        .map(|(effect, (statistic, n))| PooledStatistic {
            effect,
            statistic,
            n,
            p_value: sum_chibar_sf(statistic, n),
        })
        .collect();
    pooled.sort_by(|a, b| {
        a.p_value
            .total_cmp(&b.p_value)
            .then(b.statistic.total_cmp(&a.statistic))
    });
    let level = GROUP_ALPHA / (pooled.len().max(1) * n_groups.max(1)) as f64;
    let detected: Vec<&PooledStatistic> = pooled.iter().filter(|p| p.p_value < level).collect();
    let effect = detected.first().map(|p| p.effect);
    let ambiguous_with = detected
        .iter()
        .skip(1)
        .filter(|p| vuong_z(detected[0].effect, p.effect, members, scores) <= VUONG_Z)
        .map(|p| p.effect)
        .collect();
    let carrying = effect
        .map(|e| carriers(members, scores, e))
        .unwrap_or_default();
    GroupTest {
        group: group.to_string(),
        members: members.to_vec(),
        pooled,
        effect,
        ambiguous_with,
        n_refitted: 0,
        carrying,
        level,
        twins: None,
    }
}

/// The twin of `e` in [`GROUP_TWINS`].
pub fn twin_of(e: Effect) -> Option<Effect> {
    GROUP_TWINS.iter().find_map(|&(a, b)| {
        if a == e {
            Some(b)
        } else if b == e {
            Some(a)
        } else {
            None
        }
    })
}

/// The value of `e`'s parameter at deviation `delta` ≥ 0 from its neutral value `neutral`,
/// towards the inside of its range (a thinner wall: the ratio below 1; more air, more loss: above
/// the neutral value). `None` outside the range.
pub fn value_at_deviation(e: Effect, neutral: f64, delta: f64) -> Option<f64> {
    let p = e.parameter()?;
    let v = if neutral >= p.upper {
        neutral - delta
    } else {
        neutral + delta
    };
    (v.is_finite() && v >= p.lower && v <= p.upper).then_some(v)
}

/// The likelihood ratio of P91, "a fraction π of the members carry the effect" against "none", from
/// the members' gains g_i = χ²_base,i − χ²_i (twice each member's log-likelihood ratio, so its
/// likelihood ratio is w_i = exp(g_i/2)): 2·max over π ∈ [0, 1] of Σ_i ln(1 − π + π·w_i), and
/// that π. Each member is a carrier with probability π, so a member the effect does not fit
/// (g_i ≪ 0) costs at most ln(1 − π) and not its whole χ² increase. The sum is concave in π;
/// its derivative Σ (w_i − 1)/(1 − π + π w_i) falls with π, and its root is found by bisection
/// (π = 1 when the derivative is still positive there, π = 0 when it is not positive at 0).
/// Non-finite gains are ignored; (0, 0) when there is none.
pub fn mixture_lr(gains: &[f64]) -> (f64, f64) {
    let g: Vec<f64> = gains.iter().copied().filter(|v| v.is_finite()).collect();
    // ln(1 − π + π e^x) and its derivative in π, without overflow for large x.
    let term = |x: f64, pi: f64| -> f64 {
        if x > 0.0 {
            x + (pi + (1.0 - pi) * (-x).exp()).ln()
        } else {
            (1.0 - pi + pi * x.exp()).ln()
        }
    };
    let slope = |pi: f64| -> f64 {
        g.iter()
            .map(|&v| {
                let x = 0.5 * v;
                if x > 0.0 {
                    let e = (-x).exp();
                    (1.0 - e) / (pi + (1.0 - pi) * e)
                } else {
                    (x.exp() - 1.0) / (1.0 - pi + pi * x.exp())
                }
            })
            .sum()
    };
    if g.is_empty() || slope(0.0) <= 0.0 {
        return (0.0, 0.0);
    }
    let pi = if slope(1.0) >= 0.0 {
        1.0
    } else {
        // The log-likelihood is concave in π: its slope falls through 0 once.
        let (lo, hi) = crate::optimize::bisect(0.0, 1.0, 60, |pi| slope(pi) > 0.0);
        0.5 * (lo + hi)
    };
    let lr = 2.0 * g.iter().map(|&v| term(0.5 * v, pi)).sum::<f64>();
    (lr.max(0.0), pi)
}

/// The group's evidence for an effect carried at one deviation common to a fraction of the
/// members: with `chi2_base[i]` member i's base χ² and `profiles[i][k]` its χ² with the
/// effect at the k-th common deviation, the largest [`mixture_lr`] of the gains
/// χ²_base,i − χ²_i,k over k, with that k and its fraction π. `None` when a profile lacks a
/// value or there is no member.
pub fn common_mixture(chi2_base: &[f64], profiles: &[Vec<f64>]) -> Option<(usize, f64, f64)> {
    let n_grid = profiles.first()?.len();
    if profiles
        .iter()
        .any(|p| p.len() != n_grid || p.iter().any(|v| !v.is_finite()))
        || chi2_base.len() != profiles.len()
        || chi2_base.iter().any(|c| !c.is_finite())
    {
        return None;
    }
    (0..n_grid)
        .map(|k| {
            let g: Vec<f64> = chi2_base
                .iter()
                .zip(profiles)
                .map(|(b, p)| b - p[k])
                .collect();
            let (lr, pi) = mixture_lr(&g);
            (k, lr, pi)
        })
        .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
}

/// What [`rank_twins_with`] needs to know of the members beyond their gains.
pub trait MemberProfile: Sync {
    /// Member i's base χ² (`None`: not available).
    fn chi2_base(&self, i: usize) -> Option<f64>;
    /// The neutral value of `e`'s parameter for member i (the pipe's own loss factor for
    /// pipe loss).
    fn neutral(&self, i: usize, e: Effect) -> Option<f64>;
    /// The deviation from the neutral value of member i's own refit of `e`, if it has one.
    fn own_deviation(&self, i: usize, e: Effect) -> Option<f64>;
    /// Member i's χ² with `e`'s parameter held at `value`, the others refitted.
    fn chi2_at(&self, i: usize, e: Effect, value: f64) -> Option<f64>;
}

/// The diagnosed members of a run: member i is `.0[i]`, and `.1[i]` (when present) holds the
/// twin refits [`member_gains_and_refits`] made for it. A member's profile along an effect starts
/// from its own refit with it: the diagnosis's, else that twin refit, else the base. Started
/// from the base, the profile of a twin the diagnosis did not refit falls short of the twin
/// refit's optimum by tens where the refit found another soil (a thinner wall needs a stiffer
/// soil), and that twin loses the comparison for it.
pub struct DiagnosedMembers<'a>(
    pub Vec<(&'a super::Diagnosis, &'a super::DiagnoseSettings)>,
    pub Vec<TwinRefits>,
);

impl DiagnosedMembers<'_> {
    /// Member i's refit with `e`: its diagnosis's, else the twin refit made for the pooled test.
    fn refit(&self, i: usize, e: Effect) -> Option<&FitResult> {
        let d = self.0.get(i)?.0;
        d.refit_of(e)
            .map(|r| &r.fit)
            .filter(|f| f.status != crate::types::FitStatus::Failed)
            .or_else(|| {
                self.1
                    .get(i)?
                    .iter()
                    .find(|(f, _)| *f == e)
                    .map(|(_, fit)| fit)
            })
    }
}

impl MemberProfile for DiagnosedMembers<'_> {
    fn chi2_base(&self, i: usize) -> Option<f64> {
        let d = self.0.get(i)?.0;
        (!d.base_failed())
            .then(|| d.before.chi2())
            .filter(|c| c.is_finite())
    }
    fn neutral(&self, i: usize, e: Effect) -> Option<f64> {
        e.neutral_value(self.0.get(i)?.0.base.system.as_ref()?)
    }
    fn own_deviation(&self, i: usize, e: Effect) -> Option<f64> {
        let neutral = self.neutral(i, e)?;
        let v = self
            .refit(i, e)?
            .estimates
            .iter()
            .find(|x| x.param == crate::invert::problem::Param::Effect(e))?
            .value;
        Some((v - neutral).abs()).filter(|d| d.is_finite())
    }
    fn chi2_at(&self, i: usize, e: Effect, value: f64) -> Option<f64> {
        let (d, s) = *self.0.get(i)?;
        super::chi2_with_effect_from(d, s, e, value, self.refit(i, e))
    }
}

/// Rank a detected effect and its detected twin ([`GROUP_TWINS`]) by the group's data at one
/// common magnitude. Each member's gain lets the twin's parameter take whatever value suits that
/// member, so a twin can mimic the other member by member and sum a larger gain. The group's
/// hypothesis is one effect at a similar size in part of its members: the compared members
/// (those whose larger gain of the two exceeds [`CARRY_GAIN`]) are refitted with each twin at a
/// deviation common to all of them, on [`COMMON_GRID`] around their median own deviation, and
/// the twin with the larger likelihood ratio of "a fraction of them carry it at one common
/// deviation" ([`common_mixture`]) is ranked first. How one deviation of either twin changes
/// the wave depends on each member's pipe, water pressure and soil (P60, P62 in P10),
/// differently for the two: a common size suits the true one across its carriers and not its
/// twin. Some compared members do not fit the common size: members that carry neither (a
/// noise draw above [`CARRY_GAIN`] for one twin), carriers whose own size is far from it, and
/// profile refits that stop short of the optimum far from the member's own. A plain sum of the
/// gains at the common size charges a twin each such member's whole χ² increase, tens to
/// hundreds in a few members and unequal between the twins (a lossier wall forced on members
/// without it costs them far more than soil damping does), and those few members then decide
/// the ranking. As a mixture, such a member costs either twin at most ln(1 − π). The other
/// detected effects and the level are unchanged; `ambiguous_with` and `carrying` follow the
/// effect ranked first.
pub fn rank_twins_with(
    test: &mut GroupTest,
    scores: &[Vec<(Effect, f64)>],
    fits: &impl MemberProfile,
) {
    use rayon::prelude::*;
    let Some(a) = test.effect else { return };
    let Some(b) = twin_of(a) else { return };
    let detected = |e: Effect| {
        test.pooled
            .iter()
            .any(|p| p.effect == e && p.p_value < test.level)
    };
    if !detected(b) {
        return;
    }
    let gain = |i: usize, e: Effect| member_gain(scores, i, e);
    let compared: Vec<usize> = test
        .members
        .iter()
        .copied()
        .filter(|&i| match (gain(i, a), gain(i, b)) {
            (Some(ga), Some(gb)) => ga.max(gb) > CARRY_GAIN && fits.chi2_base(i).is_some(),
            _ => false,
        })
        .collect();
    if compared.is_empty() {
        return;
    }
    let center = |e: Effect| {
        let mut d: Vec<f64> = compared
            .iter()
            .filter_map(|&i| fits.own_deviation(i, e))
            .filter(|d| *d > 0.0)
            .collect();
        d.sort_by(|x, y| x.total_cmp(y));
        (!d.is_empty()).then(|| d[d.len() / 2])
    };
    let (Some(ca), Some(cb)) = (center(a), center(b)) else {
        return;
    };
    // Per member, its χ² along each twin's grid (NaN where the value leaves the range or
    // the model gives no prediction).
    let profile = |i: usize, e: Effect, c: f64| -> Vec<f64> {
        COMMON_GRID
            .iter()
            .map(|m| {
                fits.neutral(i, e)
                    .and_then(|n| value_at_deviation(e, n, m * c))
                    .and_then(|v| fits.chi2_at(i, e, v))
                    .unwrap_or(f64::NAN)
            })
            .collect()
    };
    let rows: Vec<(usize, f64, Vec<f64>, Vec<f64>)> = compared
        .par_iter()
        .map(|&i| {
            (
                i,
                fits.chi2_base(i).unwrap_or(f64::NAN),
                profile(i, a, ca),
                profile(i, b, cb),
            )
        })
        .collect();
    // Both twins on the same members: those with every value of both profiles, after the
    // grid's columns that most members lack (values the range excludes) are dropped.
    let keep = |col: usize| -> Vec<usize> {
        (0..COMMON_GRID.len())
            .filter(|&k| {
                let have = rows
                    .iter()
                    .filter(|r| if col == 0 { r.2[k] } else { r.3[k] }.is_finite())
                    .count();
                2 * have >= rows.len()
            })
            .collect()
    };
    let (ka, kb) = (keep(0), keep(1));
    let rows: Vec<&(usize, f64, Vec<f64>, Vec<f64>)> = rows
        .iter()
        .filter(|r| {
            ka.iter().all(|&k| r.2[k].is_finite()) && kb.iter().all(|&k| r.3[k].is_finite())
        })
        .collect();
    let base: Vec<f64> = rows.iter().map(|r| r.1).collect();
    let pa: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| ka.iter().map(|&k| r.2[k]).collect())
        .collect();
    let pb: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| kb.iter().map(|&k| r.3[k]).collect())
        .collect();
    let (Some((ia, ga, fa)), Some((ib, gb, fb))) =
        (common_mixture(&base, &pa), common_mixture(&base, &pb))
    else {
        return;
    };
    // A twin whose best common size is the end of its range has its members pinned there by
    // the range, not by the data: one size suits them for no reason of theirs (soil damping at
    // its largest loss factor under an iron pipe, where the soil radiates and its loss is almost
    // invisible, mimics a lossier wall). The comparison is then not made: the member gains
    // rank the pair.
    let at_range_end = |e: Effect, k: usize, c: f64| {
        let (Some(p), Some(n)) = (e.parameter(), fits.neutral(rows[0].0, e)) else {
            return true;
        };
        value_at_deviation(e, n, c * COMMON_GRID[k]).is_none_or(|v| {
            let tol = 1e-9 * p.upper.abs().max(1.0);
            (v - p.upper).abs() <= tol || (v - p.lower).abs() <= tol
        })
    };
    if (gb > ga && at_range_end(b, kb[ib], cb)) || (gb <= ga && at_range_end(a, ka[ia], ca)) {
        return;
    }
    let (first, second, first_gain, second_gain, first_deviation, first_fraction, second_fraction) =
        if gb > ga {
            (b, a, gb, ga, cb * COMMON_GRID[kb[ib]], fb, fa)
        } else {
            (a, b, ga, gb, ca * COMMON_GRID[ka[ia]], fa, fb)
        };
    test.twins = Some(TwinComparison {
        first,
        second,
        first_gain,
        second_gain,
        first_fraction,
        second_fraction,
        first_deviation,
        members: rows.len(),
    });
    if first == a {
        return;
    }
    // The twin goes first; the rest keep their order.
    let at = test
        .pooled
        .iter()
        .position(|p| p.effect == b)
        .expect("the twin is detected");
    let moved = test.pooled.remove(at);
    test.pooled.insert(0, moved);
    test.effect = Some(b);
    let members = test.members.clone();
    test.ambiguous_with = test
        .pooled
        .iter()
        .skip(1)
        .filter(|p| p.p_value < test.level && vuong_z(b, p.effect, &members, scores) <= VUONG_Z)
        .map(|p| p.effect)
        .collect();
    test.carrying = carriers(&members, scores, b);
}

/// [`rank_twins_with`] for every group of a run, from the members' diagnoses.
pub fn rank_twins(
    groups: &mut [GroupTest],
    scores: &[Vec<(Effect, f64)>],
    fits: &DiagnosedMembers<'_>,
) {
    for g in groups.iter_mut() {
        rank_twins_with(g, scores, fits);
    }
}

/// The members whose gain for `e` is their largest and above [`CARRY_GAIN`].
fn carriers(members: &[usize], scores: &[Vec<(Effect, f64)>], e: Effect) -> Vec<usize> {
    members
        .iter()
        .copied()
        .filter(|&i| {
            let gain = |f: Effect| {
                scores[i]
                    .iter()
                    .find(|(g, s)| *g == f && s.is_finite())
                    .map(|p| p.1)
            };
            let Some(own) = gain(e) else { return false };
            own > CARRY_GAIN
                && scores[i]
                    .iter()
                    .filter(|(_, s)| s.is_finite())
                    .all(|&(_, s)| s <= own)
        })
        .collect()
}

/// Group the segments by key (segments without a key are in no group) and test every group of
/// at least [`MIN_GROUP_SIZE`] members.
pub fn test_groups(keys: &[Option<String>], scores: &[Vec<(Effect, f64)>]) -> Vec<GroupTest> {
    let mut by: BTreeMap<&str, Vec<usize>> = BTreeMap::new();
    for (i, k) in keys.iter().enumerate() {
        if let Some(k) = k {
            by.entry(k.as_str()).or_default().push(i);
        }
    }
    let tested: Vec<(&str, Vec<usize>)> = by
        .into_iter()
        .filter(|(_, m)| m.len() >= MIN_GROUP_SIZE)
        .collect();
    let n_groups = tested.len();
    tested
        .into_iter()
        .map(|(g, m)| pooled_test(g, &m, scores, n_groups))
        .collect()
}

#[cfg(test)]
mod tests;
