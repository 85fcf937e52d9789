//! Group detection: an effect present in many members of a group (air in a pressure
//! zone, thinning of old cast iron) can be below the per-segment threshold in each one. The
//! pooled test adds the members' likelihood-ratio gains for each candidate effect: the χ² the
//! member's refit with the effect removes (χ²(base) − χ²(extended), clamped at 0), or its score
//! statistic where the effect was not refitted (the data pulled its parameter out of its allowed
//! range: the gain is then 0 to first order). Each gain tests one parameter on the bound of its
//! range, so under "no effect in any member" it is χ̄² = ½χ²₀ + ½χ²₁ (Self & Liang 1987), and
//! the sum over n independent members has the binomial mixture Σ_k C(n,k)2⁻ⁿχ²_k
//! ([`super::stats::sum_chibar_sf`]).
//!
//! Why gains, not scores: the score is the first-order view at the base fit. In the local model
//! (Z_i the standardised efficient score of member i) score and gain coincide, and the sum of
//! χ̄² statistics is as powerful as a mixture likelihood ratio for an effect carried by a
//! fraction of the members, and much more powerful than a pooled one-direction score near the
//! one-segment floor (`examples/group_power.rs`, docs/group-test.md). On real fits the base has
//! already bent its soil parameters towards the effect, and the score captures only part of
//! what the refit removes; summing scores then loses most of the power.
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
/// Another significant effect whose pooled statistic is at least this fraction of the best's,
/// or that changes the same physical quantity (compliance, loss), is reported as
/// indistinguishable at group level.
pub const GROUP_TIE_RATIO: f64 = 0.6;

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
    /// Σ of the members' likelihood-ratio gains.
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
    /// Other detected effects the group's data cannot tell apart from it.
    pub ambiguous_with: Vec<Effect>,
    /// Members refitted with the detected effect.
    pub n_refitted: usize,
    /// Members that carry the detected effect best: its gain is the member's largest and above
    /// [`CARRY_GAIN`] (empty when nothing was detected).
    pub carrying: Vec<usize>,
    /// Per-test level: [`GROUP_ALPHA`] / (effects × groups).
    pub level: f64,
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

/// The pooled test of one group tested alone (level [`GROUP_ALPHA`] over its effects).
/// `scores[i]` holds segment i's gains per candidate effect (NaN or absent: not available).
pub fn pooled_score_test(
    group: &str,
    members: &[usize],
    scores: &[Vec<(Effect, f64)>],
) -> GroupTest {
    pooled_test(group, members, scores, 1)
}

