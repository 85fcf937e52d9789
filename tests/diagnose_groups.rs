//! Group detection: an effect hidden in 30 % of a 40-segment group of grey cast iron, at an
//! amplitude where the per-segment diagnosis rarely names it, is detected by the pooled test of
//! the members' gains; groups without an effect are not. The per-segment detection rate at this
//! amplitude and the rates over more seeds are measured by
//! `cargo run --release --example diagnose_acceptance -- groups`.

use pipewave::diagnose::group::{member_gains, member_scores, pooled_score_test, GroupTest};
use pipewave::diagnose::{diagnose_segment, DiagnoseSettings, Diagnosis};
use pipewave::physics::effects::Effect;
use pipewave::physics::Material;
use pipewave::synth::trial::effect_trial;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Amplitude of the hidden thinning: effective wall 0.86–0.93 of nominal (the per-segment
/// diagnosis names it for about a quarter of the affected members).
const RATIO: (f64, f64) = (0.86, 0.93);

/// The physical candidates (the inventory check is left out to keep the test fast; it only
/// matters for members with a wrong record).
fn settings() -> DiagnoseSettings {
    DiagnoseSettings {
        candidates: Effect::PHYSICAL.to_vec(),
        ..DiagnoseSettings::default()
    }
}

fn group(seed: u64, with_effect: bool) -> GroupTest {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let trials: Vec<_> = (0..40)
        .map(|i| {
            let hidden = (with_effect && i < 12)
                .then(|| (Effect::WallThinning, rng.gen_range(RATIO.0..RATIO.1)));
            loop {
                if let Some(t) = effect_trial(&mut rng, Material::CastIron, hidden) {
                    break t;
                }
            }
        })
        .collect();
    let settings = settings();
    let scores: Vec<Vec<(Effect, f64)>> = trials
        .par_iter()
        .map(|t| member_gains(&diagnose_segment(&t.data, None, &settings), &settings))
        .collect();
    let members: Vec<usize> = (0..40).collect();
    pooled_score_test("CI 1925-1954", &members, &scores)
}

#[test]
fn pooled_score_test_finds_a_hidden_group_effect_without_false_alarms() {
    let seeds = 4u64;
    let mut detected = 0;
    let mut false_alarms = 0;
    for s in 0..seeds {
        let g = group(1000 + s, true);
        eprintln!(
            "with effect, seed {s}: {:?} or {:?} (stat {:.1}, p {:.2e})",
            g.effect,
            g.ambiguous_with,
            g.statistic(),
            g.p_value()
        );
        // Thinning, or the set it is reported in (with air: both add compliance).
        if g.effect == Some(Effect::WallThinning)
            || g.ambiguous_with.contains(&Effect::WallThinning)
        {
            detected += 1;
        }
        let n = group(2000 + s, false);
        eprintln!(
            "without, seed {s}: {:?} (stat {:.1}, p {:.2e})",
            n.effect,
            n.statistic(),
            n.p_value()
        );
        if n.effect.is_some() {
            false_alarms += 1;
        }
    }
    // Targets: >= 80 % detected, <= 5 % false alarms; with 4 groups each: at least
    // 3 detected (one of these seeds names pipe_loss instead), none falsely. Without the pooled
    // test none would be: rates over 50 seeds by examples/diagnose_acceptance.rs.
    assert!(detected >= 3, "detected in {detected} of {seeds} groups");
    assert_eq!(
        false_alarms, 0,
        "{false_alarms} false alarms in {seeds} groups"
    );
}

/// Every score statistic of a member, as if nothing were left out.
fn all_scores(d: &Diagnosis) -> Vec<(Effect, f64)> {
    d.candidates
        .iter()
        .filter(|c| c.score.is_finite())
        .map(|c| (c.effect, c.score))
        .collect()
}

#[test]
fn one_broken_member_does_not_make_its_group_detected() {
    // 20 cast-iron members without an effect; in one of them a Re k value is 25 % low at one
    // frequency (a transcription error, as the sample network's WM10077). Nothing explains it,
    // and its compliance scores alone would make the group "detected".
    let mut rng = ChaCha8Rng::seed_from_u64(4242);
    let mut trials: Vec<_> = (0..20)
        .map(|_| loop {
            if let Some(t) = effect_trial(&mut rng, Material::CastIron, None) {
                break t;
            }
        })
        .collect();
    let m = &mut trials[0].data.measurements;
    let j = m.len() / 2;
    m[j].k_re *= 0.75;
    let settings = settings();
    let diags: Vec<Diagnosis> = trials
        .par_iter()
        .map(|t| diagnose_segment(&t.data, None, &settings))
        .collect();
    let broken = &diags[0];
    assert!(broken.structure.structured && broken.named.is_none());
    assert!(broken.unexplained());
    assert!(member_scores(broken).is_empty());
    // The healthy members are not left out.
    assert!(diags[1..].iter().all(|d| !d.unexplained()));
    let members: Vec<usize> = (0..20).collect();
    let raw: Vec<_> = diags.iter().map(all_scores).collect();
    let with_broken = pooled_score_test("CI", &members, &raw);
    assert!(
        with_broken.effect.is_some(),
        "the broken member alone should dominate the raw sum: {with_broken:?}"
    );
    let scores: Vec<_> = diags.iter().map(member_scores).collect();
    let t = pooled_score_test("CI", &members, &scores);
    assert_eq!(t.effect, None, "{t:?}");
    assert!(t.pooled.iter().all(|p| p.n == 19), "{:?}", t.pooled);
}
