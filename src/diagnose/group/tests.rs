//! Unit tests of the parent module.
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
    // 40 members: 12 with a gain of 4 for thinning (p 0.023 alone: below no per-segment
    // threshold after a correction) and 0 for pipe_loss; 28 with a gain of 1 for one of the
    // two effects and 0 for the other, by turns.
    let scores: Vec<Vec<(Effect, f64)>> = (0..40)
        .map(|i| {
            let (t, l) = if i < 12 {
                (4.0, 0.0)
            } else if i % 2 == 0 {
                (1.0, 0.0)
            } else {
                (0.0, 1.0)
            };
            vec![(Effect::WallThinning, t), (Effect::PipeLoss, l)]
        })
        .collect();
    let members: Vec<usize> = (0..40).collect();
    let t = pooled_score_test("CI 1925-1954", &members, &scores);
    assert_eq!(t.effect, Some(Effect::WallThinning));
    assert!((t.statistic() - 62.0).abs() < 1e-12);
    assert!((t.pooled[1].statistic - 14.0).abs() < 1e-12);
    assert!(t.p_value() < 1e-4, "{}", t.p_value());
    // The null alone: sum 20 over 40 members is the null's mean: nothing detected.
    let null: Vec<Vec<(Effect, f64)>> =
        (0..40).map(|_| vec![(Effect::WallThinning, 0.5)]).collect();
    assert_eq!(pooled_score_test("g", &members, &null).effect, None);
}

