//! Synthetic stress (issue 11): every segment with measurements gets a fit. A network of
//! 400 segments, all materials and wall classes (thin plastic pipes included), each effect of
//! the library hidden at its default range in a quarter of them, fitted as `calibrate` fits
//! them (default settings, seeds from the ids). The larger run is
//! `cargo run --release --example stress_failures -- 10000 11 2`.

use pipewave::invert::{fit_segment, FitSettings};
use pipewave::physics::effects::Effect;
use pipewave::synth::{generate, SynthOptions};
use pipewave::types::FitStatus;
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
