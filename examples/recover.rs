use pipewave::invert::*;
use pipewave::physics::*;
use pipewave::synth::*;
use std::time::Instant;
fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .map(|s| s.parse().unwrap())
        .unwrap_or(40);
    let net = generate(&SynthOptions {
        segments: n,
        seed: 7,
        defect_fraction: 0.0,
        ..Default::default()
    });
    let t0 = Instant::now();
    let mut errs = Vec::new();
    let mut evals = 0;
    let mut flagged = std::collections::BTreeMap::new();
    for s in &net {
        let data = SegmentData {
            fluid: Fluid::water(),
            pipe: pipe_of(s.material, &s.size),
            soil_density: s.soil_density,
            material: Some(s.material),
            measurements: s
                .measurements
                .iter()
                .map(|m| {
                    Measurement::new(
                        pipewave::units::hz_to_omega(m.frequency_hz),
                        m.k_re,
                        m.attenuation,
                        Some(m.k_re_std),
                        Some(m.attenuation_std),
                    )
                    .unwrap()
                })
                .collect(),
        };
        let t = Instant::now();
        let r = fit_segment(&data, &FitSettings::default(), 42);
        let ms = t.elapsed().as_secs_f64() * 1e3;
        evals += r.evaluations;
        let e = r.soil_modulus().unwrap_or(f64::NAN);
        let err = (e / s.soil_modulus - 1.0).abs();
        println!("{} {:5} E={:.3e} true={:.3e} err={:.3} nu={:.3}/{:.3} xi={:.2}/{:.2} chi2={:.2?} {:?} {:.0}ms ev={} {}", s.id, s.material.code(), e, s.soil_modulus, err, r.soil_poisson().unwrap_or(f64::NAN), s.soil_poisson, r.contact().unwrap_or(f64::NAN), s.contact, r.chi2_per_dof, r.status, ms, r.evaluations, r.flag_codes());
        for f in &r.flags {
            *flagged.entry(f.code.as_str()).or_insert(0) += 1;
        }
        if r.status == FitStatus::Ok {
            errs.push(err);
        }
    }
    errs.sort_by(f64::total_cmp);
    let q = |p: f64| {
        errs.get(((errs.len() as f64 - 1.0) * p).round() as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    println!(
        "unflagged {} of {}: median {:.3} p90 {:.3}; flags {:?}; mean evals {}; total {:.1}s",
        errs.len(),
        net.len(),
        q(0.5),
        q(0.9),
        flagged,
        evals / net.len(),
        t0.elapsed().as_secs_f64()
    );
}