/// Signed standardised evidence of `n` members, `n_aff` of them carrying an effect at `delta`.
fn local_gains(rng: &mut rand_chacha::ChaCha8Rng, n: usize, n_aff: usize, delta: f64) -> Vec<f64> {
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

#[test]
fn the_part_every_candidate_removes_is_taken_off_each_member() {
    let g = vec![
        (Effect::SoilDamping, 6.0),
        (Effect::AirInWater, 9.5),
        (Effect::PipeLoss, 7.0),
        (Effect::WallThinning, f64::NAN),
    ];
    let r = less_shared(&g);
    assert_eq!(r[0], (Effect::SoilDamping, 0.0));
    assert_eq!(r[1], (Effect::AirInWater, 3.5));
    assert_eq!(r[2], (Effect::PipeLoss, 1.0));
    assert!(r[3].1.is_nan());
    // One finite gain: nothing to compare, kept.
    assert_eq!(
        less_shared(&[(Effect::PipeLoss, 5.0)]),
        vec![(Effect::PipeLoss, 5.0)]
    );
    // A clean group whose base fits all missed the soil optimum: every candidate removes
    // about 6 in every member. The raw sums (240 and more over 40 members) would detect
    // all four effects; less the shared part, none is detected.
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let effects = [
        Effect::SoilDamping,
        Effect::AirInWater,
        Effect::WallThinning,
        Effect::PipeLoss,
    ];
    let cols: Vec<Vec<f64>> = effects
        .iter()
        .map(|_| local_gains(&mut rng, 40, 0, 0.0))
        .collect();
    let scores: Vec<Vec<(Effect, f64)>> = (0..40)
        .map(|i| {
            effects
                .iter()
                .zip(&cols)
                .map(|(e, c)| (*e, 6.0 + c[i]))
                .collect()
        })
        .collect();
    let members: Vec<usize> = (0..40).collect();
    let t = pooled_test("g", &members, &scores, 1);
    assert_eq!(t.effect, None, "{:?}", t.pooled);
    assert!(sum_chibar_sf(40.0 * 6.0, 40) < 1e-30);
}

#[test]
fn vuong_separates_what_the_members_agree_on_and_not_a_coin_toss() {
    // Differences 1, 2, 3: mean 2, ω̂² = 2/3, z = 6/(√3·√(2/3)) = 3√2.
    let g = |a: f64, b: f64| vec![(Effect::WallThinning, a), (Effect::AirInWater, b)];
    let scores = vec![g(5.0, 4.0), g(6.0, 4.0), g(3.0, 0.0), g(1.0, f64::NAN)];
    let z = vuong_z(
        Effect::WallThinning,
        Effect::AirInWater,
        &[0, 1, 2, 3],
        &scores,
    );
    assert!((z - 3.0 * 2f64.sqrt()).abs() < 1e-12, "{z}");
    let back = vuong_z(
        Effect::AirInWater,
        Effect::WallThinning,
        &[0, 1, 2, 3],
        &scores,
    );
    assert!((back + z).abs() < 1e-12);
    // Equal gains throughout: no difference, z = 0; the same difference everywhere: +∞.
    let same = vec![g(4.0, 4.0), g(2.0, 2.0)];
    assert_eq!(
        vuong_z(Effect::WallThinning, Effect::AirInWater, &[0, 1], &same),
        0.0
    );
    let shifted = vec![g(5.0, 4.0), g(3.0, 2.0)];
    assert_eq!(
        vuong_z(Effect::WallThinning, Effect::AirInWater, &[0, 1], &shifted),
        f64::INFINITY
    );
    // In a group: 12 of 40 members carry thinning with gain 16 and air 9 (twins: air takes
    // up part of it); the others are clean. Both are detected; thinning is better in every
    // carrier, so air is not reported with it.
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let noise = local_gains(&mut rng, 40, 0, 0.0);
    let twin = |i: usize, t: f64, a: f64| {
        vec![
            (Effect::WallThinning, t),
            (Effect::AirInWater, a),
            (Effect::PipeLoss, if i < 12 { 0.0 } else { noise[i] }),
        ]
    };
    let members: Vec<usize> = (0..40).collect();
    let clear: Vec<_> = (0..40)
        .map(|i| {
            if i < 12 {
                twin(i, 16.0 + (i % 3) as f64, 9.0)
            } else {
                twin(i, 0.0, 0.0)
            }
        })
        .collect();
    let t = pooled_test("g", &members, &clear, 1);
    assert_eq!(t.effect, Some(Effect::WallThinning));
    assert!(t.pooled[1].p_value < t.level, "{:?}", t.pooled);
    assert!(t.ambiguous_with.is_empty(), "{:?}", t.ambiguous_with);
    // The members disagree (half favour air by as much as the others favour thinning):
    // thinning still sums higher, but the data cannot tell them apart.
    let mixed: Vec<_> = (0..40)
        .map(|i| match i {
            0..=5 => twin(i, 16.0 + (i % 3) as f64, 9.0),
            6..=11 => twin(i, 9.0, 14.0 + (i % 3) as f64),
            _ => twin(i, 0.0, 0.0),
        })
        .collect();
    let t = pooled_test("g", &members, &mixed, 1);
    assert_eq!(t.effect, Some(Effect::WallThinning));
    assert_eq!(t.ambiguous_with, vec![Effect::AirInWater]);
}

/// Members whose χ² with each twin at a deviation δ is base − s·(1 − (δ/r − 1)²): the own
/// gain s at the own deviation r, falling quadratically away from it.
struct Quadratic {
    /// Per member and twin: (s, r).
    curves: Vec<BTreeMap<Effect, (f64, f64)>>,
}

impl MemberProfile for Quadratic {
    fn chi2_base(&self, i: usize) -> Option<f64> {
        self.curves.get(i).map(|_| 100.0)
    }
    fn neutral(&self, _: usize, e: Effect) -> Option<f64> {
        // A pipe's own loss factor: an iron pipe's typical 0.01.
        e.parameter().map(|p| {
            if e == Effect::PipeLoss {
                0.01
            } else {
                p.neutral
            }
        })
    }
    fn own_deviation(&self, i: usize, e: Effect) -> Option<f64> {
        self.curves[i].get(&e).map(|c| c.1)
    }
    fn chi2_at(&self, i: usize, e: Effect, value: f64) -> Option<f64> {
        let (s, r) = *self.curves[i].get(&e)?;
        let delta = (value - self.neutral(i, e)?).abs();
        Some(100.0 - s * (1.0 - (delta / r - 1.0).powi(2)))
    }
}

#[test]
fn one_common_size_ranks_the_twin_that_needs_it_first() {
    // 12 of 40 members carry thinning at one deviation, 0.12, with own gains 8–19; each
    // gains 10 % more from air, but at air fractions spread over a factor 8 from member to
    // member (as a twin that mimics the other member by member must). The member gains rank
    // air first; one common size costs air a great deal and thinning nothing, so thinning
    // goes first. The other 28 members are clean.
    let (t, a) = (Effect::WallThinning, Effect::AirInWater);
    let members: Vec<usize> = (0..40).collect();
    let carriers = |spread: bool| -> Quadratic {
        Quadratic {
            curves: (0..40)
                .map(|i| {
                    let s = 8.0 + i as f64;
                    let r_air = if spread {
                        2e-6 * 2f64.powf((i % 4) as f64)
                    } else {
                        5e-6
                    };
                    BTreeMap::from([(t, (s, 0.12)), (a, (1.1 * s, r_air))])
                })
                .collect(),
        }
    };
    let scores = |q: &Quadratic| -> Vec<Vec<(Effect, f64)>> {
        (0..40)
            .map(|i| {
                let p = (Effect::PipeLoss, 0.0);
                if i < 12 {
                    vec![(t, q.curves[i][&t].0), (a, q.curves[i][&a].0), p]
                } else {
                    vec![(t, 0.0), (a, 0.0), p]
                }
            })
            .collect()
    };
    let q = carriers(true);
    let sc = scores(&q);
    let mut g = pooled_test("CI", &members, &sc, 1);
    assert_eq!(g.effect, Some(a), "{:?}", g.pooled);
    assert!(g.pooled[1].p_value < g.level);
    rank_twins_with(&mut g, &sc, &q);
    assert_eq!(g.effect, Some(t), "{:?}", g.twins);
    assert_eq!(g.pooled[0].effect, t);
    let c = g.twins.as_ref().expect("compared");
    assert_eq!(c.members, 12);
    // One size at the grid point on thinning's own deviation fits every carrier: all of
    // them carry it, and the likelihood ratio is the sum of their gains, 8 + … + 19.
    assert!((c.first_gain - 162.0).abs() < 1e-9, "{c:?}");
    assert_eq!(c.first_fraction, 1.0);
    assert!((c.first_deviation - 0.12).abs() < 1e-12);
    // Air at one size fits each member only as well as its own size is near it.
    assert!(c.second_gain < 0.7 * c.first_gain, "{c:?}");
    // Air at one size for every member: nothing to choose against the member gains, air
    // stays first.
    let q = carriers(false);
    let sc = scores(&q);
    let mut g = pooled_test("CI", &members, &sc, 1);
    rank_twins_with(&mut g, &sc, &q);
    assert_eq!(g.effect, Some(a), "{:?}", g.twins);
    assert_eq!(g.twins.as_ref().map(|c| c.first), Some(a));
}

#[test]
fn the_mixture_likelihood_ratio_takes_the_fraction_that_carries_the_effect() {
    // Every gain positive: every member carries it, the ratio is the sum of the gains.
    let (lr, pi) = mixture_lr(&[4.0, 9.0, 2.5]);
    assert!((lr - 15.5).abs() < 1e-12, "{lr}");
    assert_eq!(pi, 1.0);
    // Nothing positive: nothing carried.
    assert_eq!(mixture_lr(&[-3.0, 0.0, -0.5]), (0.0, 0.0));
    assert_eq!(mixture_lr(&[]), (0.0, 0.0));
    // Two members with w = e⁵ and two the effect does not fit at all (w ≈ 0): the
    // derivative 2(w − 1)/(1 − π + πw) − 2/(1 − π) vanishes at π = (w − 2)/(2w − 2), and a
    // member that does not fit costs ln(1 − π), not its χ² increase of 200.
    let w = 5f64.exp();
    let (lr, pi) = mixture_lr(&[10.0, 10.0, -200.0, -200.0, f64::NAN]);
    let want_pi = (w - 2.0) / (2.0 * w - 2.0);
    assert!((pi - want_pi).abs() < 1e-12, "{pi} vs {want_pi}");
    let want = 4.0 * (1.0 - want_pi + want_pi * w).ln() + 4.0 * (1.0 - want_pi).ln();
    assert!((lr - want).abs() < 1e-9, "{lr} vs {want}");
    // Huge gains do not overflow: one member of two carries it, π near ½.
    let (lr, pi) = mixture_lr(&[3000.0, -10.0]);
    assert!(
        lr.is_finite() && lr > 2990.0 && (pi - 0.5).abs() < 0.01,
        "{lr} {pi}"
    );
}

#[test]
fn members_the_common_size_does_not_fit_cost_a_twin_at_most_their_share() {
    // Pipe loss in 12 of 40 members at one deviation, 0.02 above the pipe's own loss
    // factor, own gains 8–19; soil damping mimics it in each at one loss factor, 0.1, with
    // 0.85 of the gain. Three clean members pass the comparison's threshold by a noise draw
    // (gain 3 for both twins); a lossier wall at the carriers' size is far from what they
    // need and raises their χ² by 24 each, soil damping at its common size by nothing. A
    // plain sum of the gains at the common size would rank soil damping first
    // (0.85·162 = 137.7 against 162 − 72 = 90); the mixture charges the three members
    // ln(1 − π) and keeps pipe loss first, carried by 12 of the 15 compared members.
    let (sd, pl) = (Effect::SoilDamping, Effect::PipeLoss);
    let q = Quadratic {
        curves: (0..40)
            .map(|i| {
                let s = 8.0 + i as f64;
                if i < 12 {
                    BTreeMap::from([(pl, (s, 0.02)), (sd, (0.85 * s, 0.1))])
                } else {
                    BTreeMap::from([(pl, (3.0, 0.005)), (sd, (3.0, 0.05))])
                }
            })
            .collect(),
    };
    let sc: Vec<Vec<(Effect, f64)>> = (0..40)
        .map(|i| {
            let w = (Effect::AirInWater, 0.0);
            match i {
                0..=11 => vec![(sd, q.curves[i][&sd].0), (pl, q.curves[i][&pl].0), w],
                12..=14 => vec![(sd, 3.0), (pl, 3.0), w],
                _ => vec![(sd, 0.0), (pl, 0.0), w],
            }
        })
        .collect();
    let members: Vec<usize> = (0..40).collect();
    let mut g = pooled_test("CI", &members, &sc, 1);
    assert_eq!(g.effect, Some(pl), "{:?}", g.pooled);
    assert!(g.pooled[1].p_value < g.level, "{:?}", g.pooled);
    // The plain sum over the 15 compared members at each twin's best common size.
    let plain = |e: Effect, value: f64| -> f64 {
        (0..15)
            .map(|i| 100.0 - q.chi2_at(i, e, value).expect("inside the range"))
            .sum()
    };
    assert!((plain(pl, 0.03) - 90.0).abs() < 1e-9);
    assert!((plain(sd, 0.1) - 0.85 * 162.0).abs() < 1e-9);
    rank_twins_with(&mut g, &sc, &q);
    assert_eq!(g.effect, Some(pl));
    let c = g.twins.as_ref().expect("compared");
    assert_eq!((c.first, c.members), (pl, 15));
    assert!((c.first_deviation - 0.02).abs() < 1e-12, "{c:?}");
    assert!((c.first_fraction - 0.8).abs() < 0.02, "{c:?}");
    assert_eq!(c.second_fraction, 1.0);
    assert!(c.second_gain >= 0.85 * 162.0 - 1e-9, "{c:?}");
    assert!(c.first_gain > c.second_gain + 5.0, "{c:?}");
}

#[test]
fn a_twin_pinned_at_its_range_end_does_not_win_by_one_common_size() {
    // Pipe loss in 12 of 40 members at sizes spread over a factor 8 (gains 1.1·s); soil
    // damping gains s in each, every member at 0.3, the end of its range. One size costs
    // soil damping nothing only because the range pins it: the member gains keep pipe loss
    // first and no comparison is reported.
    let (sd, pl) = (Effect::SoilDamping, Effect::PipeLoss);
    let q = Quadratic {
        curves: (0..40)
            .map(|i| {
                let s = 8.0 + i as f64;
                let r = 0.004 * 2f64.powf((i % 4) as f64);
                BTreeMap::from([(sd, (s, 0.3)), (pl, (1.1 * s, r))])
            })
            .collect(),
    };
    let sc: Vec<Vec<(Effect, f64)>> = (0..40)
        .map(|i| {
            let w = (Effect::AirInWater, 0.0);
            if i < 12 {
                vec![(sd, q.curves[i][&sd].0), (pl, q.curves[i][&pl].0), w]
            } else {
                vec![(sd, 0.0), (pl, 0.0), w]
            }
        })
        .collect();
    let members: Vec<usize> = (0..40).collect();
    let mut g = pooled_test("CI", &members, &sc, 1);
    assert_eq!(g.effect, Some(pl));
    assert!(g.pooled[1].p_value < g.level, "{:?}", g.pooled);
    rank_twins_with(&mut g, &sc, &q);
    assert_eq!(g.effect, Some(pl));
    assert_eq!(g.twins, None);
    assert_eq!(value_at_deviation(sd, 0.0, 0.3), Some(0.3));
    assert_eq!(value_at_deviation(sd, 0.0, 0.31), None);
    assert_eq!(
        value_at_deviation(Effect::WallThinning, 1.0, 0.2),
        Some(0.8)
    );
}

#[test]
fn removing_the_shared_part_keeps_the_null_below_its_level() {
    // 20 000 clean groups of 40 members with four independent candidates each: the p-value
    // of the statistic less the shared part is never below the raw one, and the share of
    // groups whose best effect falls below 0.05/4 stays below 0.05 (raw: about 0.05; 4
    // binomial standard errors of margin).
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
    let effects = [
        Effect::SoilDamping,
        Effect::AirInWater,
        Effect::WallThinning,
        Effect::PipeLoss,
    ];
    let members: Vec<usize> = (0..40).collect();
    let reps = 20_000;
    let (mut raw_hits, mut hits) = (0, 0);
    for _ in 0..reps {
        let cols: Vec<Vec<f64>> = effects
            .iter()
            .map(|_| local_gains(&mut rng, 40, 0, 0.0))
            .collect();
        let scores: Vec<Vec<(Effect, f64)>> = (0..40)
            .map(|i| effects.iter().zip(&cols).map(|(e, c)| (*e, c[i])).collect())
            .collect();
        let t = pooled_test("g", &members, &scores, 1);
        let raw_p = cols
            .iter()
            .map(|c| sum_chibar_sf(c.iter().sum(), 40))
            .fold(1.0, f64::min);
        assert!(t.p_value() >= raw_p - 1e-15, "{} < {raw_p}", t.p_value());
        raw_hits += (raw_p < 0.05 / 4.0) as usize;
        hits += (t.p_value() < 0.05 / 4.0) as usize;
    }
    let rate = |h: usize| h as f64 / reps as f64;
    assert!(
        (rate(raw_hits) - 0.049).abs() < 0.006,
        "raw {}",
        rate(raw_hits)
    );
    assert!(rate(hits) < 0.05, "{}", rate(hits));
}
