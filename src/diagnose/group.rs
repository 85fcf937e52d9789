//! Group detection: an effect present in many members of a group (air in a pressure
//! zone, thinning of old cast iron) can be below the per-segment threshold in each one. The
//! pooled score test adds the members' one-sided score statistics: under "no effect in any
//! member" each is χ̄² = ½χ²₀ + ½χ²₁ (the parameter on its bound), so their sum over n members
//! has the binomial mixture Σ_k C(n,k)2⁻ⁿχ²_k ([`super::stats::sum_chibar_sf`]). Testing every
//! candidate effect of a group at level [`GROUP_ALPHA`] with a Bonferroni correction over the
//! effects keeps the group's false-alarm rate at or below [`GROUP_ALPHA`].
//!
//! Members whose base could not be fitted, whose own diagnosis found a wrong inventory record, or
//! whose misfit is far above the noise with no physical effect explaining it
//! ([`super::Diagnosis::unexplained`]: a wrong record, a unit or transcription error in the data)
//! do not contribute ([`member_scores`]). One such member has score statistics in the hundreds
//! for every compliance or loss effect and would alone make the group "detected": the pooled
//! test is for an effect the members share, not for one broken member.
//!
//! Measured calibration (tests/diagnose_groups.rs, `examples/diagnose_acceptance.rs groups`):
//! on cast-iron groups without an effect the members' scores are somewhat over-dispersed
//! against χ̄² (one null group of five reached p = 5e-4 for pipe_loss), hence the strict
//! [`GROUP_ALPHA`].

use std::collections::BTreeMap;

use super::stats::sum_chibar_sf;
use crate::physics::effects::Effect;

/// False-alarm rate of the pooled test per group (over all candidate effects), set strict
/// because the scores are over-dispersed on real fits (see the module description).
pub const GROUP_ALPHA: f64 = 0.001;
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
    /// Σ of the members' score statistics.
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

/// A member's contribution to the pooled test: its score statistics per effect, or nothing when
/// its own diagnosis named a wrong inventory record or left a gross misfit unexplained
/// ([`super::Diagnosis::unexplained`], which includes a base that could not be fitted).
pub fn member_scores(d: &super::Diagnosis) -> Vec<(Effect, f64)> {
    if d.unexplained() || d.named == Some(Effect::InventoryError) {
        return Vec::new();
    }
    d.candidates
        .iter()
        .filter(|c| c.score.is_finite())
        .map(|c| (c.effect, c.score))
        .collect()
}

/// The pooled score test of one group. `scores[i]` holds segment i's score statistics per
/// candidate effect (NaN or absent: not available for that segment).
pub fn pooled_score_test(
    group: &str,
    members: &[usize],
    scores: &[Vec<(Effect, f64)>],
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
    let level = GROUP_ALPHA / pooled.len().max(1) as f64;
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
    GroupTest {
        group: group.to_string(),
        members: members.to_vec(),
        pooled,
        effect,
        ambiguous_with,
        n_refitted: 0,
    }
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
    by.into_iter()
        .filter(|(_, m)| m.len() >= MIN_GROUP_SIZE)
        .map(|(g, m)| pooled_score_test(g, &m, scores))
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
}
