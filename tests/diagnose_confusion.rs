//! The discrepancy workflow on synthetic data in which the effect is hidden (issue 6): for each
//! effect of the library, segments generated with it (1 % / 5 % noise, 4–8 frequencies) are
//! fitted with the base model and diagnosed; control segments have no effect. The diagnosis
//! never sees which effect (or value) was hidden.

use std::collections::BTreeMap;

use pipewave::diagnose::{diagnose_segment, DiagnoseSettings};
use pipewave::physics::effects::Effect;
use pipewave::physics::Model;
use pipewave::synth::{generate, SynthOptions};
use rayon::prelude::*;

/// (true effect, hidden effect and its range, model generating the data).
type Case = (&'static str, Option<(Effect, f64, f64)>, Model);

struct Outcome {
    truth: &'static str,
    named: String,
    structured: bool,
    chi2_after: f64,
}

#[test]
fn confusion_matrix_on_hidden_effects() {
    const N: usize = 10;
    let cases: [Case; 6] = [
        ("none", None, Model::Full),
        (
            "soil_damping",
            Some((Effect::SoilDamping, 0.05, 0.3)),
            Model::Full,
        ),
        (
            "air_in_water",
            Some((Effect::AirInWater, 2e-5, 5e-4)),
            Model::Full,
        ),
        (
            "wall_thinning",
            Some((Effect::WallThinning, 0.5, 0.85)),
            Model::Full,
        ),
        (
            "pipe_loss",
            Some((Effect::PipeLoss, 0.04, 0.15)),
            Model::Full,
        ),
        ("full_model", None, Model::Full),
    ];
    let mut outcomes: Vec<Outcome> = Vec::new();
    for (ci, (truth, hidden, model)) in cases.iter().enumerate() {
        let net = generate(&SynthOptions {
            segments: N,
            seed: 300 + ci as u64,
            defect_fraction: 0.0,
            model: *model,
            hidden_effect: *hidden,
            ..SynthOptions::default()
        });
        // The full-model case is data from `full` diagnosed with a `seed` base model.
        let base_model = if *truth == "full_model" {
            Model::Seed
        } else {
            Model::Full
        };
        let settings = DiagnoseSettings {
            model: base_model,
            ..DiagnoseSettings::default()
        };
        let res: Vec<Outcome> = net
            .par_iter()
            .map(|s| {
                let d = diagnose_segment(&s.segment_data(), None, &settings);
                Outcome {
                    truth,
                    named: d
                        .named
                        .map(|e| e.name().to_string())
                        .unwrap_or("none".into()),
                    structured: d.structure.structured || d.base.chi2_per_dof.is_none(),
                    chi2_after: d.chi2_per_dof_after(),
                }
            })
            .collect();
        outcomes.extend(res);
    }
    let names = [
        "none",
        "soil_damping",
        "air_in_water",
        "wall_thinning",
        "pipe_loss",
        "full_model",
    ];
    let mut matrix: BTreeMap<(&str, String), usize> = BTreeMap::new();
    for o in &outcomes {
        *matrix.entry((o.truth, o.named.clone())).or_default() += 1;
    }
    eprintln!("confusion matrix (rows: hidden effect; columns: named), {N} segments per row:");
    eprintln!("{:>14} {}", "", names.map(|n| format!("{n:>14}")).join(""));
    for t in names {
        let row: Vec<String> = names
            .iter()
            .map(|n| {
                format!(
                    "{:>14}",
                    matrix.get(&(t, n.to_string())).copied().unwrap_or(0)
                )
            })
            .collect();
        eprintln!("{t:>14} {}", row.join(""));
    }
    // Targets: the right effect for >= 90 % of segments whose base misfit is clearly above the
    // noise; "none" for >= 90 % of controls; named refits within 1.5x the noise level.
    let structured: Vec<&Outcome> = outcomes
        .iter()
        .filter(|o| o.truth != "none" && o.structured)
        .collect();
    let right = structured.iter().filter(|o| o.named == o.truth).count();
    let controls: Vec<&Outcome> = outcomes.iter().filter(|o| o.truth == "none").collect();
    let none_ok = controls.iter().filter(|o| o.named == "none").count();
    let mut after: Vec<f64> = outcomes
        .iter()
        .filter(|o| o.named != "none")
        .map(|o| o.chi2_after)
        .collect();
    after.sort_by(f64::total_cmp);
    let within = after.iter().filter(|&&c| c <= 1.5).count();
    eprintln!(
        "right effect for {right}/{} segments with clearly structured misfit; none for {none_ok}/{} controls; named refits with chi2/dof <= 1.5: {within}/{}",
        structured.len(),
        controls.len(),
        after.len()
    );
    assert!(structured.len() >= 20, "too few structured cases to judge");
    assert!(right as f64 >= 0.9 * structured.len() as f64);
    assert!(none_ok as f64 >= 0.9 * controls.len() as f64);
    assert!(within as f64 >= 0.8 * after.len() as f64);
    assert!(
        after[after.len() / 2] <= 1.5,
        "median chi2/dof after {}",
        after[after.len() / 2]
    );
}
