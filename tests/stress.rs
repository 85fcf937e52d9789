//! Synthetic stress (issue 11): every segment with measurements gets a fit. A network of
//! 400 segments, all materials and wall classes (thin plastic pipes included), each effect of
//! the library hidden at its default range in a quarter of them, fitted as `calibrate` fits
//! them (default settings, seeds from the ids). The larger run is
//! `cargo run --release --example stress_failures -- 10000 11 2`.

use pipewave::invert::{fit_segment, FitSettings, FitStatus};
use pipewave::physics::effects::Effect;
use pipewave::synth::{generate, SynthOptions};
use rayon::prelude::*;

#[test]
fn no_segment_of_a_stress_network_is_left_without_a_fit() {
    let effects = [
        Effect::SoilDamping,
        Effect::AirInWater,
        Effect::WallThinning,
        Effect::PipeLoss,
    ];
    let mut net = Vec::new();
    for (i, e) in effects.iter().enumerate() {
        let options = SynthOptions::hiding(*e, 100, 61 + i as u64).expect("a default range");
        net.extend(generate(&options));
    }
    let results: Vec<_> = net
        .par_iter()
        .map(|s| {
            let r = fit_segment(
                &s.segment_data(),
                &FitSettings::default(),
                pipewave::batch::segment_seed(61, &s.id),
            );
            let grazing = r
                .notes
                .iter()
                .chain(&r.flags)
                .any(|f| f.code.as_str() == "near_grazing");
            (s.id.clone(), s.material, r.status, r.message, grazing)
        })
        .collect();
    let failed: Vec<String> = results
        .iter()
        .filter(|r| r.2 == FitStatus::Failed)
        .map(|r| format!("{} {:?}: {}", r.0, r.1, r.3.as_deref().unwrap_or("")))
        .collect();
    let grazing = results.iter().filter(|r| r.4).count();
    eprintln!(
        "{} segments, {} failed, {grazing} with a root near grazing",
        results.len(),
        failed.len()
    );
    assert!(failed.is_empty(), "failed fits:\n{}", failed.join("\n"));
    // The network reaches the grazing regime this issue is about: otherwise the test would
    // pass without exercising it.
    assert!(grazing >= 1, "no fit reached a soil wave speed");
}

/// The one failure of the 10,000-segment stress run before the `unstable_root` flag: a thick
/// HDPE pipe (OD 250 mm) with its wall thinned to 0.69 of nominal, whose optimum lay where the
/// model's root jumps between branches for the slightest change of E_m or ξ, so that no
/// finite-difference Jacobian existed there (fit algorithm 8 answered there, χ² 33.73, flagged
/// `unstable_root`; `invert::fit`'s unit test keeps that point). Since version 9 (the grazing
/// probe, the step off a cliff) the answer, χ² 33.60, lies next to the jump, where the
/// Jacobian exists and the intervals come from the curvature. It also guards the rule that a fast-path answer stands only when no
/// better optimum lacked a reference root: without it this segment's answer is the contact
/// probe's optimum at ξ = 0, χ² 1532.
#[test]
fn an_optimum_next_to_a_root_jump_gets_an_answer_with_a_jacobian() {
    let options = SynthOptions::hiding(Effect::WallThinning, 2500, 13).expect("a range");
    let net = generate(&options);
    let s = net.iter().find(|s| s.id == "WM10951").expect("the segment");
    let r = fit_segment(
        &s.segment_data(),
        &FitSettings::default(),
        pipewave::batch::segment_seed(11, &s.id),
    );
    assert_eq!(r.status, FitStatus::Flagged, "{:?}", r.message);
    assert!(
        r.misfit < 33.7,
        "χ² {} (33.73 at the jump, 1532 at ξ = 0)",
        r.misfit
    );
    assert!(
        r.flags.iter().all(|f| f.code.as_str() != "unstable_root"),
        "{:?}",
        r.flags
    );
    for e in &r.estimates {
        assert!(e.interval.hi > e.interval.lo, "{e:?}");
    }
}
