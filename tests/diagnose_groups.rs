//! Group detection (issue 13): an effect hidden in 30 % of a 40-segment group of grey cast
//! iron, at an amplitude where the per-segment diagnosis rarely names it, is detected by the
//! pooled score test; groups without an effect are not. The per-segment detection rate at this
//! amplitude and the rates over more seeds are measured by
//! `cargo run --release --example diagnose_acceptance -- groups`.

use pipewave::diagnose::group::{member_scores, pooled_score_test, GroupTest};
use pipewave::diagnose::trial::effect_trial;
use pipewave::diagnose::{prepare, score_candidates, DiagnoseSettings};
use pipewave::physics::effects::Effect;
use pipewave::physics::Material;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Amplitude of the hidden thinning: effective wall 0.80–0.90 of nominal.
const RATIO: (f64, f64) = (0.80, 0.90);

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
    let settings = DiagnoseSettings::default();
    let scores: Vec<Vec<(Effect, f64)>> = trials
        .par_iter()
        .map(|t| {
            let d = prepare(&t.data, None, &settings);
            let mut d = d;
            d.candidates = score_candidates(&d, &settings);
            member_scores(&d)
        })
        .collect();
    let members: Vec<usize> = (0..40).collect();
    pooled_score_test("CI 1925-1954", &members, &scores)
}

#[test]
fn pooled_score_test_finds_a_hidden_group_effect_without_false_alarms() {
    let seeds = 3u64;
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
    // Targets (issue 13): >= 80 % detected, <= 5 % false alarms; with 3 groups each: all
    // detected, none falsely. More seeds: examples/diagnose_acceptance.rs.
    assert_eq!(detected, seeds, "detected in {detected} of {seeds} groups");
    assert_eq!(
        false_alarms, 0,
        "{false_alarms} false alarms in {seeds} groups"
    );
}
