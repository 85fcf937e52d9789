//! The extra cost of the nested-fit guarantee per extended fit: on synthetic trials hiding each
//! nested effect (and controls), the same fit with the effect switched on with and without the
//! start from the base optimum (`fit_extended` against `fit_segment`), in forward-model
//! evaluations and wall time, and the misfit rise of each over the base fit.
//!
//! Run: `cargo run --release --example nested_cost -- [N]` (default N = 8 per effect).

use std::time::Instant;

use pipewave::invert::{fit_extended, fit_segment, FitSettings};
use pipewave::physics::effects::Effect;
use pipewave::physics::Material;
use pipewave::synth::default_hidden_range;
use pipewave::synth::trial::effect_trial;
use pipewave::types::FitStatus;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(8);
    let base_settings = FitSettings::default();
    println!("effect          n  evals plain  evals nested  ms plain  ms nested  worst rise plain  worst rise nested");
    for (k, e) in [
        Effect::SoilDamping,
        Effect::AirInWater,
        Effect::WallThinning,
        Effect::PipeLoss,
    ]
    .into_iter()
    .enumerate()
    {
        let settings = FitSettings {
            effects: vec![e],
            ..FitSettings::default()
        };
        let (mut ev_p, mut ev_n, mut t_p, mut t_n) = (0usize, 0usize, 0.0, 0.0);
        let (mut rise_p, mut rise_n) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
        let mut done = 0;
        let mut seed = 9_000_000 + 1000 * k as u64;
        while done < n {
            seed += 1;
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let m = Material::ALL[rng.gen_range(0..Material::ALL.len())];
            let hidden = (seed % 2 == 0).then(|| {
                let (lo, hi) = default_hidden_range(e).expect("range");
                (e, rng.gen_range(lo..hi))
            });
            let Some(t) = effect_trial(&mut rng, m, hidden) else {
                continue;
            };
            let base = fit_segment(&t.data, &base_settings, seed);
            if base.status == FitStatus::Failed {
                continue;
            }
            let t0 = Instant::now();
            let plain = fit_segment(&t.data, &settings, seed);
            t_p += t0.elapsed().as_secs_f64();
            let t0 = Instant::now();
            let nested = fit_extended(&t.data, &settings, seed, &base);
            t_n += t0.elapsed().as_secs_f64();
            ev_p += plain.evaluations;
            ev_n += nested.evaluations;
            rise_p = rise_p.max(plain.misfit - base.misfit);
            rise_n = rise_n.max(nested.misfit - base.misfit);
            done += 1;
        }
        println!(
            "{:<14} {n:>2} {:>12.0} {:>13.0} {:>9.1} {:>10.1} {:>17.4} {:>18.4}",
            e.name(),
            ev_p as f64 / n as f64,
            ev_n as f64 / n as f64,
            1e3 * t_p / n as f64,
            1e3 * t_n / n as f64,
            rise_p,
            rise_n
        );
    }
}
