use pipewave::invert::*;
use pipewave::physics::*;
use std::time::Instant;
fn main() {
    let pipe = Pipe::new(1.22e11, 0.25, 7800.0, 0.01, 0.069, 0.006).unwrap();
    let meas: Vec<Measurement> = [
        (3121.958, 2.508, 0.00544),
        (4167.04, 3.3276, 0.00882),
        (7221.736, 5.9966, 0.0274),
        (10314.48, 8.16, 0.0596),
    ]
    .iter()
    .map(|&(w, k, a)| Measurement::new(w, k, a, None, None).unwrap())
    .collect();
    let data = SegmentData {
        fluid: Fluid::water(),
        pipe,
        soil_density: 1999.0,
        material: Some(Material::CastIron),
        measurements: meas,
    };
    for (name, settings) in [
        (
            "paper seed/printed",
            FitSettings::paper(Model::Seed, ContactMode::Printed),
        ),
        (
            "paper full",
            FitSettings::paper(Model::Full, ContactMode::Reciprocal),
        ),
        ("default", FitSettings::default()),
    ] {
        for seed in 0..3 {
            let t = Instant::now();
            let r = fit_segment(&data, &settings, seed);
            println!("{name} seed {seed}: {:?} E={:?} nu={:?} xi={:?} misfit={:.4} evals={} {:.1} ms restarts={:?} flags={}", r.status, r.soil_modulus(), r.soil_poisson(), r.contact(), r.misfit, r.evaluations, t.elapsed().as_secs_f64()*1e3, r.restart_misfits, r.flag_codes());
            for e in &r.estimates {
                print!(" [{} {:.4e} ± {:?}]", e.param.name(), e.value, e.std);
            }
            println!();
            for f in &r.flags {
                println!("   {f}");
            }
        }
    }
}
