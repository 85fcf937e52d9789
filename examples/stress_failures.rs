//! Failed fits on a stress network (issue 11): every effect hidden at its default range in a
//! quarter of the segments each, all materials, thin walls included, fitted as `calibrate`
//! fits (default settings, seeds from the ids).
//!
//! Usage: stress_failures [SEGMENTS] [SEED] [JOBS]

use pipewave::physics::effects::Effect;
use pipewave::synth::bench::BenchSegment;
use pipewave::synth::{generate, SynthOptions};
use rayon::prelude::*;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(10_000);
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(11);
    let jobs: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(2);
    let settings = pipewave::invert::FitSettings::default();
    let effects = [
        Effect::SoilDamping,
        Effect::AirInWater,
        Effect::WallThinning,
        Effect::PipeLoss,
    ];
    let mut net: Vec<(Effect, pipewave::synth::SynthSegment)> = Vec::new();
    for (i, e) in effects.iter().enumerate() {
        let options = SynthOptions::hiding(*e, n / effects.len(), seed + i as u64).expect("range");
        let segs = generate(&options);
        net.extend(segs.into_iter().map(|s| (*e, s)));
    }
    if let Ok(only) = std::env::var("ONLY") {
        net.retain(|(e, s)| {
            only.split(',')
                .any(|o| format!("{}-{}", e.name(), s.id) == o)
        });
    }
    let t = std::time::Instant::now();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs)
        .build()
        .unwrap();
    let results: Vec<_> = pool.install(|| {
        net.par_iter()
            .map(|(e, s)| {
                let seg = BenchSegment {
                    id: format!("{}-{}", e.name(), s.id),
                    material: s.material,
                    data: s.segment_data(),
                    seed: pipewave::batch::segment_seed(seed, &s.id),
                };
                let r = pipewave::invert::fit_segment(&seg.data, &settings, seg.seed);
                let grazing = r
                    .notes
                    .iter()
                    .chain(&r.flags)
                    .any(|f| f.code.as_str() == "near_grazing");
                (seg.id, r.status, r.message, s.clone(), grazing)
            })
            .collect()
    });
    let failed: Vec<_> = results
        .iter()
        .filter(|r| r.1 == pipewave::types::FitStatus::Failed)
        .collect();
    let by_status = |st: pipewave::types::FitStatus| results.iter().filter(|r| r.1 == st).count();
    println!(
        "{} segments, {} failed ({} ok, {} flagged; {} with a root near grazing), {:.1} s on {} jobs",
        results.len(),
        failed.len(),
        by_status(pipewave::types::FitStatus::Ok),
        by_status(pipewave::types::FitStatus::Flagged),
        results.iter().filter(|r| r.4).count(),
        t.elapsed().as_secs_f64(),
        jobs
    );
    for (id, _, msg, s, _) in failed {
        println!(
            "  {id} {:?} OD {} wall {} E {:.3e} nu {:.3} xi {:.3} rho {} hidden {:?} freqs {:?}: {}",
            s.material,
            s.size.od_mm,
            s.size.wall_mm,
            s.soil_modulus,
            s.soil_poisson,
            s.contact,
            s.soil_density,
            s.hidden,
            s.measurements.iter().map(|m| m.frequency_hz).collect::<Vec<_>>(),
            msg.as_deref().unwrap_or("")
        );
    }
}
