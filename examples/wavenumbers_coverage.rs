//! How often the truth lies inside the stated 2σ of `pipewave wavenumbers`, on synthetic
//! hydrant tests (the generator of tests/wavenumbers.rs: CI, DI, PVC, MDPE, HDPE and ST pipes of
//! random size and soil, the seed layout with sensors 20–80 m (metals) or 6–30 m (plastics) from
//! the source, sensor noise 30 % of the source channel, 8 kHz).
//!
//!     cargo run --release --example wavenumbers_coverage -- [FIRST_SEED] [SEEDS] [SECONDS] [-v]
//!
//! (`-v`: the z-scores of every band.)
//!
//! The estimator's settings were chosen on seeds 1–10 (the defaults here); the acceptance test
//! uses another seed.

use pipewave::physics::{ContactMode, Fluid, Material, Model, Soil, System};
use pipewave::recordings::estimate::analyse_audio;
use pipewave::recordings::wav::SegmentAudio;
use pipewave::recordings::{EstimateOptions, SegmentLayout};
use pipewave::synth::recordings::{hydrant_test, seed_layout, sensor_range_m, RecordingSpec};
use rand::{Rng, SeedableRng};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |i: usize, d: f64| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (first, seeds, seconds) = (arg(1, 1.0) as u64, arg(2, 10.0) as u64, arg(3, 30.0));
    let verbose = args.iter().any(|a| a == "-v");
    let materials = [
        Material::CastIron,
        Material::DuctileIron,
        Material::Pvc,
        Material::Mdpe,
        Material::Hdpe,
        Material::Steel,
    ];
    let (mut n, mut in_k, mut in_a, mut fewest) = (0usize, 0usize, 0usize, usize::MAX);
    let mut rel = Vec::new();
    for seed in first..first + seeds {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        for &mat in &materials {
            let sizes = pipewave::synth::sizes(mat);
            let sz = sizes[rng.gen_range(0..sizes.len())];
            let soil = Soil::new(
                rng.gen_range(2e7..2e8),
                rng.gen_range(0.25..0.4),
                1900.0,
                0.0,
            )?;
            let sys = System::new(
                Fluid::water(),
                pipewave::synth::pipe_of(mat, &sz),
                soil,
                rng.gen_range(0.0..1.0),
                Model::Full,
                ContactMode::Reciprocal,
            )?;
            let positions = seed_layout(&mut rng, sensor_range_m(mat));
            let spec = RecordingSpec {
                sample_rate: 8000,
                seconds,
                positions_m: positions.clone(),
                noise_fraction: 0.3,
                seed: rng.gen(),
            };
            let rec = hydrant_test(&sys, &spec)?;
            let seg = SegmentLayout::one_file("X", "x.wav", &positions);
            let audio = SegmentAudio {
                sample_rate: 8000,
                channels: rec.channels.clone(),
            };
            let r = analyse_audio(
                std::path::Path::new("layout.csv"),
                &seg,
                &audio,
                &EstimateOptions::default(),
                &|_| {},
            )?;
            let (mut bk, mut ba) = (0, 0);
            for b in &r.bands {
                let k = rec
                    .truth
                    .at(b.frequency_hz)
                    .ok_or("band outside the truth")?;
                bk += usize::from((b.k_re - k.re).abs() <= 2.0 * b.k_re_std);
                ba += usize::from((b.attenuation + k.im).abs() <= 2.0 * b.attenuation_std);
                rel.push(((b.k_re - k.re) / k.re).abs());
                if verbose {
                    println!(
                        "  {:>7.1} Hz  k_re z {:+.2}  attenuation z {:+.2}  {:?}",
                        b.frequency_hz,
                        (b.k_re - k.re) / b.k_re_std,
                        (b.attenuation + k.im) / b.attenuation_std,
                        b.notes
                    );
                }
            }
            println!(
                "seed {seed} {:<12} OD {:>5} mm, sensors {:?} m: {:>3} bands, k_re in 2σ {:>3}, attenuation in 2σ {:>3}",
                format!("{mat:?}"),
                sz.od_mm,
                positions,
                r.bands.len(),
                bk,
                ba
            );
            n += r.bands.len();
            in_k += bk;
            in_a += ba;
            fewest = fewest.min(r.bands.len());
        }
    }
    rel.sort_by(f64::total_cmp);
    println!(
        "{n} bands: truth inside 2σ for {:.1} % (k_re), {:.1} % (attenuation); median k_re error {:.4} %; fewest bands of a pipe {fewest}",
        100.0 * in_k as f64 / n as f64,
        100.0 * in_a as f64 / n as f64,
        100.0 * rel.get(rel.len() / 2).copied().unwrap_or(f64::NAN)
    );
    Ok(())
}