/// The pooled test of one group among `n_groups` tested: each effect at level
/// [`GROUP_ALPHA`] / (effects × `n_groups`).
pub fn pooled_test(
    group: &str,
    members: &[usize],
    scores: &[Vec<(Effect, f64)>],
    n_groups: usize,
) -> GroupTest {
    let mut sums: BTreeMap<Effect, (f64, usize)> = BTreeMap::new();
    for &i in members {
        for &(e, s) in &scores[i] {
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
        .filter(|p| {
            p.statistic >= GROUP_TIE_RATIO * detected[0].statistic
                || super::ambiguity::same_quantity(p.effect, detected[0].effect)
        })
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
mod tests {
    use super::*;

    #[test]
    fn keys_and_age_classes() {
        assert_eq!(age_class(1925), "1925-1954");
        assert_eq!(age_class(1954), "1925-1954");
        assert_eq!(age_class(1860), "1835-1864");
        assert_eq!(
            group_key(GroupBy::MaterialAge, "CI", Some(1930), None, None).as_deref(),
            Some("CI 1925-1954")
        );
        assert_eq!(
            group_key(GroupBy::InstallDecade, "CI", Some(1967), None, None).as_deref(),
            Some("1960s")
        );
        assert_eq!(
            group_key(GroupBy::SoilZone, "CI", None, None, Some(" ")),
            None
        );
        assert!("zone".parse::<GroupBy>().is_err());
    }

    #[test]
    fn many_small_scores_detect_what_none_does_alone() {
        // 40 members: 12 with a score of 4 (p 0.023 alone: below no per-segment threshold
        // after a correction), 28 with the null's mean 0.5.
        let scores: Vec<Vec<(Effect, f64)>> = (0..40)
            .map(|i| {
                let s = if i < 12 { 4.0 } else { 0.5 };
                vec![(Effect::WallThinning, s), (Effect::PipeLoss, 0.5)]
            })
            .collect();
        let members: Vec<usize> = (0..40).collect();
        let t = pooled_score_test("CI 1925-1954", &members, &scores);
        assert_eq!(t.effect, Some(Effect::WallThinning));
        assert!((t.statistic() - 62.0).abs() < 1e-12);
        assert!(t.p_value() < 1e-4, "{}", t.p_value());
        // The null alone: sum 20 over 40 members is the null's mean: nothing detected.
        let null: Vec<Vec<(Effect, f64)>> =
            (0..40).map(|_| vec![(Effect::WallThinning, 0.5)]).collect();
        assert_eq!(pooled_score_test("g", &members, &null).effect, None);
    }

    /// Signed standardised evidence of `n` members, `n_aff` of them carrying an effect at `delta`.
    fn local_gains(
        rng: &mut rand_chacha::ChaCha8Rng,
        n: usize,
        n_aff: usize,
        delta: f64,
    ) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let z = crate::stats::normal(rng) + if i < n_aff { delta } else { 0.0 };
                z.max(0.0).powi(2)
            })
            .collect()
    }

    #[test]
    fn null_of_the_gain_sum_matches_the_mixture_formula() {
        // 20 000 clean groups of 40 members in the local model (each gain max(0, Z)², Z ~ N(0,1)):
        // the simulated tail against Σ_k C(40,k)2⁻⁴⁰χ²_k at 0.46, 0.089 and 0.009. Binomial
        // standard errors: 0.0035, 0.0020, 0.00067; the bounds are 4 of them.
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let reps = 20_000;
        let sums: Vec<f64> = (0..reps)
            .map(|_| local_gains(&mut rng, 40, 0, 0.0).iter().sum())
            .collect();
        for (x, tol) in [(20.0, 0.014), (30.0, 0.008), (40.0, 0.0027)] {
            let sim = sums.iter().filter(|s| **s > x).count() as f64 / reps as f64;
            let formula = sum_chibar_sf(x, 40);
            assert!(
                (sim - formula).abs() < tol,
                "x {x}: simulated {sim}, formula {formula}"
            );
        }
        // Under the null the test rejects at about its level over 4 effects and 1 group.
        let level = GROUP_ALPHA / 4.0;
        let rejected = sums
            .iter()
            .filter(|s| sum_chibar_sf(**s, 40) < level)
            .count();
        assert!(
            rejected <= 3 * (level * reps as f64) as usize + 5,
            "{rejected}"
        );
    }

    #[test]
    fn gains_at_the_one_segment_floor_detect_the_group_and_rank_the_effect_first() {
        // The one-segment floor: one member's χ̄² test at the diagnosis's α over 4 effects has
        // 50 % power when its z mean is z with P(Z > z) = 2.5e-4: 3.48. 30 % of 40 members
        // carry thinning there; the other effects are clean. 200 groups, 8 tested per run.
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let members: Vec<usize> = (0..40).collect();
        let (mut hits, mut false_alarms) = (0, 0);
        for _ in 0..200 {
            let t = local_gains(&mut rng, 40, 12, 3.48);
            let l = local_gains(&mut rng, 40, 0, 0.0);
            let a = local_gains(&mut rng, 40, 0, 0.0);
            let scores: Vec<Vec<(Effect, f64)>> = (0..40)
                .map(|i| {
                    vec![
                        (Effect::WallThinning, t[i]),
                        (Effect::PipeLoss, l[i]),
                        (Effect::AirInWater, a[i]),
                    ]
                })
                .collect();
            let g = pooled_test("CI", &members, &scores, 8);
            hits += (g.effect == Some(Effect::WallThinning)) as usize;
            false_alarms += g.ambiguous_with.len();
            assert!((g.level - GROUP_ALPHA / 24.0).abs() < 1e-15);
            if g.effect.is_some() {
                // Those carrying it are mostly the 12 affected members.
                let true_carriers = g.carrying.iter().filter(|&&i| i < 12).count();
                assert!(
                    true_carriers * 10 >= g.carrying.len() * 6,
                    "{:?}",
                    g.carrying
                );
            }
        }
        assert!(hits >= 196, "detected {hits} of 200");
        assert!(false_alarms <= 2, "{false_alarms}");
    }

    #[test]
    fn the_level_is_corrected_over_effects_and_groups() {
        // Groups of 5: the same statistic passes alone and fails when 100 groups are tested.
        let scores: Vec<Vec<(Effect, f64)>> =
            (0..5).map(|_| vec![(Effect::WallThinning, 4.0)]).collect();
        let members: Vec<usize> = (0..5).collect();
        let p = sum_chibar_sf(20.0, 5);
        assert!(p < GROUP_ALPHA && p > GROUP_ALPHA / 100.0, "{p}");
        assert!(pooled_test("g", &members, &scores, 1).effect.is_some());
        assert!(pooled_test("g", &members, &scores, 100).effect.is_none());
        let keys: Vec<Option<String>> = (0..10)
            .map(|i| Some(if i < 5 { "a" } else { "b" }.to_string()))
            .collect();
        let mut all = scores.clone();
        all.extend(scores.clone());
        let groups = test_groups(&keys, &all);
        assert_eq!(groups.len(), 2);
        assert!(groups
            .iter()
            .all(|g| (g.level - GROUP_ALPHA / 2.0).abs() < 1e-15));
    }
}
