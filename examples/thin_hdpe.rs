//! The thin HDPE pipe of issue 11: where does the continuation lose the s = 1 root?
use pipewave::physics::effects::Effect;
use pipewave::physics::solver::{solve_curve, Continuation, Tolerance};
use pipewave::physics::{ContactMode, Fluid, Material, Model, Pipe, Soil, System};

fn main() {
    let pipe = Pipe::from_outside_diameter(Material::Hdpe.typical(), 0.090, 0.0054).unwrap();
    let soil = Soil::new(1.8e7, 0.32, 1930.0, 0.0).unwrap();
    let sys = System::new(
        Fluid::water(),
        pipe,
        soil,
        0.30,
        Model::Full,
        ContactMode::Reciprocal,
    )
    .unwrap();
    let sys = if let Ok(v) = std::env::var("SOIL") {
        // E,nu,xi at the nominal wall (a fit's optimum)
        let p: Vec<f64> = v.split(',').map(|x| x.parse().unwrap()).collect();
        let soil = Soil::new(p[0], p[1], 1930.0, 0.0).unwrap();
        System::new(
            Fluid::water(),
            pipe,
            soil,
            p[2],
            Model::Full,
            ContactMode::Reciprocal,
        )
        .unwrap()
    } else {
        Effect::WallThinning.apply(&sys, 0.62).unwrap()
    };
    let (cp, cs) = sys.soil.wave_speeds();
    println!("cp {cp:.1} cs {cs:.1}");
    let f: Vec<f64> = [136.0, 260.0, 390.0, 520.0, 717.0].to_vec();
    let w: Vec<f64> = f.iter().map(|f| f * std::f64::consts::TAU).collect();
    for (name, opts) in [
        ("reference", Continuation::default()),
        (
            "fast",
            Continuation {
                ramp_points: 0,
                tolerance: Tolerance::FAST,
            },
        ),
        (
            "ramp8",
            Continuation {
                ramp_points: 8,
                tolerance: Tolerance::FAST,
            },
        ),
    ] {
        println!("{name}");
        for (fi, r) in f.iter().zip(solve_curve(&sys, &w, opts)) {
            match r {
                Ok(r) => println!(
                    "  {fi} Hz k1 = {:.6} c = {:.2} flags {}",
                    r.k1,
                    r.phase_speed(),
                    r.flags
                ),
                Err(e) => println!("  {fi} Hz {e}"),
            }
        }
    }
    if std::env::var_os("PROBE").is_some() {
        let kv = pipewave::physics::dispersion::in_vacuo_root(&sys, 260.0 * std::f64::consts::TAU);
        let kp = 260.0 * std::f64::consts::TAU / cp;
        probe(
            &sys,
            260.0,
            &[
                kv,
                num_complex::Complex64::new(4.635, -0.308),
                num_complex::Complex64::new(kp * 1.05, -0.45),
                num_complex::Complex64::new(kp * 1.1, 0.0),
            ],
        );
        return;
    }
    if std::env::var_os("FIT").is_some() {
        fit_it(&sys, pipe);
        return;
    }
    // Scan the reference ramp at fine steps.
    let fine: Vec<f64> = (1..=400)
        .map(|i| i as f64 * 2.0 * std::f64::consts::TAU)
        .collect();
    let res = solve_curve(&sys, &fine, Continuation::default());
    let mut last = None;
    for (w, r) in fine.iter().zip(&res) {
        match r {
            Ok(r) => last = Some((*w, r.k1, r.phase_speed())),
            Err(e) => {
                println!(
                    "fine scan fails at {:.0} Hz: {e}; last ok {:?}",
                    w / std::f64::consts::TAU,
                    last
                );
                break;
            }
        }
    }
}

/// Fit noisy data of the thinned pipe with the nominal wall, over several noise seeds.
pub fn fit_it(sys: &System, pipe: Pipe) {
    use rand::SeedableRng;
    let freqs = [136.0, 260.0, 390.0, 520.0, 717.0];
    let mut failed = 0;
    for s in 0..20u64 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(s);
        let meas = pipewave::synth::measure(sys, &freqs, &mut rng).expect("solves");
        let data = pipewave::synth::segment_data(Material::Hdpe, pipe, 1930.0, &meas);
        let r = pipewave::invert::fit_segment(&data, &pipewave::invert::FitSettings::default(), s);
        if r.status == pipewave::types::FitStatus::Failed {
            failed += 1;
            println!("seed {s}: {:?}", r.message);
        } else {
            println!(
                "seed {s}: E {:.3e} nu {:.3} xi {:.3} chi2 {:.2} flags {}",
                r.soil_modulus().unwrap(),
                r.soil_poisson().unwrap(),
                r.contact().unwrap(),
                r.misfit,
                r.flag_codes()
            );
        }
    }
    println!("{failed}/20 failed");
}

/// Solve at one frequency from given guesses with both tolerances.
pub fn probe(sys: &System, f: f64, guesses: &[num_complex::Complex64]) {
    use pipewave::physics::solver::solve_from_guess_tol;
    let w = f * std::f64::consts::TAU;
    for &g in guesses {
        for t in [Tolerance::REFERENCE, Tolerance::FAST] {
            println!(
                "  probe {f} Hz from {g:.4}: {:?}",
                solve_from_guess_tol(sys, w, g, t).map(|r| (r.k1, r.phase_speed(), r.residual))
            );
        }
    }
}
